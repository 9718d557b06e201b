//! The emulated SubDevice: ESC memory, datagram execution, SII interface, AL state machine,
//! mailbox, process data and SM watchdog.

use core::ops::Range;
use core::time::Duration;

use crate::al::{self, Check, Step};
use crate::coe::{Outcome, SdoServer};
use crate::fault::{Faults, Rng, Stats};
use crate::frame::{self, Cmd, Datagram, DGRAM_HEADER, ECAT_HEADER, ETH_HEADER};
use crate::mailbox::{
    self, mailbox_error, Header, MailboxState, HEADER_LEN, TYPE_COE, TYPE_ERR, TYPE_FOE,
};
use crate::registers::{self as reg, sii_control as sc, NUM_FMMUS, NUM_SMS};
use crate::sii::{self, Eeprom};
use crate::{
    al_status, AlState, AppRequest, Application, ConfigError, EscConfig, MailboxContext,
    MailboxReply, Pdi, PdiAccess, SyncManagers,
};

/// ESC type register value.
const ESC_TYPE: u8 = 0x04;
/// Minimum process RAM (KiB); grown to cover the configured areas.
const MIN_RAM_KIB: usize = 8;
/// Power-on watchdog divider: (2498 + 2) * 40 ns = 100 µs per watchdog tick.
const WATCHDOG_DIVIDER: u16 = 2498;
/// Power-on PDI watchdog: 1000 ticks.
const WATCHDOG_PDI: u16 = 1000;
/// DL status: PDI operational, PDI watchdog ok, link and communication on port 0, loops of
/// ports 1..3 closed.
const DL_STATUS: u16 = 0x0001 | 0x0002 | 0x0010 | 0x0200 | 0x0400 | 0x1000 | 0x4000;
/// DL status: loop of port 1 closed (in [`DL_STATUS`]).
const DL_LOOP_PORT1_CLOSED: u16 = 0x0400;
/// DL status: link and communication on port 1 (a SubDevice behind this one).
const DL_PORT1_LINKED: u16 = 0x0020 | 0x0800;
/// SM control bit 6: watchdog trigger enable.
const SM_WATCHDOG_ENABLE: u8 = 0x40;

/// What a datagram touched; handled once the datagram is done, in a fixed order.
#[derive(Debug, Default)]
struct Events {
    al_control: bool,
    sii_command: Option<u8>,
    sii_status_read: bool,
    watchdog_written: bool,
    sm_activate_old: [Option<u8>; NUM_SMS],
    sm_last_written: [bool; NUM_SMS],
    sm_last_read: [bool; NUM_SMS],
    inputs_refreshed: [bool; NUM_SMS],
}

#[derive(Debug, Clone, Copy)]
enum Access {
    Read,
    Write,
    ReadWrite,
}

impl Access {
    fn reads(self) -> bool {
        matches!(self, Self::Read | Self::ReadWrite)
    }
    fn writes(self) -> bool {
        matches!(self, Self::Write | Self::ReadWrite)
    }
}

/// A SyncManager as its registers describe it.
#[derive(Debug, Clone, Copy)]
struct Sm {
    start: u16,
    len: u16,
    control: u8,
    activate: u8,
}

impl Sm {
    fn active(&self) -> bool {
        self.activate & 0x01 != 0 && self.len > 0
    }
    fn mailbox(&self) -> bool {
        self.control & 0x03 == 0x02
    }
    fn buffered(&self) -> bool {
        self.control & 0x03 == 0x00
    }
    fn ecat_writes(&self) -> bool {
        (self.control >> 2) & 0x03 == 0x01
    }
    fn range(&self) -> Range<usize> {
        usize::from(self.start)..usize::from(self.start) + usize::from(self.len)
    }
    fn contains(&self, addr: u16) -> bool {
        self.active() && self.range().contains(&usize::from(addr))
    }
    fn is_last(&self, addr: u16) -> bool {
        usize::from(addr) + 1 == self.range().end
    }
    /// The buffer lies in the process RAM (a MainDevice could point an SM anywhere).
    fn in_ram(&self, mem_len: usize) -> bool {
        self.start >= reg::RAM_START && self.range().end <= mem_len
    }
}

/// An FMMU as its registers describe it (byte granular).
#[derive(Debug, Clone, Copy)]
struct Fmmu {
    logical: u64,
    len: u64,
    physical: u64,
    read: bool,
    write: bool,
    enabled: bool,
}

impl Fmmu {
    fn map(&self, logical: u64) -> Option<u16> {
        if !self.enabled || logical < self.logical || logical >= self.logical + self.len {
            return None;
        }
        u16::try_from(self.physical + (logical - self.logical)).ok()
    }
}

/// One emulated SubDevice: an ESC with its SII EEPROM, and the [`Application`] behind it.
///
/// Feed it every EtherCAT frame that passes it with [`process_frame`](Self::process_frame) (or
/// [`process_frame_into`](Self::process_frame_into)) and send back what it returns. `now` is a
/// monotonic time of the caller's choosing (the SM watchdog and the application use it).
pub struct SubDevice<A: Application> {
    config: EscConfig,
    app: A,
    /// ESC address space: registers 0x0000..0x1000, then the process RAM.
    mem: Vec<u8>,
    eeprom: Eeprom,
    sii_pending: Option<u8>,
    state: AlState,
    error: bool,
    code: u16,
    mbx: MailboxState,
    sdo: SdoServer,
    last_outputs: Duration,
    faults: Faults,
    rng: Rng,
    stats: Stats,
    /// Restarting: no frames are answered until then.
    offline_until: Option<Duration>,
    /// When AL control was first written since the firmware last read it (with
    /// [`EscConfig::firmware_loop`]).
    al_control_written_at: Option<Duration>,
    /// When each programmed one-buffer SM was last filled by the MainDevice.
    sm_written_at: [Duration; NUM_SMS],
}

impl<A: Application> core::fmt::Debug for SubDevice<A> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("SubDevice")
            .field("name", &self.config.name)
            .field("state", &self.state)
            .field("error", &self.error)
            .field("code", &format_args!("{:#06x}", self.code))
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl<A: Application> SubDevice<A> {
    /// Powers on a SubDevice in INIT. An invalid configuration (see [`EscConfig::validate`]) is
    /// logged and used as it is; use [`try_new`](Self::try_new) to refuse it instead.
    pub fn new(config: EscConfig, app: A) -> Self {
        let sizes = app.process_image_sizes().unwrap_or((0, 0));
        if let Err(error) = config.validate(sizes) {
            tracing::warn!(%error, "EscConfig is not valid; the SubDevice may misbehave");
        }
        Self::power_on(config, app, sizes)
    }

    /// Like [`new`](Self::new), but refuses an invalid configuration.
    pub fn try_new(config: EscConfig, app: A) -> Result<Self, ConfigError> {
        let sizes = app.process_image_sizes().unwrap_or((0, 0));
        config.validate(sizes)?;
        Ok(Self::power_on(config, app, sizes))
    }

    fn power_on(config: EscConfig, app: A, sizes: (usize, usize)) -> Self {
        let image = sii::build_image(&config, sizes);
        let programmed = match &config.sync_managers {
            SyncManagers::Standard => Vec::new(),
            SyncManagers::Programmed(sms) => sms
                .iter()
                .map(|sm| (sm.start, usize::from(sm.len)))
                .collect(),
        };
        let standard = [
            (config.rx_mailbox.0, usize::from(config.rx_mailbox.1)),
            (config.tx_mailbox.0, usize::from(config.tx_mailbox.1)),
            (
                config.bootstrap_rx_mailbox.0,
                usize::from(config.bootstrap_rx_mailbox.1),
            ),
            (
                config.bootstrap_tx_mailbox.0,
                usize::from(config.bootstrap_tx_mailbox.1),
            ),
            (config.outputs_address, sizes.0),
            (config.inputs_address, sizes.1),
        ];
        let ram_start = usize::from(reg::RAM_START);
        let end = standard
            .iter()
            .chain(&programmed)
            .map(|(start, len)| usize::from(*start) + len)
            .fold(ram_start + MIN_RAM_KIB * 1024, usize::max);
        let ram_kib = (end - ram_start).div_ceil(1024).min(60);
        let mut sd = Self {
            app,
            mem: vec![0; ram_start + ram_kib * 1024],
            eeprom: Eeprom::new(image),
            sii_pending: None,
            state: AlState::Init,
            error: false,
            code: 0,
            mbx: MailboxState::default(),
            sdo: SdoServer::default(),
            last_outputs: Duration::ZERO,
            rng: Rng::new(0),
            faults: Faults::default(),
            stats: Stats::default(),
            offline_until: None,
            al_control_written_at: None,
            sm_written_at: [Duration::ZERO; NUM_SMS],
            config,
        };
        sd.init_registers();
        sd
    }

    /// The registers as at power-on (memory zeroed by the caller), the configuration area loaded
    /// from the SII.
    fn init_registers(&mut self) {
        let ram_kib = (self.mem.len() - usize::from(reg::RAM_START)) / 1024;
        let sd = self;
        sd.mem[usize::from(reg::TYPE)] = ESC_TYPE;
        sd.mem[usize::from(reg::REVISION)] = 0x01;
        sd.set_u16(reg::BUILD, 0x0001);
        sd.mem[usize::from(reg::FMMU_COUNT)] = NUM_FMMUS as u8;
        sd.mem[usize::from(reg::SM_COUNT)] = NUM_SMS as u8;
        sd.mem[usize::from(reg::RAM_SIZE)] = ram_kib as u8;
        // Ports 0 and 1: MII.
        sd.mem[usize::from(reg::PORT_DESCRIPTOR)] = 0x0F;
        // Byte-oriented FMMUs only; no DC, LRW and BRW/APRW/FPRW supported.
        sd.set_u16(reg::FEATURES, 0x0001);
        sd.mem[usize::from(reg::DL_CONTROL)] = 0x01;
        sd.mem[usize::from(reg::DL_CONTROL) + 2] = 0x07;
        let dl_status = if sd.config.port1_linked {
            (DL_STATUS & !DL_LOOP_PORT1_CLOSED) | DL_PORT1_LINKED
        } else {
            DL_STATUS
        };
        sd.set_u16(reg::DL_STATUS, dl_status);
        sd.set_u16(reg::AL_CONTROL, AlState::Init.bits().into());
        sd.set_u16(reg::WATCHDOG_DIVIDER, WATCHDOG_DIVIDER);
        sd.set_u16(reg::WATCHDOG_PDI, WATCHDOG_PDI);
        let ticks = sd.config.watchdog.as_micros().div_ceil(100);
        sd.set_u16(reg::WATCHDOG_SM, u16::try_from(ticks).unwrap_or(u16::MAX));
        sd.set_u16(reg::WATCHDOG_SM_STATUS, 0x0001);
        let mut sii_status = sc::READ_8_BYTES;
        if sd.eeprom.two_address_bytes() {
            sii_status |= sc::TWO_ADDRESS_BYTES;
        }
        if sii::checksum_ok(sd.eeprom.image()) {
            sd.load_config_area();
        } else {
            sii_status |= sc::CHECKSUM_ERROR;
        }
        sd.set_u16(reg::SII_CONTROL, sii_status);
        sd.update_status();
    }

    /// Restarts the device as a power cycle does: it answers no frame for `offline` (frames
    /// are lost, as behind a device that reboots), and comes back as at power-on: INIT,
    /// station address 0, sync managers and FMMUs cleared, mailbox emptied, SII configuration
    /// reloaded (the SII content, the application, the faults and the counters stay). The
    /// application is not told (it asked for it, or it is being power-cycled with its ESC).
    pub fn restart(&mut self, now: Duration, offline: Duration) {
        tracing::info!(?offline, "SubDevice restarting");
        self.stats.restarts += 1;
        self.mem.fill(0);
        self.sii_pending = None;
        self.state = AlState::Init;
        self.error = false;
        self.code = al_status::NO_ERROR;
        self.mbx.reset();
        self.sdo.reset();
        self.al_control_written_at = None;
        self.last_outputs = now;
        self.init_registers();
        self.offline_until = if offline.is_zero() {
            None
        } else {
            Some(now + offline)
        };
    }

    /// True while the device restarts and answers no frame.
    pub fn restarting(&self) -> bool {
        self.offline_until.is_some()
    }

    /// The configuration this SubDevice was built with.
    pub fn config(&self) -> &EscConfig {
        &self.config
    }

    /// The application.
    pub fn app(&self) -> &A {
        &self.app
    }

    /// The application, mutably (e.g. to change what it reports).
    pub fn app_mut(&mut self) -> &mut A {
        &mut self.app
    }

    /// AL state, error flag, AL status code.
    pub fn al_state(&self) -> (AlState, bool, u16) {
        (self.state, self.error, self.code)
    }

    /// Fault injection settings.
    pub fn faults(&mut self) -> &mut Faults {
        &mut self.faults
    }

    /// Counters.
    pub fn stats(&self) -> Stats {
        let mut stats = self.stats;
        stats.sdo_aborts = self.sdo.aborts();
        stats
    }

    /// The SII EEPROM content (including writes the MainDevice made).
    pub fn sii_image(&self) -> &[u8] {
        self.eeprom.image()
    }

    /// The ESC address space as the MainDevice would read it: registers from 0x0000, process
    /// RAM from 0x1000 (for diagnostics and tests).
    pub fn memory(&self) -> &[u8] {
        &self.mem
    }

    /// Selects 8-byte (`true`, the power-on default) or 4-byte (`false`) SII reads: bit 6 of
    /// register 0x0502, a property of the ESC that a MainDevice must honour.
    pub fn set_sii_8_byte_reads(&mut self, eight: bool) {
        let mut status = self.u16_at(reg::SII_CONTROL) & !sc::READ_8_BYTES;
        if eight {
            status |= sc::READ_8_BYTES;
        }
        self.set_u16(reg::SII_CONTROL, status);
    }

    /// Forces the SM watchdog to fire now, as if outputs had stopped (only has an effect in OP).
    pub fn trip_watchdog(&mut self) {
        if self.state == AlState::Op {
            self.watchdog_expired();
        }
    }

    /// Advances the SubDevice's own clock without a frame (the end of a restart, the firmware's
    /// reading of AL control, the application's [`poll`](Application::poll) and the SM watchdog
    /// are checked on every frame and here).
    pub fn tick(&mut self, now: Duration) {
        if let Some(until) = self.offline_until {
            if now < until {
                return;
            }
            tracing::info!("SubDevice up again after its restart");
            self.offline_until = None;
        }
        self.firmware_reads_al_control(now);
        if let AppRequest::Restart { offline } = self.app.poll(now, self.state) {
            self.restart(now, offline);
            return;
        }
        if self.programmed() && matches!(self.state, AlState::SafeOp | AlState::Op) {
            let mut buffers = Buffers {
                mem: &mut self.mem,
                written_at: &self.sm_written_at,
            };
            self.app
                .pdi(now, self.state, &mut Pdi { esc: &mut buffers });
        }
        if self.state != AlState::Op {
            return;
        }
        if let Some(timeout) = self.watchdog_timeout() {
            if now.saturating_sub(self.last_outputs) > timeout {
                self.watchdog_expired();
            }
        }
    }

    /// Processes one Ethernet frame as it passes this SubDevice and returns the frame to send
    /// on (datagrams executed, working counters updated, source MAC replaced). `None`: not an
    /// EtherCAT frame, a malformed one, or one lost by fault injection.
    pub fn process_frame(&mut self, frame: &[u8], now: Duration) -> Option<Vec<u8>> {
        if !self.accept(frame, now) {
            return None;
        }
        let mut out = frame.to_vec();
        self.execute_frame(&mut out, now);
        Some(out)
    }

    /// Like [`process_frame`](Self::process_frame), writing the reply into `out` (which must be
    /// at least as long as `frame`); returns the reply length. Allocates nothing on the process
    /// data path (mailbox traffic allocates).
    pub fn process_frame_into(
        &mut self,
        frame: &[u8],
        out: &mut [u8],
        now: Duration,
    ) -> Option<usize> {
        let Some(out) = out.get_mut(..frame.len()) else {
            tracing::warn!(
                frame = frame.len(),
                out = out.len(),
                "reply buffer too short, frame dropped"
            );
            return None;
        };
        if !self.accept(frame, now) {
            return None;
        }
        out.copy_from_slice(frame);
        self.execute_frame(out, now);
        Some(frame.len())
    }

    fn accept(&mut self, frame: &[u8], now: Duration) -> bool {
        if !frame::is_ethercat(frame) {
            self.stats.not_ethercat += 1;
            return false;
        }
        self.stats.frames += 1;
        self.tick(now);
        if self.offline_until.is_some() {
            self.stats.frames_while_restarting += 1;
            return false;
        }
        if self.faults.link_down
            || self
                .rng
                .chance(self.faults.drop_probability, self.faults.seed)
        {
            self.stats.dropped_frames += 1;
            return false;
        }
        if frame::validate(frame).is_err() {
            self.stats.malformed += 1;
            return false;
        }
        true
    }

    fn execute_frame(&mut self, buf: &mut [u8], now: Duration) {
        let mut offset = ETH_HEADER + ECAT_HEADER;
        while let Some(dg) = Datagram::at(buf, offset) {
            self.execute(buf, dg, now);
            if !dg.more {
                break;
            }
            offset = dg.next_offset();
        }
        let mut src = [0u8; 6];
        src.copy_from_slice(&buf[6..12]);
        let mac = if self.config.mac == src {
            src[0] ^= 0x02;
            src
        } else {
            self.config.mac
        };
        buf[6..12].copy_from_slice(&mac);
        self.stats.replies += 1;
    }

    fn execute(&mut self, buf: &mut [u8], dg: Datagram, now: Duration) {
        self.stats.datagrams += 1;
        let Some(datagram) = buf.get_mut(dg.offset..dg.next_offset()) else {
            return;
        };
        let (head, tail) = datagram.split_at_mut(DGRAM_HEADER);
        let (data, wkc) = tail.split_at_mut(dg.len);
        let cmd = Cmd::from_code(head[0]);
        let adp = u16::from_le_bytes([head[2], head[3]]);
        let ado = u16::from_le_bytes([head[4], head[5]]);
        let logical = u32::from_le_bytes([head[2], head[3], head[4], head[5]]);
        let alias_enabled = self.mem[usize::from(reg::DL_CONTROL) + 3] & 0x01 != 0;
        let configured = adp == self.u16_at(reg::STATION_ADDRESS)
            || (alias_enabled && adp == self.u16_at(reg::STATION_ALIAS));
        let mut ev = Events::default();
        let next_position = adp.wrapping_add(1).to_le_bytes();

        let (read, written) = match cmd {
            Cmd::Nop | Cmd::Unknown => (false, false),
            Cmd::Aprd | Cmd::Apwr | Cmd::Aprw => {
                head[2..4].copy_from_slice(&next_position);
                if adp == 0 {
                    self.physical(ado, data, access(cmd), false, &mut ev, now)
                } else {
                    (false, false)
                }
            }
            Cmd::Fprd | Cmd::Fpwr | Cmd::Fprw => {
                if configured {
                    self.physical(ado, data, access(cmd), false, &mut ev, now)
                } else {
                    (false, false)
                }
            }
            Cmd::Brd | Cmd::Bwr | Cmd::Brw => {
                head[2..4].copy_from_slice(&next_position);
                self.physical(ado, data, access(cmd), true, &mut ev, now)
            }
            Cmd::Lrd | Cmd::Lwr | Cmd::Lrw => {
                self.logical(logical, data, access(cmd), &mut ev, now)
            }
            Cmd::Armw => {
                head[2..4].copy_from_slice(&next_position);
                let a = if adp == 0 {
                    Access::Read
                } else {
                    Access::Write
                };
                self.physical(ado, data, a, false, &mut ev, now)
            }
            Cmd::Frmw => {
                let a = if configured {
                    Access::Read
                } else {
                    Access::Write
                };
                self.physical(ado, data, a, false, &mut ev, now)
            }
        };
        let mut increment = match cmd {
            Cmd::Aprw | Cmd::Fprw | Cmd::Brw | Cmd::Lrw => u16::from(read) + 2 * u16::from(written),
            _ => u16::from(read || written),
        };
        self.after_datagram(ev, now);

        if cmd.is_logical()
            && self
                .rng
                .chance(self.faults.wrong_wkc_probability, self.faults.seed)
        {
            self.stats.wrong_wkc += 1;
            increment = if increment > 0 {
                increment - 1
            } else {
                increment + 1
            };
        }
        let count = u16::from_le_bytes([wkc[0], wkc[1]]).wrapping_add(increment);
        wkc[..2].copy_from_slice(&count.to_le_bytes());
    }

    /// Register/RAM access by physical address. Returns (read hit, write hit).
    fn physical(
        &mut self,
        start: u16,
        data: &mut [u8],
        access: Access,
        or: bool,
        ev: &mut Events,
        now: Duration,
    ) -> (bool, bool) {
        let (mut read, mut written) = (false, false);
        if access.reads() {
            let s = usize::from(start);
            self.prepare_read(s..s + data.len(), ev, now);
        }
        for (i, b) in data.iter_mut().enumerate() {
            let Ok(addr) = u16::try_from(usize::from(start) + i) else {
                break;
            };
            let original = *b;
            if access.reads() && self.readable(addr) {
                let v = self.mem[usize::from(addr)];
                *b = if or { original | v } else { v };
                read = true;
                self.note_read(addr, ev);
            }
            if access.writes() && self.writable(addr) {
                self.write_byte(addr, original, ev);
                written = true;
            }
        }
        (read, written)
    }

    /// Process data access through the FMMUs. Returns (read hit, write hit).
    fn logical(
        &mut self,
        start: u32,
        data: &mut [u8],
        access: Access,
        ev: &mut Events,
        now: Duration,
    ) -> (bool, bool) {
        let fmmus: [Fmmu; NUM_FMMUS] = core::array::from_fn(|n| self.fmmu(n));
        let start = u64::from(start);
        let end = start + data.len() as u64;
        if access.reads() {
            for f in fmmus.iter().filter(|f| f.enabled && f.read) {
                let (s, e) = (start.max(f.logical), end.min(f.logical + f.len));
                if s < e {
                    let p = f.physical + (s - f.logical);
                    let range = usize::try_from(p).unwrap_or(usize::MAX)
                        ..usize::try_from(p + (e - s)).unwrap_or(usize::MAX);
                    self.prepare_read(range, ev, now);
                }
            }
        }
        let (mut read, mut written) = (false, false);
        for (i, b) in data.iter_mut().enumerate() {
            let l = start + i as u64;
            let original = *b;
            if access.reads() {
                for f in fmmus.iter().filter(|f| f.read) {
                    if let Some(p) = f.map(l) {
                        if self.readable(p) {
                            *b = self.mem[usize::from(p)];
                            read = true;
                            self.note_read(p, ev);
                        }
                    }
                }
            }
            if access.writes() {
                for f in fmmus.iter().filter(|f| f.write) {
                    if let Some(p) = f.map(l) {
                        if self.writable(p) {
                            self.write_byte(p, original, ev);
                            written = true;
                        }
                    }
                }
            }
        }
        (read, written)
    }

    /// Before the MainDevice reads an input buffer, the application fills it.
    fn prepare_read(&mut self, range: Range<usize>, ev: &mut Events, now: Duration) {
        for n in 0..NUM_SMS {
            let sm = self.sm(n);
            let r = sm.range();
            if ev.inputs_refreshed[n]
                || !sm.active()
                || !sm.buffered()
                || sm.ecat_writes()
                || !self.sm_pdi_active(&sm)
                || r.start >= range.end
                || range.start >= r.end
                || !sm.in_ram(self.mem.len())
            {
                continue;
            }
            ev.inputs_refreshed[n] = true;
            self.app.read_inputs(&mut self.mem[r], now);
        }
    }

    fn readable(&self, addr: u16) -> bool {
        if addr < reg::RAM_START {
            return reg::is_present(addr);
        }
        if usize::from(addr) >= self.mem.len() {
            return false;
        }
        match self.sm_at(addr) {
            None => true,
            Some((n, sm)) => {
                self.sm_pdi_active(&sm) && !sm.ecat_writes() && (!sm.mailbox() || self.sm_full(n))
            }
        }
    }

    fn writable(&self, addr: u16) -> bool {
        if addr < reg::RAM_START {
            return reg::is_present(addr);
        }
        if usize::from(addr) >= self.mem.len() {
            return false;
        }
        match self.sm_at(addr) {
            None => true,
            Some((n, sm)) => {
                self.sm_pdi_active(&sm) && sm.ecat_writes() && (!sm.mailbox() || !self.sm_full(n))
            }
        }
    }

    fn note_read(&self, addr: u16, ev: &mut Events) {
        if addr == reg::SII_CONTROL + 1 {
            ev.sii_status_read = true;
        }
        if addr >= reg::RAM_START {
            if let Some((n, sm)) = self.sm_at(addr) {
                if sm.is_last(addr) {
                    ev.sm_last_read[n] = true;
                }
            }
        }
    }

    /// One byte written by ECAT to an accessible address.
    fn write_byte(&mut self, addr: u16, v: u8, ev: &mut Events) {
        let a = usize::from(addr);
        if addr >= reg::RAM_START {
            self.mem[a] = v;
            if let Some((n, sm)) = self.sm_at(addr) {
                if sm.is_last(addr) {
                    ev.sm_last_written[n] = true;
                }
            }
            return;
        }
        let sii_owned_by_ecat = self.mem[usize::from(reg::SII_CONFIG)] & 0x01 == 0;
        let fmmu_end = reg::fmmu(NUM_FMMUS, 0);
        let sm_end = reg::sm(NUM_SMS, 0);
        match addr {
            0x0010 | 0x0011 | 0x0100..=0x0103 | 0x0200 | 0x0201 | 0x0410 | 0x0411 => {
                self.mem[a] = v
            }
            0x0400 | 0x0401 | 0x0420 | 0x0421 => {
                self.mem[a] = v;
                ev.watchdog_written = true;
            }
            0x0120 | 0x0121 => {
                self.mem[a] = v;
                ev.al_control = true;
            }
            // Error and watchdog counters: any write clears.
            0x0300..=0x0313 | 0x0442 | 0x0443 => self.mem[a] = 0,
            0x0500 => {
                if v & 0x02 != 0 {
                    // Force ECAT access: the PDI loses the EEPROM.
                    self.mem[usize::from(reg::SII_PDI_ACCESS)] = 0;
                }
                self.mem[a] = v & 0x01;
            }
            0x0502 if sii_owned_by_ecat => {
                self.mem[a] = (self.mem[a] & !0x01) | (v & 0x01);
            }
            0x0503 if sii_owned_by_ecat => ev.sii_command = Some(v & 0x07),
            0x0504..=0x050F if sii_owned_by_ecat && self.sii_pending.is_none() => self.mem[a] = v,
            // FMMU bytes 13..15 are reserved.
            _ if (reg::FMMU0..fmmu_end).contains(&addr) && (addr - reg::FMMU0) % 16 <= 12 => {
                self.mem[a] = v
            }
            _ if (reg::SM0..sm_end).contains(&addr) => {
                let n = usize::from((addr - reg::SM0) / 8);
                match (addr - reg::SM0) % 8 {
                    // Start, length, control: only while the SM is disabled.
                    0..=4 if self.mem[usize::from(reg::sm(n, 6))] & 0x01 == 0 => self.mem[a] = v,
                    6 => {
                        if ev.sm_activate_old[n].is_none() {
                            ev.sm_activate_old[n] = Some(self.mem[a]);
                        }
                        // Enable, repeat, DC event bits.
                        self.mem[a] = v & 0xC3;
                    }
                    // Status and PDI control are read-only for ECAT (and start, length,
                    // control while the SM is enabled).
                    _ => {}
                }
            }
            // Present but read-only.
            _ => {}
        }
    }

    fn after_datagram(&mut self, ev: Events, now: Duration) {
        for (n, old) in ev.sm_activate_old.iter().enumerate() {
            if let Some(old) = *old {
                self.sm_activate_changed(n, old);
            }
        }
        if ev.watchdog_written {
            // Reprogramming the SM watchdog restarts it.
            self.last_outputs = now;
        }
        // A command pending before this datagram completes once its busy flag was seen.
        if ev.sii_status_read {
            self.sii_complete();
        }
        if let Some(cmd) = ev.sii_command {
            self.sii_command(cmd);
        }
        for n in 0..NUM_SMS {
            if ev.sm_last_written[n] {
                if !self.sm(n).mailbox() {
                    self.outputs_written(n, now);
                } else if self.programmed() {
                    // One-buffer process data: the buffer is full until the firmware takes it.
                    self.set_sm_full(n, true);
                    self.sm_written_at[n] = now;
                } else {
                    self.mailbox_written(n, now);
                }
            }
            if ev.sm_last_read[n] && self.sm(n).mailbox() {
                self.set_sm_full(n, false);
                self.try_deliver();
            }
        }
        if ev.al_control {
            if self.config.firmware_loop.is_zero() {
                self.al_control_written(now);
            } else if self.al_control_written_at.is_none() {
                self.al_control_written_at = Some(now);
            }
        }
    }

    /// The firmware's loop: at each multiple of [`EscConfig::firmware_loop`] it reads AL
    /// control; acts on the value there once a loop has run since the first unread write (the
    /// frame being processed has not written yet, so the value is the one the loop saw).
    fn firmware_reads_al_control(&mut self, now: Duration) {
        let Some(at) = self.al_control_written_at else {
            return;
        };
        let period = self.config.firmware_loop.as_nanos().max(1);
        if now.as_nanos() / period > at.as_nanos() / period {
            self.al_control_written_at = None;
            self.al_control_written(now);
        }
    }

    // ----- registers -----

    fn u16_at(&self, addr: u16) -> u16 {
        let a = usize::from(addr);
        u16::from_le_bytes([self.mem[a], self.mem[a + 1]])
    }

    fn set_u16(&mut self, addr: u16, v: u16) {
        let a = usize::from(addr);
        self.mem[a..a + 2].copy_from_slice(&v.to_le_bytes());
    }

    fn sm(&self, n: usize) -> Sm {
        Sm {
            start: self.u16_at(reg::sm(n, 0)),
            len: self.u16_at(reg::sm(n, 2)),
            control: self.mem[usize::from(reg::sm(n, 4))],
            activate: self.mem[usize::from(reg::sm(n, 6))],
        }
    }

    fn fmmu(&self, n: usize) -> Fmmu {
        let b = usize::from(reg::fmmu(n, 0));
        let m = &self.mem[b..b + 16];
        Fmmu {
            logical: u64::from(u32::from_le_bytes([m[0], m[1], m[2], m[3]])),
            len: u64::from(u16::from_le_bytes([m[4], m[5]])),
            physical: u64::from(u16::from_le_bytes([m[8], m[9]])),
            read: m[11] & 0x01 != 0,
            write: m[11] & 0x02 != 0,
            enabled: m[12] & 0x01 != 0,
        }
    }

    fn sm_at(&self, addr: u16) -> Option<(usize, Sm)> {
        (0..NUM_SMS)
            .map(|n| (n, self.sm(n)))
            .find(|(_, sm)| sm.contains(addr))
    }

    /// The PDI (the application) serves mailbox SMs outside INIT and process data SMs in
    /// SAFE-OP/OP; otherwise it keeps them deactivated (SM register +7 bit 0) and ECAT cannot
    /// access their buffers.
    fn sm_pdi_active(&self, sm: &Sm) -> bool {
        if sm.mailbox() && !self.programmed() {
            self.state != AlState::Init
        } else {
            matches!(self.state, AlState::SafeOp | AlState::Op)
        }
    }

    /// The firmware uses sync managers the MainDevice programs ([`SyncManagers::Programmed`]).
    fn programmed(&self) -> bool {
        matches!(self.config.sync_managers, SyncManagers::Programmed(_))
    }

    fn sm_full(&self, n: usize) -> bool {
        self.mem[usize::from(reg::sm(n, 5))] & 0x08 != 0
    }

    fn set_sm_full(&mut self, n: usize, full: bool) {
        let a = usize::from(reg::sm(n, 5));
        if full {
            self.mem[a] |= 0x08;
        } else {
            self.mem[a] &= !0x08;
        }
    }

    fn sm_activate_changed(&mut self, n: usize, old: u8) {
        let new = self.mem[usize::from(reg::sm(n, 6))];
        if (old ^ new) & 0x01 != 0 {
            // Enabling or disabling resets the buffer state.
            self.set_sm_full(n, false);
            if new & 0x01 != 0 {
                self.try_deliver();
            }
        }
        if (old ^ new) & 0x02 != 0 {
            self.repeat_requested(n);
        }
    }

    fn update_status(&mut self) {
        let status = u16::from(self.state.bits()) | (u16::from(self.error) << 4);
        self.set_u16(reg::AL_STATUS, status);
        self.set_u16(reg::AL_STATUS_CODE, self.code);
        for n in 0..NUM_SMS {
            let sm = self.sm(n);
            let a = usize::from(reg::sm(n, 7));
            if self.sm_pdi_active(&sm) {
                self.mem[a] &= !0x01;
            } else {
                self.mem[a] |= 0x01;
            }
        }
    }

    // ----- SII EEPROM interface -----

    fn load_config_area(&mut self) {
        let pdi_control = self.eeprom.word(0);
        let config = self.eeprom.word(1);
        let config2 = self.eeprom.word(3);
        let alias = self.eeprom.word(4);
        self.set_u16(reg::PDI_CONTROL, pdi_control);
        self.set_u16(reg::PDI_CONFIG, config);
        self.set_u16(reg::PDI_CONFIG + 2, config2);
        self.set_u16(reg::STATION_ALIAS, alias);
    }

    fn sii_command(&mut self, cmd: u8) {
        if self.sii_pending.is_some() {
            // Busy: ignored.
            return;
        }
        let mut status = self.u16_at(reg::SII_CONTROL);
        match cmd {
            0 => status &= !(sc::COMMAND_ERROR | sc::WRITE_ENABLE_ERROR),
            0x01 | 0x02 | 0x04 => {
                status &= !(sc::COMMAND_ERROR | sc::WRITE_ENABLE_ERROR);
                if cmd == 0x02 && status & sc::WRITE_ENABLE == 0 {
                    status |= sc::WRITE_ENABLE_ERROR;
                } else {
                    status |= sc::BUSY | (u16::from(cmd) << 8);
                    self.sii_pending = Some(cmd);
                }
                status &= !sc::WRITE_ENABLE;
            }
            _ => status |= sc::COMMAND_ERROR,
        }
        self.set_u16(reg::SII_CONTROL, status);
    }

    /// Finishes the pending EEPROM command (the MainDevice has seen it busy once).
    fn sii_complete(&mut self) {
        let Some(cmd) = self.sii_pending.take() else {
            return;
        };
        let mut status = self.u16_at(reg::SII_CONTROL) & !(sc::BUSY | 0x0700);
        let a = usize::from(reg::SII_ADDRESS);
        let word = u32::from_le_bytes([
            self.mem[a],
            self.mem[a + 1],
            self.mem[a + 2],
            self.mem[a + 3],
        ]);
        let data = usize::from(reg::SII_DATA);
        match cmd {
            0x01 => {
                let n = if status & sc::READ_8_BYTES != 0 { 8 } else { 4 };
                self.eeprom.read(word, &mut self.mem[data..data + n]);
            }
            0x02 => {
                let value = [self.mem[data], self.mem[data + 1]];
                if !self.eeprom.write_word(word, value) {
                    status |= sc::COMMAND_ERROR;
                }
            }
            _ => {
                if sii::checksum_ok(self.eeprom.image()) {
                    status &= !sc::CHECKSUM_ERROR;
                    self.load_config_area();
                } else {
                    status |= sc::CHECKSUM_ERROR;
                }
            }
        }
        self.set_u16(reg::SII_CONTROL, status);
    }

    // ----- AL state machine -----

    fn al_control_written(&mut self, now: Duration) {
        let control = self.mem[usize::from(reg::AL_CONTROL)];
        let acknowledge = control & 0x10 != 0;
        if acknowledge && self.error {
            self.error = false;
            self.code = al_status::NO_ERROR;
        }
        let from = self.state;
        let Some(to) = AlState::from_bits(control) else {
            if !self.error {
                self.refuse(from, None, al_status::UNKNOWN_STATE);
            }
            self.update_status();
            return;
        };
        if to == from {
            self.update_status();
            return;
        }
        if self.error && to.bits() > from.bits() {
            tracing::debug!(%from, %to, "state request ignored: error not acknowledged");
            self.update_status();
            return;
        }
        match al::classify(from, to) {
            Err(code) => self.refuse(from, Some(to), code),
            Ok(Step::Down) => {
                if let Err(code) = self.app.transition(from, to) {
                    tracing::debug!(%from, %to, code, "downward transition cannot be refused");
                }
                self.enter(to, now);
            }
            Ok(Step::Up(check)) => {
                if let Some(code) = self.faults.refuse_next_transition.take() {
                    self.stats.injected_refusals += 1;
                    self.refuse(from, Some(to), code);
                    return;
                }
                let result = self
                    .check(check)
                    .and_then(|()| self.app.transition(from, to));
                match result {
                    Ok(()) => self.enter(to, now),
                    Err(code) => self.refuse(from, Some(to), code),
                }
            }
        }
    }

    fn refuse(&mut self, from: AlState, to: Option<AlState>, code: u16) {
        tracing::warn!(%from, to = ?to, code = format_args!("{code:#06x}"), "state change refused");
        self.stats.refused_transitions += 1;
        self.error = true;
        self.code = code;
        self.update_status();
    }

    fn enter(&mut self, to: AlState, now: Duration) {
        let from = self.state;
        tracing::debug!(%from, %to, "AL state");
        self.state = to;
        self.stats.transitions += 1;
        if !self.error {
            self.code = al_status::NO_ERROR;
        }
        match to {
            AlState::Init => self.mailbox_reset(),
            AlState::PreOp | AlState::Boot if from == AlState::Init => self.mailbox_reset(),
            AlState::Op => {
                self.last_outputs = now;
                self.set_u16(reg::WATCHDOG_SM_STATUS, 0x0001);
            }
            _ => {}
        }
        self.update_status();
        self.try_deliver();
    }

    fn check(&self, check: Check) -> Result<(), u16> {
        let c = &self.config;
        if let SyncManagers::Programmed(expected) = &c.sync_managers {
            return match check {
                // No mailbox to check, and none to boot with.
                Check::StandardMailbox | Check::Nothing => Ok(()),
                Check::BootstrapMailbox => Err(al_status::BOOTSTRAP_NOT_SUPPORTED),
                Check::ProcessData => self.check_programmed(expected),
            };
        }
        match check {
            Check::StandardMailbox => self.check_mailboxes(
                c.rx_mailbox,
                c.tx_mailbox,
                al_status::INVALID_MAILBOX_CONFIG,
            ),
            Check::BootstrapMailbox => {
                if c.bootstrap_rx_mailbox.1 == 0 || c.bootstrap_tx_mailbox.1 == 0 {
                    return Err(al_status::BOOTSTRAP_NOT_SUPPORTED);
                }
                self.check_mailboxes(
                    c.bootstrap_rx_mailbox,
                    c.bootstrap_tx_mailbox,
                    al_status::INVALID_MAILBOX_CONFIG_BOOT,
                )
            }
            Check::ProcessData => {
                let (outputs, inputs) = self.app.process_image_sizes()?;
                self.check_process_data(
                    2,
                    outputs,
                    c.outputs_address,
                    true,
                    al_status::INVALID_OUTPUT_CONFIG,
                )?;
                self.check_process_data(
                    3,
                    inputs,
                    c.inputs_address,
                    false,
                    al_status::INVALID_INPUT_CONFIG,
                )
            }
            Check::Nothing => Ok(()),
        }
    }

    /// Every sync manager the firmware expects is enabled with its start, length and control.
    fn check_programmed(&self, expected: &[crate::SmSetting]) -> Result<(), u16> {
        for (n, want) in expected.iter().enumerate() {
            let sm = self.sm(n);
            if !(sm.activate & 0x01 != 0
                && sm.start == want.start
                && sm.len == want.len
                && sm.control == want.control)
            {
                tracing::warn!(
                    sm = n,
                    start = format!("{:#06x}", sm.start),
                    len = sm.len,
                    control = format!("{:#04x}", sm.control),
                    enabled = sm.activate & 0x01 != 0,
                    expected = ?want,
                    "sync manager not programmed as the firmware expects: SAFE-OP refused"
                );
                return Err(al_status::INVALID_SM_CONFIG);
            }
        }
        Ok(())
    }

    /// SM0 must be a mailbox the MainDevice writes, SM1 one it reads, both enabled at the SII
    /// start addresses, at least 16 bytes and at most the SII size.
    fn check_mailboxes(&self, rx: (u16, u16), tx: (u16, u16), code: u16) -> Result<(), u16> {
        let ok = |sm: Sm, (start, size): (u16, u16), ecat_writes: bool| {
            sm.activate & 0x01 != 0
                && sm.start == start
                && (16..=size).contains(&sm.len)
                && sm.mailbox()
                && sm.ecat_writes() == ecat_writes
        };
        if ok(self.sm(0), rx, true) && ok(self.sm(1), tx, false) {
            Ok(())
        } else {
            tracing::debug!(sm0 = ?self.sm(0), sm1 = ?self.sm(1), "invalid mailbox configuration");
            Err(code)
        }
    }

    /// A process data SM must be a buffered SM of the right direction at the configured address
    /// with exactly the image size, or disabled (or empty) if the image is empty.
    fn check_process_data(
        &self,
        n: usize,
        size: usize,
        start: u16,
        ecat_writes: bool,
        code: u16,
    ) -> Result<(), u16> {
        let sm = self.sm(n);
        let ok = if size == 0 {
            !sm.active()
        } else {
            sm.activate & 0x01 != 0
                && usize::from(sm.len) == size
                && sm.start == start
                && sm.buffered()
                && sm.ecat_writes() == ecat_writes
                && sm.range().end <= self.mem.len()
        };
        if ok {
            Ok(())
        } else {
            tracing::debug!(n, ?sm, size, "invalid process data configuration");
            Err(code)
        }
    }

    // ----- process data and watchdog -----

    fn outputs_written(&mut self, n: usize, now: Duration) {
        let sm = self.sm(n);
        if self.state == AlState::Op && sm.in_ram(self.mem.len()) {
            self.app.write_outputs(&self.mem[sm.range()], now);
        }
        self.last_outputs = now;
        self.set_u16(reg::WATCHDOG_SM_STATUS, 0x0001);
    }

    fn watchdog_timeout(&self) -> Option<Duration> {
        let outputs = (0..NUM_SMS)
            .map(|n| self.sm(n))
            .find(|sm| sm.active() && sm.buffered() && sm.ecat_writes())?;
        if outputs.control & SM_WATCHDOG_ENABLE == 0 {
            return None;
        }
        let ticks = u64::from(self.u16_at(reg::WATCHDOG_SM));
        if ticks == 0 {
            return None;
        }
        let divider = u64::from(self.u16_at(reg::WATCHDOG_DIVIDER));
        Some(Duration::from_nanos((divider + 2) * 40 * ticks))
    }

    fn watchdog_expired(&mut self) {
        tracing::warn!("SM watchdog expired: OP -> SAFE-OP + ERR 0x001B");
        self.stats.watchdog_trips += 1;
        self.state = AlState::SafeOp;
        self.error = true;
        self.code = al_status::SM_WATCHDOG;
        let counter = usize::from(reg::WATCHDOG_SM_COUNTER);
        self.mem[counter] = self.mem[counter].saturating_add(1);
        self.set_u16(reg::WATCHDOG_SM_STATUS, 0x0000);
        self.app.outputs_lost();
        self.update_status();
    }

    // ----- mailbox -----

    fn mailbox_reset(&mut self) {
        self.mbx.reset();
        self.sdo.reset();
        for n in 0..NUM_SMS {
            if self.sm(n).mailbox() {
                self.set_sm_full(n, false);
            }
        }
    }

    /// The SM the replies go to: the first enabled mailbox SM the MainDevice reads (SM1).
    fn reply_sm(&self) -> Option<(usize, Sm)> {
        (0..NUM_SMS)
            .map(|n| (n, self.sm(n)))
            .find(|(_, sm)| sm.active() && sm.mailbox() && !sm.ecat_writes())
    }

    /// SM0 was written up to its last byte: the application takes the request at once.
    fn mailbox_written(&mut self, n: usize, now: Duration) {
        let range = self.sm(n).range();
        let Some(request) = self.mem.get(range).map(<[u8]>::to_vec) else {
            return;
        };
        self.stats.mailbox_requests += 1;
        if let Some(reply) = self.handle_mailbox(&request, now) {
            if !self.mbx.push(reply) {
                tracing::warn!("mailbox reply queue full, oldest reply dropped");
            }
        }
        self.try_deliver();
    }

    fn handle_mailbox(&mut self, request: &[u8], now: Duration) -> Option<Vec<u8>> {
        let capacity = self
            .reply_sm()
            .map_or(0, |(_, sm)| usize::from(sm.len).saturating_sub(HEADER_LEN));
        if capacity < 4 {
            tracing::debug!("mailbox request without a reply mailbox");
            return None;
        }
        let Some(header) = Header::parse(request) else {
            return Some(self.mailbox_error(mailbox_error::SIZE_TOO_SHORT));
        };
        if HEADER_LEN + header.length > request.len() {
            return Some(self.mailbox_error(mailbox_error::INVALID_SIZE));
        }
        if self.mbx.is_duplicate(header.counter) {
            tracing::debug!(
                counter = header.counter,
                "repeated mailbox request discarded"
            );
            self.stats.mailbox_duplicates += 1;
            return None;
        }
        let payload = &request[HEADER_LEN..HEADER_LEN + header.length];
        let kind = header.mailbox_type;
        let supported =
            mailbox::protocol_bit(kind).is_some_and(|bit| self.config.mailbox_protocols & bit != 0);
        // BOOT offers FoE only (ETG.1000.6: the bootstrap mailbox is for firmware download).
        if !supported || (self.state == AlState::Boot && kind != TYPE_FOE) {
            return Some(self.mailbox_error(mailbox_error::UNSUPPORTED_PROTOCOL));
        }
        if kind == TYPE_COE {
            return match self
                .sdo
                .handle(&mut self.app, payload, self.state, capacity)
            {
                Outcome::Reply(p) => Some(self.message(TYPE_COE, &p)),
                Outcome::None => None,
                Outcome::MailboxError(detail) => Some(self.mailbox_error(detail)),
            };
        }
        let cx = MailboxContext {
            state: self.state,
            now,
            request_size: request.len(),
            reply_capacity: capacity,
        };
        match self.app.mailbox_request(kind, payload, &cx) {
            MailboxReply::Reply(p) if p.len() <= capacity => Some(self.message(kind, &p)),
            MailboxReply::Reply(_) => Some(self.mailbox_error(mailbox_error::NO_MORE_MEMORY)),
            MailboxReply::Silent => None,
            MailboxReply::Unsupported => {
                Some(self.mailbox_error(mailbox_error::UNSUPPORTED_PROTOCOL))
            }
        }
    }

    fn message(&mut self, kind: u8, payload: &[u8]) -> Vec<u8> {
        let counter = self.mbx.next_counter();
        mailbox::message(kind, counter, payload)
    }

    fn mailbox_error(&mut self, detail: u16) -> Vec<u8> {
        tracing::debug!(detail, "mailbox error reply");
        self.message(TYPE_ERR, &mailbox::error_payload(detail))
    }

    /// Places the next queued reply in SM1 if it is free.
    fn try_deliver(&mut self) {
        if self.programmed() {
            return; // no mailbox: SM buffers are the application's
        }
        let Some((n, sm)) = self.reply_sm() else {
            return;
        };
        if !self.sm_pdi_active(&sm) || self.sm_full(n) {
            return;
        }
        if !sm.in_ram(self.mem.len()) {
            return;
        }
        let range = sm.range();
        let Some(reply) = self.mbx.pop() else {
            return;
        };
        let area = &mut self.mem[range];
        area.fill(0);
        let k = reply.len().min(area.len());
        area[..k].copy_from_slice(&reply[..k]);
        self.set_sm_full(n, true);
    }

    /// The MainDevice toggled the repeat bit of SM1: the last reply is placed again and the
    /// toggle acknowledged (ETG.1000.4 mailbox repeat).
    fn repeat_requested(&mut self, n: usize) {
        let sm = self.sm(n);
        if !(sm.mailbox() && !sm.ecat_writes() && sm.in_ram(self.mem.len())) {
            return;
        }
        let range = sm.range();
        if let Some(last) = self.mbx.last_reply() {
            if let Some(area) = self.mem.get_mut(range) {
                area.fill(0);
                let k = last.len().min(area.len());
                area[..k].copy_from_slice(&last[..k]);
                self.set_sm_full(n, true);
            }
        }
        let repeat = self.mem[usize::from(reg::sm(n, 6))] & 0x02;
        let ack = usize::from(reg::sm(n, 7));
        self.mem[ack] = (self.mem[ack] & !0x02) | repeat;
    }
}

/// The firmware's side of programmed one-buffer sync managers (see [`Pdi`]).
struct Buffers<'a> {
    mem: &'a mut Vec<u8>,
    written_at: &'a [Duration; NUM_SMS],
}

impl Buffers<'_> {
    fn sm(&self, n: usize) -> Option<(Sm, usize)> {
        if n >= NUM_SMS {
            return None;
        }
        let at = |a: u16| usize::from(a);
        let u16_at = |a: u16| u16::from_le_bytes([self.mem[at(a)], self.mem[at(a) + 1]]);
        let sm = Sm {
            start: u16_at(reg::sm(n, 0)),
            len: u16_at(reg::sm(n, 2)),
            control: self.mem[at(reg::sm(n, 4))],
            activate: self.mem[at(reg::sm(n, 6))],
        };
        (sm.active() && sm.mailbox() && sm.in_ram(self.mem.len()))
            .then_some((sm, at(reg::sm(n, 5))))
    }
}

impl PdiAccess for Buffers<'_> {
    fn written(&self, n: usize) -> Option<Duration> {
        let (_, status) = self.sm(n).filter(|(sm, _)| sm.ecat_writes())?;
        (self.mem[status] & 0x08 != 0).then_some(self.written_at[n])
    }

    fn take(&mut self, n: usize) -> Option<&[u8]> {
        let (sm, status) = self.sm(n).filter(|(sm, _)| sm.ecat_writes())?;
        if self.mem[status] & 0x08 == 0 {
            return None;
        }
        self.mem[status] &= !0x08;
        Some(&self.mem[sm.range()])
    }

    fn put(&mut self, n: usize, data: &[u8]) -> bool {
        let Some((sm, status)) = self.sm(n).filter(|(sm, _)| !sm.ecat_writes()) else {
            return false;
        };
        if self.mem[status] & 0x08 != 0 {
            return false;
        }
        let buffer = &mut self.mem[sm.range()];
        let len = data.len().min(buffer.len());
        buffer[..len].copy_from_slice(&data[..len]);
        buffer[len..].fill(0);
        self.mem[status] |= 0x08;
        true
    }
}

/// A SubDevice alone on a link answers its frames (see `teleop_ecat_link::serve_link`).
impl<A: Application> teleop_ecat_link::Responder for SubDevice<A> {
    fn respond(&mut self, frame: &[u8], out: &mut [u8], now: Duration) -> Option<usize> {
        self.process_frame_into(frame, out, now)
    }

    fn idle(&mut self, now: Duration) {
        self.tick(now);
    }
}

fn access(cmd: Cmd) -> Access {
    match cmd {
        Cmd::Aprw | Cmd::Fprw | Cmd::Brw | Cmd::Lrw => Access::ReadWrite,
        Cmd::Apwr | Cmd::Fpwr | Cmd::Bwr | Cmd::Lwr => Access::Write,
        _ => Access::Read,
    }
}

#[cfg(test)]
#[path = "esc_tests.rs"]
mod tests;
