//! Unit tests of the ESC: register file, working counter rules, SII interface, AL state
//! machine, mailbox handshake, process data, watchdog, faults.

use super::*;
use crate::{mailbox_protocols, Pdi, SdoAbort, SmSetting, SyncManagers};
use proptest::prelude::*;
use std::collections::BTreeMap;

const MASTER_MAC: [u8; 6] = [0x10; 6];
const STATION: u16 = 0x1000;

const APRD: u8 = 0x01;
const APWR: u8 = 0x02;
const APRW: u8 = 0x03;
const FPRD: u8 = 0x04;
const FPWR: u8 = 0x05;
const FPRW: u8 = 0x06;
const BRD: u8 = 0x07;
const BWR: u8 = 0x08;
const BRW: u8 = 0x09;
const LRD: u8 = 0x0A;
const LWR: u8 = 0x0B;
const LRW: u8 = 0x0C;
const ARMW: u8 = 0x0D;
const FRMW: u8 = 0x0E;

#[derive(Default)]
struct App {
    outputs: usize,
    inputs: usize,
    received: Vec<Vec<u8>>,
    input_value: u8,
    lost: u32,
    transitions: Vec<(AlState, AlState)>,
    refuse: Option<u16>,
    od: BTreeMap<(u16, u8), Vec<u8>>,
    /// With programmed SMs: buffers taken from SM0, each echoed into SM2.
    taken: Vec<Vec<u8>>,
    echo_refused: u32,
    /// The firmware's loop runs once per clock value, after time 0.
    pdi_at: Duration,
}

impl App {
    fn new(outputs: usize, inputs: usize) -> Self {
        let mut od = BTreeMap::new();
        od.insert((0x1018, 1), 0x1234_5678u32.to_le_bytes().to_vec());
        Self {
            outputs,
            inputs,
            input_value: 0xA0,
            od,
            ..Self::default()
        }
    }
}

impl Application for App {
    fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, SdoAbort> {
        self.od
            .get(&(index, sub))
            .cloned()
            .ok_or(SdoAbort::OBJECT_DOES_NOT_EXIST)
    }
    fn sdo_write(&mut self, index: u16, sub: u8, data: &[u8], _: AlState) -> Result<(), SdoAbort> {
        self.od.insert((index, sub), data.to_vec());
        Ok(())
    }
    fn process_image_sizes(&self) -> Result<(usize, usize), u16> {
        Ok((self.outputs, self.inputs))
    }
    fn write_outputs(&mut self, outputs: &[u8], _: Duration) {
        self.received.push(outputs.to_vec());
    }
    fn read_inputs(&mut self, inputs: &mut [u8], _: Duration) {
        for (i, b) in inputs.iter_mut().enumerate() {
            *b = self.input_value.wrapping_add(i as u8);
        }
    }
    fn transition(&mut self, from: AlState, to: AlState) -> Result<(), u16> {
        self.transitions.push((from, to));
        match self.refuse.take() {
            Some(code) => Err(code),
            None => Ok(()),
        }
    }
    fn outputs_lost(&mut self) {
        self.lost += 1;
    }
    fn pdi(&mut self, now: Duration, _: AlState, pdi: &mut Pdi<'_>) {
        if now <= self.pdi_at {
            return;
        }
        self.pdi_at = now;
        if let Some(buffer) = pdi.take(0) {
            let buffer = buffer.to_vec();
            if !pdi.put(2, &buffer) {
                self.echo_refused += 1;
            }
            self.taken.push(buffer);
        }
    }
}

/// One datagram of a test frame.
struct Dg {
    cmd: u8,
    address: u32,
    data: Vec<u8>,
}

fn dg(cmd: u8, adp: u16, ado: u16, data: &[u8]) -> Dg {
    Dg {
        cmd,
        address: u32::from(adp) | (u32::from(ado) << 16),
        data: data.to_vec(),
    }
}

fn ldg(cmd: u8, logical: u32, data: &[u8]) -> Dg {
    Dg {
        cmd,
        address: logical,
        data: data.to_vec(),
    }
}

fn build_frame(dgs: &[Dg]) -> Vec<u8> {
    let mut payload = Vec::new();
    for (i, d) in dgs.iter().enumerate() {
        let more = if i + 1 < dgs.len() { 0x8000 } else { 0 };
        payload.push(d.cmd);
        payload.push(i as u8);
        payload.extend_from_slice(&d.address.to_le_bytes());
        payload.extend_from_slice(&(d.data.len() as u16 | more).to_le_bytes());
        payload.extend_from_slice(&[0, 0]);
        payload.extend_from_slice(&d.data);
        payload.extend_from_slice(&[0, 0]);
    }
    let mut f = vec![0xFF; 6];
    f.extend_from_slice(&MASTER_MAC);
    f.extend_from_slice(&[0x88, 0xA4]);
    f.extend_from_slice(&(payload.len() as u16 | 0x1000).to_le_bytes());
    f.extend_from_slice(&payload);
    f
}

/// (address field, data, working counter) of each datagram of a reply.
fn parse_reply(reply: &[u8]) -> Vec<(u32, Vec<u8>, u16)> {
    let mut out = Vec::new();
    let mut o = 16;
    loop {
        let address = u32::from_le_bytes([reply[o + 2], reply[o + 3], reply[o + 4], reply[o + 5]]);
        let flags = u16::from_le_bytes([reply[o + 6], reply[o + 7]]);
        let len = usize::from(flags & 0x7FF);
        let data = reply[o + 10..o + 10 + len].to_vec();
        let wkc = u16::from_le_bytes([reply[o + 10 + len], reply[o + 11 + len]]);
        out.push((address, data, wkc));
        o += 12 + len;
        if flags & 0x8000 == 0 {
            return out;
        }
    }
}

struct Bus {
    sd: SubDevice<App>,
    now: Duration,
}

impl Bus {
    fn new(app: App) -> Self {
        Self::with_config(EscConfig::default(), app)
    }

    fn with_config(config: EscConfig, app: App) -> Self {
        let mut bus = Self {
            sd: SubDevice::new(config, app),
            now: Duration::ZERO,
        };
        assert_eq!(
            bus.one(dg(APWR, 0, reg::STATION_ADDRESS, &STATION.to_le_bytes()))
                .1,
            1
        );
        bus
    }

    fn frame(&mut self, dgs: &[Dg]) -> Vec<(u32, Vec<u8>, u16)> {
        let reply = self
            .sd
            .process_frame(&build_frame(dgs), self.now)
            .expect("reply");
        parse_reply(&reply)
    }

    fn one(&mut self, d: Dg) -> (Vec<u8>, u16) {
        let (_, data, wkc) = self.frame(&[d]).remove(0);
        (data, wkc)
    }

    fn fpwr(&mut self, register: u16, data: &[u8]) -> u16 {
        self.one(dg(FPWR, STATION, register, data)).1
    }

    fn fprd(&mut self, register: u16, len: usize) -> (Vec<u8>, u16) {
        self.one(dg(FPRD, STATION, register, &vec![0; len]))
    }

    fn reg16(&mut self, register: u16) -> u16 {
        let (d, wkc) = self.fprd(register, 2);
        assert_eq!(wkc, 1);
        u16::from_le_bytes([d[0], d[1]])
    }

    fn request(&mut self, state: u16) -> (u16, u16) {
        assert_eq!(self.fpwr(reg::AL_CONTROL, &state.to_le_bytes()), 1);
        (self.reg16(reg::AL_STATUS), self.reg16(reg::AL_STATUS_CODE))
    }

    /// Disables SM `n`, then writes its whole configuration (as a MainDevice must: start,
    /// length and control are only writable while the SM is disabled).
    fn sm(&mut self, n: usize, start: u16, len: u16, control: u8, enable: bool) {
        assert_eq!(self.fpwr(reg::sm(n, 6), &[0]), 1);
        let mut b = start.to_le_bytes().to_vec();
        b.extend_from_slice(&len.to_le_bytes());
        b.extend_from_slice(&[control, 0, u8::from(enable), 0]);
        assert_eq!(self.fpwr(reg::sm(n, 0), &b), 1);
    }

    fn fmmu(&mut self, n: usize, logical: u32, len: u16, physical: u16, kind: u8) {
        let mut b = logical.to_le_bytes().to_vec();
        b.extend_from_slice(&len.to_le_bytes());
        b.extend_from_slice(&[0, 7]);
        b.extend_from_slice(&physical.to_le_bytes());
        b.extend_from_slice(&[0, kind, 1, 0, 0, 0]);
        assert_eq!(self.fpwr(reg::fmmu(n, 0), &b), 1);
    }

    fn mailboxes(&mut self) {
        self.sm(0, 0x1000, 128, 0x26, true);
        self.sm(1, 0x1080, 128, 0x22, true);
    }

    fn enter_preop(&mut self) {
        self.mailboxes();
        assert_eq!(self.request(0x02), (0x02, 0));
    }

    /// PRE-OP -> SAFE-OP -> OP with SM2/SM3 and FMMUs as ethercrab lays them out: inputs at
    /// logical 0, outputs right after.
    fn enter_op(&mut self) {
        self.enter_preop();
        let (o, i) = (self.sd.app().outputs, self.sd.app().inputs);
        self.sm(2, 0x1100, o as u16, 0x64, o > 0);
        self.sm(3, 0x1400, i as u16, 0x20, i > 0);
        self.fmmu(0, i as u32, o as u16, 0x1100, 2);
        self.fmmu(1, 0, i as u16, 0x1400, 1);
        assert_eq!(self.request(0x04), (0x04, 0));
        assert_eq!(self.request(0x08), (0x08, 0));
    }

    /// Writes a whole mailbox request into SM0.
    fn mailbox_write(&mut self, message: &[u8]) -> u16 {
        let mut m = message.to_vec();
        m.resize(128, 0);
        self.fpwr(0x1000, &m)
    }

    fn mailbox_read(&mut self) -> (Vec<u8>, u16) {
        self.fprd(0x1080, 128)
    }
}

/// The datagrams that put SM0/SM1 on the standard mailbox (0x1000 and 0x1080, 128 bytes each).
fn standard_mailbox() -> [Dg; 2] {
    [
        dg(BWR, 0, reg::sm(0, 0), &[0x00, 0x10, 128, 0, 0x26, 0, 1, 0]),
        dg(BWR, 0, reg::sm(1, 0), &[0x80, 0x10, 128, 0, 0x22, 0, 1, 0]),
    ]
}

fn sdo_upload(counter: u8, index: u16, sub: u8) -> Vec<u8> {
    let i = index.to_le_bytes();
    vec![
        10,
        0,
        0,
        0,
        0,
        0x03 | (counter << 4),
        0x00,
        0x20,
        0x40,
        i[0],
        i[1],
        sub,
        0,
        0,
        0,
        0,
    ]
}

#[test]
fn register_file_after_power_on() {
    let mut bus = Bus::new(App::new(4, 6));
    let (info, wkc) = bus.fprd(0x0000, 10);
    assert_eq!(wkc, 1);
    assert_eq!(info[0], ESC_TYPE);
    assert_eq!(info[4], 3, "FMMUs");
    assert_eq!(info[5], 4, "SyncManagers");
    assert_eq!(info[6], 8, "RAM KiB");
    assert_eq!(u16::from_le_bytes([info[8], info[9]]) & 0x0004, 0, "no DC");
    assert_eq!(bus.reg16(reg::STATION_ADDRESS), STATION);
    let dl = bus.reg16(reg::DL_STATUS);
    assert_eq!(dl & 0x0010, 0x0010, "link on port 0");
    assert_eq!(dl & 0x0200, 0x0200, "communication on port 0");
    assert_eq!(bus.reg16(reg::AL_STATUS), 0x0001);
    assert_eq!(bus.reg16(reg::AL_STATUS_CODE), 0);
    assert_eq!(bus.reg16(reg::WATCHDOG_DIVIDER), 2498);
    assert_eq!(bus.reg16(reg::WATCHDOG_SM), 1000, "100 ms in 100 us ticks");
    let sii = bus.reg16(reg::SII_CONTROL);
    assert_eq!(sii & sc::READ_8_BYTES, sc::READ_8_BYTES);
    assert_eq!(sii & (sc::BUSY | sc::CHECKSUM_ERROR), 0);
    assert_eq!(bus.reg16(reg::PDI_CONTROL), sii::PDI_CONTROL);

    // Read-only registers ignore writes (but exist, so the datagram counts).
    assert_eq!(bus.fpwr(reg::TYPE, &[0x55]), 1);
    assert_eq!(bus.fprd(reg::TYPE, 1).0, [ESC_TYPE]);
    assert_eq!(bus.fpwr(reg::STATION_ALIAS, &[0x34, 0x12]), 1);
    assert_eq!(bus.reg16(reg::STATION_ALIAS), 0);
    assert_eq!(bus.fpwr(reg::AL_STATUS, &[0x08, 0]), 1);
    assert_eq!(bus.reg16(reg::AL_STATUS), 0x0001);
    // SM status byte is read-only; SM start/length only writable while disabled.
    bus.mailboxes();
    assert_eq!(bus.fpwr(reg::sm(0, 0), &[0x00, 0x20]), 1);
    assert_eq!(bus.reg16(reg::sm(0, 0)), 0x1000);
    assert_eq!(bus.fpwr(reg::sm(0, 5), &[0x08]), 1);
    assert_eq!(bus.fprd(reg::sm(0, 5), 1).0, [0]);
    // Error counters clear on write.
    assert_eq!(bus.fpwr(reg::ERROR_COUNTERS, &[0xFF; 4]), 1);
    assert_eq!(bus.fprd(reg::ERROR_COUNTERS, 4).0, [0; 4]);
    // Absent registers (DC, FMMU 3, SM 4) neither read nor count.
    assert_eq!(bus.fprd(0x0910, 8), (vec![0; 8], 0));
    assert_eq!(bus.fpwr(0x0900, &[1, 2, 3, 4]), 0);
    assert_eq!(bus.fpwr(reg::fmmu(3, 0), &[0; 16]), 0);
    assert_eq!(bus.fpwr(reg::sm(4, 0), &[0; 8]), 0);
    // A datagram straddling present and absent bytes counts once.
    let (d, wkc) = bus.fprd(0x0130, 8);
    assert_eq!(wkc, 1);
    assert_eq!(d, [1, 0, 0, 0, 0, 0, 0, 0]);
}

#[test]
fn working_counter_rules_for_every_command() {
    let mut bus = Bus::new(App::new(4, 6));
    // Auto increment: only the device at position 0 is addressed; the position is incremented.
    let r = bus.frame(&[
        dg(APRD, 0, reg::TYPE, &[0]),
        dg(APRD, 0xFFFF, reg::TYPE, &[0]),
        dg(APWR, 0, 0x0200, &[1, 0]),
        dg(APRW, 0, 0x0200, &[2, 0]),
        dg(APWR, 1, 0x0200, &[3, 0]),
    ]);
    assert_eq!(r[0], (1, vec![ESC_TYPE], 1));
    assert_eq!(r[1], (0, vec![0], 0));
    assert_eq!(r[2].2, 1);
    assert_eq!(r[3], (1 | (0x0200 << 16), vec![1, 0], 3));
    assert_eq!(r[4].2, 0);
    assert_eq!(bus.fprd(0x0200, 2).0, [2, 0]);

    // Configured address.
    let r = bus.frame(&[
        dg(FPRD, STATION, reg::TYPE, &[0]),
        dg(FPRD, STATION + 1, reg::TYPE, &[0]),
        dg(FPWR, STATION, 0x0200, &[4, 0]),
        dg(FPRW, STATION, 0x0200, &[5, 0]),
        dg(FPRW, STATION + 1, 0x0200, &[6, 0]),
    ]);
    assert_eq!(r[0], (u32::from(STATION), vec![ESC_TYPE], 1));
    assert_eq!(r[1].2, 0);
    assert_eq!(r[2].2, 1);
    assert_eq!((r[3].1.clone(), r[3].2), (vec![4, 0], 3));
    assert_eq!((r[4].1.clone(), r[4].2), (vec![6, 0], 0));
    // Alias addressing only once enabled in DL control.
    assert_eq!(bus.one(dg(FPRD, 0, reg::TYPE, &[0])).1, 0);
    assert_eq!(bus.fpwr(reg::DL_CONTROL + 3, &[1]), 1);
    assert_eq!(
        bus.one(dg(FPRD, 0, reg::TYPE, &[0])).1,
        1,
        "alias 0 now matches"
    );

    // Broadcast: read ORs, position incremented.
    let r = bus.frame(&[
        dg(BRD, 0, reg::TYPE, &[0x10]),
        dg(BWR, 7, 0x0200, &[7, 0]),
        dg(BRW, 0, 0x0200, &[0x08, 0]),
    ]);
    assert_eq!(r[0], (1, vec![0x10 | ESC_TYPE], 1));
    assert_eq!(r[1], (8 | (0x0200 << 16), vec![7, 0], 1));
    assert_eq!((r[2].1.clone(), r[2].2), (vec![0x0F, 0], 3));
    assert_eq!(bus.fprd(0x0200, 2).0, [8, 0]);

    // Read-multiple-write: the addressed device reads, the others write.
    let r = bus.frame(&[
        dg(ARMW, 0, 0x0200, &[0, 0]),
        dg(ARMW, 0xFFFF, 0x0200, &[9, 0]),
        dg(FRMW, STATION, 0x0200, &[0, 0]),
        dg(FRMW, STATION + 1, 0x0200, &[10, 0]),
    ]);
    assert_eq!((r[0].1.clone(), r[0].2), (vec![8, 0], 1));
    assert_eq!(r[1].2, 1);
    assert_eq!((r[2].1.clone(), r[2].2), (vec![9, 0], 1));
    assert_eq!(r[3].2, 1);
    assert_eq!(bus.fprd(0x0200, 2).0, [10, 0]);

    // NOP and unknown commands are passed through untouched.
    let r = bus.frame(&[dg(0x00, 0, 0x0000, &[1]), dg(0x0F, 0, 0x0000, &[1])]);
    assert_eq!(r[0], (0, vec![1], 0));
    assert_eq!(r[1], (0, vec![1], 0));

    // Logical commands: no process data before SAFE-OP...
    bus.enter_preop();
    bus.sm(2, 0x1100, 4, 0x64, true);
    bus.sm(3, 0x1400, 6, 0x20, true);
    bus.fmmu(0, 6, 4, 0x1100, 2);
    bus.fmmu(1, 0, 6, 0x1400, 1);
    assert_eq!(bus.one(ldg(LRW, 0, &[0; 10])).1, 0);
    // ...in SAFE-OP inputs +1, outputs +2 (accepted by the ESC, ignored by the application)...
    assert_eq!(bus.request(0x04), (0x04, 0));
    let (data, wkc) = bus.one(ldg(LRW, 0, &[0, 0, 0, 0, 0, 0, 1, 2, 3, 4]));
    assert_eq!(wkc, 3);
    assert_eq!(&data[..6], &[0xA0, 0xA1, 0xA2, 0xA3, 0xA4, 0xA5]);
    assert!(bus.sd.app().received.is_empty());
    // ...and in OP.
    assert_eq!(bus.request(0x08), (0x08, 0));
    assert_eq!(bus.one(ldg(LRD, 0, &[0; 10])).1, 1);
    assert_eq!(bus.one(ldg(LWR, 0, &[0, 0, 0, 0, 0, 0, 5, 6, 7, 8])).1, 1);
    let (data, wkc) = bus.one(ldg(LRW, 0, &[0, 0, 0, 0, 0, 0, 1, 2, 3, 4]));
    assert_eq!(wkc, 3);
    assert_eq!(data, [0xA0, 0xA1, 0xA2, 0xA3, 0xA4, 0xA5, 1, 2, 3, 4]);
    assert_eq!(bus.sd.app().received, [vec![5, 6, 7, 8], vec![1, 2, 3, 4]]);
    // Only the output FMMU hit: write only.
    assert_eq!(bus.one(ldg(LRW, 6, &[0; 4])).1, 2);
    // Only the input FMMU hit.
    assert_eq!(bus.one(ldg(LRW, 0, &[0; 6])).1, 1);
    // Outside every FMMU.
    assert_eq!(bus.one(ldg(LRW, 0x100, &[0; 4])).1, 0);
    // ECAT cannot write the input buffer nor read the output buffer.
    assert_eq!(bus.fpwr(0x1400, &[0; 6]), 0);
    assert_eq!(bus.fprd(0x1100, 4).1, 0);
    assert_eq!(bus.fprd(0x1400, 6).1, 1);
    // Plain RAM outside any SM is accessible; beyond the RAM nothing is.
    assert_eq!(bus.fpwr(0x2000, &[1, 2]), 1);
    assert_eq!(bus.fprd(0x2000, 2), (vec![1, 2], 1));
    assert_eq!(bus.fprd(0xF000, 2), (vec![0, 0], 0));
}

#[test]
fn sii_interface_reads_writes_and_reloads() {
    let mut config = EscConfig::default();
    config.identity.vendor_id = 0x00BC_0000;
    let mut bus = Bus::with_config(config, App::new(4, 6));
    // Read word 8 (vendor ID): command + address in one write.
    assert_eq!(
        bus.fpwr(reg::SII_CONTROL, &[0x00, 0x01, 0x08, 0x00, 0x00, 0x00]),
        1
    );
    let status = bus.reg16(reg::SII_CONTROL);
    assert_eq!(status & sc::BUSY, sc::BUSY, "busy until seen once");
    assert_eq!(status & sc::READ, sc::READ);
    assert_eq!(bus.reg16(reg::SII_CONTROL) & (sc::BUSY | sc::READ), 0);
    let (data, wkc) = bus.fprd(reg::SII_DATA, 8);
    assert_eq!(wkc, 1);
    assert_eq!(&data[..4], &0x00BC_0000u32.to_le_bytes());
    assert_eq!(&data[4..], &1u32.to_le_bytes(), "product code follows");

    // 4-byte reads: only 0x0508..0x050B are loaded.
    bus.sd.set_sii_8_byte_reads(false);
    assert_eq!(bus.reg16(reg::SII_CONTROL) & sc::READ_8_BYTES, 0);
    bus.fpwr(reg::SII_DATA, &[0; 8]);
    bus.fpwr(reg::SII_CONTROL, &[0x00, 0x01, 0x08, 0x00, 0x00, 0x00]);
    bus.reg16(reg::SII_CONTROL);
    assert_eq!(
        &bus.fprd(reg::SII_DATA, 8).0,
        &[0x00, 0x00, 0xBC, 0x00, 0, 0, 0, 0]
    );
    bus.sd.set_sii_8_byte_reads(true);

    // Beyond the EEPROM: blank.
    bus.fpwr(reg::SII_CONTROL, &[0x00, 0x01, 0xF0, 0x7F, 0x00, 0x00]);
    bus.reg16(reg::SII_CONTROL);
    assert_eq!(bus.fprd(reg::SII_DATA, 8).0, [0xFF; 8]);

    // Write without write enable: error, nothing written.
    bus.fpwr(reg::SII_DATA, &[0x34, 0x12]);
    bus.fpwr(reg::SII_CONTROL, &[0x00, 0x02, 0x04, 0x00]);
    let status = bus.reg16(reg::SII_CONTROL);
    assert_eq!(status & sc::WRITE_ENABLE_ERROR, sc::WRITE_ENABLE_ERROR);
    // Error reset with an empty command.
    bus.fpwr(reg::SII_CONTROL, &[0x00, 0x00]);
    assert_eq!(bus.reg16(reg::SII_CONTROL) & sc::WRITE_ENABLE_ERROR, 0);

    // Write the station alias (word 4) and the matching checksum (word 7), then reload.
    let mut area = bus.sd.sii_image()[..14].to_vec();
    area[8..10].copy_from_slice(&0x1234u16.to_le_bytes());
    let crc = sii::crc8(&area);
    for (word, value) in [(4u8, [0x34, 0x12]), (7, [crc, 0])] {
        bus.fpwr(reg::SII_DATA, &value);
        bus.fpwr(reg::SII_CONTROL, &[0x01, 0x02, word, 0x00]);
        assert_eq!(bus.reg16(reg::SII_CONTROL) & sc::BUSY, sc::BUSY);
        assert_eq!(
            bus.reg16(reg::SII_CONTROL) & (sc::BUSY | sc::COMMAND_ERROR),
            0
        );
    }
    assert_eq!(bus.reg16(reg::STATION_ALIAS), 0, "loaded on reload only");
    bus.fpwr(reg::SII_CONTROL, &[0x00, 0x04]);
    bus.reg16(reg::SII_CONTROL);
    assert_eq!(bus.reg16(reg::SII_CONTROL) & sc::CHECKSUM_ERROR, 0);
    assert_eq!(bus.reg16(reg::STATION_ALIAS), 0x1234);
    // A bad checksum is reported on reload.
    bus.fpwr(reg::SII_DATA, &[0x00, 0x00]);
    bus.fpwr(reg::SII_CONTROL, &[0x01, 0x02, 0x07, 0x00]);
    bus.reg16(reg::SII_CONTROL);
    bus.fpwr(reg::SII_CONTROL, &[0x00, 0x04]);
    bus.reg16(reg::SII_CONTROL);
    assert_eq!(
        bus.reg16(reg::SII_CONTROL) & sc::CHECKSUM_ERROR,
        sc::CHECKSUM_ERROR
    );

    // Two commands at once: command error.
    bus.fpwr(reg::SII_CONTROL, &[0x00, 0x03]);
    assert_eq!(
        bus.reg16(reg::SII_CONTROL) & sc::COMMAND_ERROR,
        sc::COMMAND_ERROR
    );

    // EEPROM assigned to the PDI: ECAT commands are discarded.
    bus.fpwr(reg::SII_CONFIG, &[0x01]);
    bus.fpwr(reg::SII_CONTROL, &[0x00, 0x01, 0x08, 0x00]);
    assert_eq!(bus.reg16(reg::SII_CONTROL) & sc::BUSY, 0);
    bus.fpwr(reg::SII_CONFIG, &[0x02]);
    assert_eq!(bus.fprd(reg::SII_CONFIG, 2).0, [0, 0]);
}

#[test]
fn al_state_machine_rules() {
    let mut bus = Bus::new(App::new(4, 6));
    // Invalid transition: error flag and 0x0011, state kept.
    assert_eq!(bus.request(0x08), (0x11, 0x0011));
    // Higher states are ignored until the error is acknowledged.
    bus.mailboxes();
    assert_eq!(bus.request(0x02), (0x11, 0x0011));
    // Acknowledge and request in one write.
    assert_eq!(bus.request(0x12), (0x02, 0));
    // Unknown state.
    assert_eq!(bus.request(0x05), (0x12, 0x0012));
    assert_eq!(bus.request(0x12), (0x02, 0));
    // PRE-OP -> OP is not allowed, PRE-OP -> BOOT neither.
    assert_eq!(bus.request(0x08), (0x12, 0x0011));
    assert_eq!(bus.request(0x13), (0x12, 0x0011));
    // Lower states are taken without acknowledge, the error stays.
    assert_eq!(bus.request(0x01), (0x11, 0x0011));
    assert_eq!(bus.request(0x11), (0x01, 0));
    assert_eq!(bus.sd.al_state(), (AlState::Init, false, 0));

    // INIT -> PRE-OP needs valid mailbox SMs.
    bus.sm(0, 0x1000, 128, 0x26, false);
    assert_eq!(bus.request(0x02), (0x11, 0x0016));
    bus.fpwr(reg::sm(0, 6), &[1]);
    bus.sm(1, 0x1080, 128, 0x26, true); // wrong direction
    assert_eq!(bus.request(0x12), (0x11, 0x0016));
    bus.sm(1, 0x1080, 0, 0x22, false);
    bus.sm(1, 0x1080, 200, 0x22, true); // larger than the SII mailbox
    assert_eq!(bus.request(0x12), (0x11, 0x0016));
    bus.fpwr(reg::sm(1, 6), &[0]);
    bus.sm(1, 0x1080, 64, 0x22, true); // smaller is fine
    assert_eq!(bus.request(0x12), (0x02, 0));

    // PRE-OP -> SAFE-OP checks SM2/SM3 against the process image.
    bus.sm(2, 0x1100, 2, 0x64, true);
    bus.sm(3, 0x1400, 6, 0x20, true);
    assert_eq!(bus.request(0x04), (0x12, 0x001D));
    bus.fpwr(reg::sm(2, 6), &[0]);
    bus.sm(2, 0x1100, 4, 0x64, true);
    bus.fpwr(reg::sm(3, 6), &[0]);
    bus.sm(3, 0x1400, 6, 0x24, true); // wrong direction
    assert_eq!(bus.request(0x14), (0x12, 0x001E));
    bus.fpwr(reg::sm(3, 6), &[0]);
    bus.sm(3, 0x1400, 6, 0x20, true);
    // The application may refuse.
    bus.sd.app_mut().refuse = Some(0x0024);
    assert_eq!(bus.request(0x14), (0x12, 0x0024));
    assert_eq!(bus.request(0x14), (0x04, 0));
    assert_eq!(bus.request(0x08), (0x08, 0));
    let t = &bus.sd.app().transitions;
    assert_eq!(
        t[t.len() - 3..],
        [
            (AlState::PreOp, AlState::SafeOp),
            (AlState::PreOp, AlState::SafeOp),
            (AlState::SafeOp, AlState::Op)
        ]
    );
    // Downward to INIT.
    assert_eq!(bus.request(0x01), (0x01, 0));

    // Injected refusal: only the next upward request.
    bus.sd.faults().refuse_next_transition = Some(0x0020);
    assert_eq!(bus.request(0x02), (0x11, 0x0020));
    assert_eq!(bus.sd.faults().refuse_next_transition, None);
    assert_eq!(bus.request(0x12), (0x02, 0));
    let stats = bus.sd.stats();
    assert_eq!(stats.injected_refusals, 1);
    assert!(stats.refused_transitions >= 10);
}

#[test]
fn bootstrap_state() {
    let mut bus = Bus::new(App::new(0, 0));
    bus.mailboxes();
    assert_eq!(bus.request(0x03), (0x03, 0));
    // CoE is not available in BOOT: mailbox error "unsupported protocol".
    assert_eq!(bus.mailbox_write(&sdo_upload(1, 0x1018, 1)), 1);
    let (reply, wkc) = bus.mailbox_read();
    assert_eq!(wkc, 1);
    assert_eq!(&reply[..10], &[4, 0, 0, 0, 0, 0x10, 0x01, 0x00, 0x02, 0x00]);
    // BOOT -> PRE-OP is invalid, BOOT -> INIT fine.
    assert_eq!(bus.request(0x02), (0x13, 0x0011));
    assert_eq!(bus.request(0x01), (0x11, 0x0011));
    assert_eq!(bus.request(0x11), (0x01, 0));

    // No bootstrap mailbox: no BOOT.
    let config = EscConfig {
        bootstrap_rx_mailbox: (0, 0),
        bootstrap_tx_mailbox: (0, 0),
        ..EscConfig::default()
    };
    let mut bus = Bus::with_config(config, App::new(0, 0));
    bus.mailboxes();
    assert_eq!(bus.request(0x03), (0x11, 0x0013));
}

#[test]
fn mailbox_handshake() {
    let mut bus = Bus::new(App::new(4, 6));
    bus.mailboxes();
    // INIT: the mailbox is not served.
    assert_eq!(bus.mailbox_write(&sdo_upload(1, 0x1018, 1)), 0);
    bus.enter_preop();
    // Empty reply mailbox: reading does not count.
    assert_eq!(bus.mailbox_read().1, 0);
    assert_eq!(bus.fprd(reg::sm(1, 5), 1).0[0] & 0x08, 0);
    // A partial write (not reaching the last byte) is not a request.
    assert_eq!(bus.fpwr(0x1000, &sdo_upload(1, 0x1018, 1)), 1);
    assert_eq!(bus.sd.stats().mailbox_requests, 0);
    // Whole mailbox: request processed, reply in SM1, SM1 full.
    assert_eq!(bus.mailbox_write(&sdo_upload(1, 0x1018, 1)), 1);
    assert_eq!(bus.fprd(reg::sm(1, 5), 1).0[0] & 0x08, 0x08);
    let (reply, wkc) = bus.mailbox_read();
    assert_eq!(wkc, 1);
    assert_eq!(&reply[..6], &[10, 0, 0, 0, 0, 0x13]);
    assert_eq!(
        &reply[6..16],
        &[0x00, 0x30, 0x43, 0x18, 0x10, 1, 0x78, 0x56, 0x34, 0x12]
    );
    // Reading the last byte emptied it.
    assert_eq!(bus.fprd(reg::sm(1, 5), 1).0[0] & 0x08, 0);
    assert_eq!(bus.mailbox_read().1, 0);

    // Same counter again: a repeated request, discarded.
    assert_eq!(bus.mailbox_write(&sdo_upload(1, 0x1018, 1)), 1);
    assert_eq!(bus.mailbox_read().1, 0);
    assert_eq!(bus.sd.stats().mailbox_duplicates, 1);

    // Two requests before reading: the second reply waits for SM1.
    assert_eq!(bus.mailbox_write(&sdo_upload(2, 0x1018, 1)), 1);
    assert_eq!(bus.mailbox_write(&sdo_upload(3, 0x1018, 2)), 1);
    let (first, _) = bus.mailbox_read();
    assert_eq!(first[5] >> 4, 2, "reply counter");
    let (second, wkc) = bus.mailbox_read();
    assert_eq!(wkc, 1);
    assert_eq!(
        &second[6..16],
        &[0x00, 0x20, 0x80, 0x18, 0x10, 2, 0x00, 0x00, 0x02, 0x06]
    );

    // Repeat: toggling SM1's repeat bit puts the last reply back and acknowledges.
    assert_eq!(bus.fpwr(reg::sm(1, 6), &[0x03]), 1);
    assert_eq!(bus.fprd(reg::sm(1, 7), 1).0[0] & 0x02, 0x02);
    let (again, wkc) = bus.mailbox_read();
    assert_eq!(wkc, 1);
    assert_eq!(again, second);

    // A protocol the SII does not announce: mailbox error "unsupported protocol".
    let mut foe = vec![6, 0, 0, 0, 0, 0x44];
    foe.extend_from_slice(&[0x01, 0, 0, 0, 0, 0]);
    bus.mailbox_write(&foe);
    let (reply, _) = bus.mailbox_read();
    assert_eq!(
        &reply[..10],
        &[4, 0, 0, 0, 0, (reply[5] & 0xF0), 0x01, 0x00, 0x02, 0x00]
    );
    // Length beyond the mailbox: invalid size.
    bus.mailbox_write(&[200, 0, 0, 0, 0, 0x53]);
    let (reply, _) = bus.mailbox_read();
    assert_eq!(&reply[6..10], &[0x01, 0x00, 0x08, 0x00]);

    // Back to INIT drops everything.
    bus.mailbox_write(&sdo_upload(6, 0x1018, 1));
    assert_eq!(bus.request(0x01), (0x01, 0));
    assert_eq!(bus.fprd(reg::sm(1, 5), 1).0[0] & 0x08, 0);
}

#[test]
fn other_mailbox_protocols_reach_the_application() {
    struct Foe(App);
    impl Application for Foe {
        fn sdo_read(&mut self, i: u16, s: u8) -> Result<Vec<u8>, SdoAbort> {
            self.0.sdo_read(i, s)
        }
        fn sdo_write(&mut self, i: u16, s: u8, d: &[u8], st: AlState) -> Result<(), SdoAbort> {
            self.0.sdo_write(i, s, d, st)
        }
        fn process_image_sizes(&self) -> Result<(usize, usize), u16> {
            Ok((0, 0))
        }
        fn write_outputs(&mut self, _: &[u8], _: Duration) {}
        fn read_inputs(&mut self, _: &mut [u8], _: Duration) {}
        fn mailbox(&mut self, kind: u8, payload: &[u8], state: AlState) -> Option<Vec<u8>> {
            (kind == 4 && state == AlState::Boot).then(|| payload.iter().rev().copied().collect())
        }
    }
    let config = EscConfig {
        mailbox_protocols: mailbox_protocols::COE | mailbox_protocols::FOE,
        ..EscConfig::default()
    };
    let mut sd = SubDevice::new(config, Foe(App::new(0, 0)));
    let mut now = Duration::ZERO;
    let mut run = |sd: &mut SubDevice<Foe>, d: Dg| {
        now += Duration::from_millis(1);
        parse_reply(&sd.process_frame(&build_frame(&[d]), now).expect("reply")).remove(0)
    };
    for d in standard_mailbox() {
        run(&mut sd, d);
    }
    run(&mut sd, dg(BWR, 0, reg::AL_CONTROL, &[0x03, 0]));
    assert_eq!(sd.al_state(), (AlState::Boot, false, 0));
    let mut m = vec![3, 0, 0, 0, 0, 0x14, 1, 2, 3];
    m.resize(128, 0);
    assert_eq!(run(&mut sd, dg(BWR, 0, 0x1000, &m)).2, 1);
    let (_, reply, wkc) = run(&mut sd, dg(BRD, 0, 0x1080, &[0; 128]));
    assert_eq!(wkc, 1);
    assert_eq!(&reply[..9], &[3, 0, 0, 0, 0, 0x14, 3, 2, 1]);
}

/// An application with a firmware loader: FoE requests are recorded with their context and
/// echoed (or not answered, for an FoE ERR); it asks for a restart at a set time.
#[derive(Default)]
struct Loader {
    requests: Vec<(u8, Vec<u8>, MailboxContext)>,
    restart_at: Option<Duration>,
    polls: u32,
}

impl Application for Loader {
    crate::no_objects!();
    fn mailbox_request(&mut self, kind: u8, payload: &[u8], cx: &MailboxContext) -> MailboxReply {
        self.requests.push((kind, payload.to_vec(), *cx));
        if payload.first() == Some(&5) {
            MailboxReply::Silent
        } else {
            MailboxReply::Reply(payload.to_vec())
        }
    }
    fn poll(&mut self, now: Duration, _: AlState) -> AppRequest {
        self.polls += 1;
        match self.restart_at {
            Some(at) if now >= at => {
                self.restart_at = None;
                AppRequest::Restart {
                    offline: Duration::from_millis(50),
                }
            }
            _ => AppRequest::None,
        }
    }
}

#[test]
fn boot_uses_the_bootstrap_mailbox_and_offers_foe_only() {
    let config = EscConfig {
        mailbox_protocols: mailbox_protocols::COE | mailbox_protocols::FOE | mailbox_protocols::EOE,
        bootstrap_rx_mailbox: (0x1800, 256),
        bootstrap_tx_mailbox: (0x1A00, 256),
        ..EscConfig::default()
    };
    let mut sd = SubDevice::new(config, Loader::default());
    let mut now = Duration::ZERO;
    let mut run = |sd: &mut SubDevice<Loader>, d: Dg| {
        now += Duration::from_millis(1);
        parse_reply(&sd.process_frame(&build_frame(&[d]), now).expect("reply")).remove(0)
    };
    // The SII announces the bootstrap mailbox in words 0x14..0x17.
    let image = sd.sii_image();
    assert_eq!(&image[0x28..0x30], &[0x00, 0x18, 0, 1, 0x00, 0x1A, 0, 1]);
    // SM0/SM1 on the standard mailbox: BOOT refused with 0x0015.
    for d in standard_mailbox() {
        run(&mut sd, d);
    }
    run(&mut sd, dg(BWR, 0, reg::AL_CONTROL, &[0x03, 0]));
    assert_eq!(sd.al_state(), (AlState::Init, true, 0x0015));
    // Moved to the bootstrap mailbox (disable, configure, enable): BOOT.
    for (n, cfg) in [
        (0, [0x00, 0x18, 0, 1, 0x26, 0, 1, 0]),
        (1, [0x00, 0x1A, 0, 1, 0x22, 0, 1, 0]),
    ] {
        run(&mut sd, dg(BWR, 0, reg::sm(n, 6), &[0]));
        run(&mut sd, dg(BWR, 0, reg::sm(n, 0), &cfg));
    }
    run(&mut sd, dg(BWR, 0, reg::AL_CONTROL, &[0x13, 0]));
    assert_eq!(sd.al_state(), (AlState::Boot, false, 0));
    // An FoE request reaches the application with its context and is answered.
    let mut m = vec![3, 0, 0, 0, 0, 0x14, 3, 0, 1];
    m.resize(256, 0);
    assert_eq!(run(&mut sd, dg(BWR, 0, 0x1800, &m)).2, 1);
    let (_, reply, wkc) = run(&mut sd, dg(BRD, 0, 0x1A00, &[0; 256]));
    assert_eq!(wkc, 1);
    assert_eq!(&reply[..9], &[3, 0, 0, 0, 0, 0x14, 3, 0, 1]);
    let (kind, payload, cx) = sd.app().requests[0].clone();
    assert_eq!((kind, payload), (4, vec![3, 0, 1]));
    assert_eq!(cx.state, AlState::Boot);
    assert_eq!(cx.request_size, 256);
    assert_eq!(cx.reply_capacity, 250);
    assert_eq!(cx.now, Duration::from_millis(9));
    // An FoE ERR is not answered (the application stays silent).
    let mut m = vec![6, 0, 0, 0, 0, 0x24, 5, 0, 0, 0x80, 0, 0];
    m.resize(256, 0);
    run(&mut sd, dg(BWR, 0, 0x1800, &m));
    assert_eq!(run(&mut sd, dg(BRD, 0, 0x1A00, &[0; 256])).2, 0);
    // EoE is announced but not offered in BOOT: mailbox error "unsupported protocol".
    let mut m = vec![2, 0, 0, 0, 0, 0x32, 1, 2];
    m.resize(256, 0);
    run(&mut sd, dg(BWR, 0, 0x1800, &m));
    let (_, reply, _) = run(&mut sd, dg(BRD, 0, 0x1A00, &[0; 256]));
    assert_eq!(&reply[5..10], &[reply[5] & 0xF0, 0x01, 0x00, 0x02, 0x00]);
    assert_eq!(sd.app().requests.len(), 2);
    // Back to INIT, then PRE-OP needs the standard mailbox again.
    run(&mut sd, dg(BWR, 0, reg::AL_CONTROL, &[0x01, 0]));
    run(&mut sd, dg(BWR, 0, reg::AL_CONTROL, &[0x02, 0]));
    assert_eq!(sd.al_state(), (AlState::Init, true, 0x0016));
}

#[test]
fn a_restart_takes_the_device_off_the_bus_then_back_as_at_power_on() {
    let config = EscConfig {
        mailbox_protocols: mailbox_protocols::COE | mailbox_protocols::FOE,
        ..EscConfig::default()
    };
    let app = Loader {
        restart_at: Some(Duration::from_millis(100)),
        ..Loader::default()
    };
    let mut sd = SubDevice::new(config, app);
    let frame = |d: Dg| build_frame(&[d]);
    let at = |ms: u64| Duration::from_millis(ms);
    sd.process_frame(
        &frame(dg(APWR, 0, reg::STATION_ADDRESS, &[0x00, 0x10])),
        at(1),
    )
    .expect("reply");
    for (ms, d) in [2, 3].into_iter().zip(standard_mailbox()) {
        sd.process_frame(&frame(d), at(ms));
    }
    sd.process_frame(&frame(dg(BWR, 0, reg::AL_CONTROL, &[0x02, 0])), at(4));
    assert_eq!(sd.al_state(), (AlState::PreOp, false, 0));
    assert!(sd.app().polls >= 4, "polled on every frame");
    // The application asks for a restart at 100 ms: from then on, no answers for 50 ms.
    sd.tick(at(100));
    assert!(sd.restarting());
    assert_eq!(sd.al_state(), (AlState::Init, false, 0));
    let read = frame(dg(FPRD, 0x1000, reg::AL_STATUS, &[0, 0]));
    assert_eq!(sd.process_frame(&read, at(120)), None);
    assert_eq!(sd.process_frame(&read, at(149)), None);
    // Back: INIT, station address 0 (the FPRD misses), sync managers cleared.
    let reply = parse_reply(&sd.process_frame(&read, at(150)).expect("reply"));
    assert_eq!(reply[0].2, 0, "station address is gone");
    let reply = parse_reply(
        &sd.process_frame(&frame(dg(APRD, 0, reg::STATION_ADDRESS, &[0; 2])), at(151))
            .expect("reply"),
    );
    assert_eq!(reply[0].1, [0, 0]);
    let reply = parse_reply(
        &sd.process_frame(&frame(dg(APRD, 0, reg::sm(0, 0), &[0; 8])), at(152))
            .expect("reply"),
    );
    // Start, length, control, activate cleared; PDI control says "deactivated" (INIT).
    assert_eq!(reply[0].1, [0, 0, 0, 0, 0, 0, 0, 1]);
    assert!(!sd.restarting());
    let stats = sd.stats();
    assert_eq!((stats.restarts, stats.frames_while_restarting), (1, 2));
    // The SII survives (identity), the configuration area is loaded again.
    assert!(sii::checksum_ok(sd.sii_image()));
    // A caller-made power cycle with no offline time is immediate.
    sd.restart(at(200), Duration::ZERO);
    assert!(!sd.restarting());
    assert_eq!(sd.stats().restarts, 2);
}

#[test]
fn sm_watchdog_drops_to_safe_op() {
    let mut bus = Bus::new(App::new(4, 6));
    bus.enter_op();
    bus.now = Duration::from_millis(50);
    assert_eq!(bus.one(ldg(LRW, 0, &[0; 10])).1, 3);
    bus.now = Duration::from_millis(140);
    // 90 ms since the last outputs: still fine.
    assert_eq!(bus.reg16(reg::AL_STATUS), 0x08);
    bus.now = Duration::from_millis(151);
    // The next frame sees SAFE-OP + ERR 0x001B.
    assert_eq!(bus.reg16(reg::AL_STATUS), 0x14);
    assert_eq!(bus.reg16(reg::AL_STATUS_CODE), 0x001B);
    assert_eq!(bus.sd.app().lost, 1);
    assert_eq!(bus.fprd(reg::WATCHDOG_SM_COUNTER, 1).0, [1]);
    assert_eq!(bus.reg16(reg::WATCHDOG_SM_STATUS) & 1, 0);
    // Outputs are no longer passed to the application, inputs still flow.
    let received = bus.sd.app().received.len();
    assert_eq!(bus.one(ldg(LRW, 0, &[0; 10])).1, 3);
    assert_eq!(bus.sd.app().received.len(), received);
    // Acknowledge (stay in SAFE-OP), then OP again.
    assert_eq!(bus.request(0x14), (0x04, 0));
    assert_eq!(bus.request(0x08), (0x08, 0));
    assert_eq!(bus.sd.stats().watchdog_trips, 1);

    // The MainDevice may reprogram the watchdog: 0 disables it.
    bus.fpwr(reg::WATCHDOG_SM, &[0, 0]);
    bus.now += Duration::from_secs(10);
    assert_eq!(bus.reg16(reg::AL_STATUS), 0x08);
    // 10 ticks of 100 us = 1 ms.
    bus.fpwr(reg::WATCHDOG_SM, &[10, 0]);
    bus.one(ldg(LWR, 6, &[0; 4]));
    bus.sd.tick(bus.now + Duration::from_micros(900));
    assert_eq!(bus.sd.al_state().0, AlState::Op);
    bus.sd.tick(bus.now + Duration::from_micros(1100));
    assert_eq!(bus.sd.al_state(), (AlState::SafeOp, true, 0x001B));

    // Forced trip.
    assert_eq!(bus.request(0x14), (0x04, 0));
    assert_eq!(bus.request(0x08), (0x08, 0));
    bus.sd.trip_watchdog();
    assert_eq!(bus.sd.al_state(), (AlState::SafeOp, true, 0x001B));
    assert_eq!(bus.sd.app().lost, 3);
}

#[test]
fn faults_and_mac() {
    let mut bus = Bus::new(App::new(4, 6));
    let f = build_frame(&[dg(BRD, 0, reg::TYPE, &[0])]);
    let reply = bus.sd.process_frame(&f, Duration::ZERO).expect("reply");
    assert_eq!(&reply[6..12], &EscConfig::default().mac);
    assert_eq!(&reply[..6], &[0xFF; 6]);

    bus.sd.faults().link_down = true;
    assert_eq!(bus.sd.process_frame(&f, Duration::ZERO), None);
    bus.sd.faults().link_down = false;
    bus.sd.faults().drop_probability = 1.0;
    assert_eq!(bus.sd.process_frame(&f, Duration::ZERO), None);
    bus.sd.faults().drop_probability = 0.0;
    assert_eq!(bus.sd.stats().dropped_frames, 2);

    bus.enter_op();
    bus.sd.faults().wrong_wkc_probability = 1.0;
    assert_eq!(bus.one(ldg(LRW, 0, &[0; 10])).1, 2);
    assert_eq!(bus.one(ldg(LRW, 0x100, &[0; 4])).1, 1);
    // Register datagrams are not affected.
    assert_eq!(bus.fprd(reg::TYPE, 1).1, 1);
    bus.sd.faults().wrong_wkc_probability = 0.0;
    assert_eq!(bus.one(ldg(LRW, 0, &[0; 10])).1, 3);
    assert_eq!(bus.sd.stats().wrong_wkc, 2);

    // A MAC equal to the MainDevice's: the locally administered bit of the source is flipped.
    let config = EscConfig {
        mac: MASTER_MAC,
        ..EscConfig::default()
    };
    assert!(SubDevice::try_new(config.clone(), App::new(0, 0)).is_err());
    let mut sd = SubDevice::new(config, App::new(0, 0));
    let reply = sd.process_frame(&f, Duration::ZERO).expect("reply");
    assert_eq!(&reply[6..12], &[0x12, 0x10, 0x10, 0x10, 0x10, 0x10]);

    // process_frame_into: same reply, no allocation, short buffer refused.
    let mut sd = SubDevice::new(EscConfig::default(), App::new(0, 0));
    let mut out = [0u8; 64];
    let n = sd
        .process_frame_into(&f, &mut out, Duration::ZERO)
        .expect("reply");
    assert_eq!(n, f.len());
    assert_eq!(parse_reply(&out[..n])[0].2, 1);
    assert_eq!(
        sd.process_frame_into(&f, &mut out[..10], Duration::ZERO),
        None
    );
}

#[test]
fn config_validation() {
    let ok = EscConfig::default();
    assert_eq!(ok.validate((4, 6)), Ok(()));
    let overlap = EscConfig {
        inputs_address: 0x1102,
        ..EscConfig::default()
    };
    assert!(matches!(
        overlap.validate((4, 6)),
        Err(ConfigError::Overlap(..))
    ));
    let small = EscConfig {
        tx_mailbox: (0x1080, 8),
        ..EscConfig::default()
    };
    assert!(matches!(
        small.validate((0, 0)),
        Err(ConfigError::Area { .. })
    ));
    let multicast = EscConfig {
        mac: [0x01, 0, 0, 0, 0, 1],
        ..EscConfig::default()
    };
    assert!(matches!(
        multicast.validate((0, 0)),
        Err(ConfigError::Mac(_))
    ));
}

#[test]
fn malformed_and_foreign_frames() {
    let mut sd = SubDevice::new(EscConfig::default(), App::new(4, 6));
    // IPv4.
    let mut ip = build_frame(&[dg(BRD, 0, 0, &[0])]);
    ip[12] = 0x08;
    ip[13] = 0x00;
    assert_eq!(sd.process_frame(&ip, Duration::ZERO), None);
    // Truncated datagram: nothing executed, nothing returned.
    let mut f = build_frame(&[dg(APWR, 0, reg::STATION_ADDRESS, &[0x34, 0x12])]);
    f.truncate(f.len() - 1);
    assert_eq!(sd.process_frame(&f, Duration::ZERO), None);
    let stats = sd.stats();
    assert_eq!((stats.not_ethercat, stats.malformed), (1, 1));
    assert_eq!(&sd.memory()[0x10..0x12], &[0, 0]);
}

fn arbitrary_ethercat() -> impl Strategy<Value = Vec<u8>> {
    (
        proptest::collection::vec(
            (
                0u8..16,
                any::<u32>(),
                proptest::collection::vec(any::<u8>(), 0..64),
            ),
            1..6,
        ),
        proptest::collection::vec(any::<u8>(), 0..8),
    )
        .prop_map(|(dgs, tail)| {
            let dgs: Vec<Dg> = dgs
                .into_iter()
                .map(|(cmd, address, data)| Dg { cmd, address, data })
                .collect();
            let mut f = build_frame(&dgs);
            f.extend_from_slice(&tail);
            f
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..256)) {
        let mut sd = SubDevice::new(EscConfig::default(), App::new(4, 6));
        let reply = sd.process_frame(&bytes, Duration::ZERO);
        if bytes.len() < 14 || bytes[12..14] != [0x88, 0xA4] {
            prop_assert!(reply.is_none());
        }
        if let Some(reply) = reply {
            prop_assert_eq!(reply.len(), bytes.len());
        }
    }

    #[test]
    fn arbitrary_datagrams_never_panic(
        frames in proptest::collection::vec(arbitrary_ethercat(), 1..8),
        op in any::<bool>(),
    ) {
        let mut bus = Bus::new(App::new(4, 6));
        if op {
            bus.enter_op();
        }
        for (i, f) in frames.iter().enumerate() {
            let reply = bus.sd.process_frame(f, Duration::from_millis(i as u64));
            let reply = reply.expect("well-formed frames are answered");
            prop_assert_eq!(reply.len(), f.len());
            prop_assert_eq!(&reply[12..16], &f[12..16]);
        }
    }
}

#[test]
fn a_firmware_loop_reads_al_control_once_per_loop() {
    let ms = |tenths: u64| Duration::from_micros(tenths * 100);
    for firmware_loop in [Duration::from_millis(1), Duration::ZERO] {
        let config = EscConfig {
            firmware_loop,
            ..EscConfig::default()
        };
        let mut bus = Bus::with_config(config, App::new(4, 6));
        bus.mailboxes();
        let looped = !firmware_loop.is_zero();
        // An invalid request: seen at the next loop.
        bus.now = ms(1);
        bus.fpwr(reg::AL_CONTROL, &[0x08, 0]);
        let status = (bus.reg16(reg::AL_STATUS), bus.reg16(reg::AL_STATUS_CODE));
        assert_eq!(status, if looped { (0x01, 0) } else { (0x11, 0x0011) });
        bus.now = ms(11);
        assert_eq!(bus.reg16(reg::AL_STATUS), 0x11, "{firmware_loop:?}");
        // Acknowledge and PRE-OP request back to back, within one loop: the firmware sees
        // only the request, and the error stays.
        bus.now = ms(12);
        bus.fpwr(reg::AL_CONTROL, &[0x11, 0]);
        bus.now = ms(13);
        bus.fpwr(reg::AL_CONTROL, &[0x02, 0]);
        bus.now = ms(21);
        let status = (bus.reg16(reg::AL_STATUS), bus.reg16(reg::AL_STATUS_CODE));
        assert_eq!(
            status,
            if looped { (0x11, 0x0011) } else { (0x02, 0) },
            "{firmware_loop:?}"
        );
        if !looped {
            continue;
        }
        // Acknowledge, wait for the error flag to clear, then request: taken.
        bus.fpwr(reg::AL_CONTROL, &[0x11, 0]);
        bus.now = ms(31);
        assert_eq!(bus.reg16(reg::AL_STATUS), 0x01);
        bus.fpwr(reg::AL_CONTROL, &[0x02, 0]);
        bus.now = ms(41);
        assert_eq!(bus.reg16(reg::AL_STATUS), 0x02);
        assert_eq!(bus.sd.al_state(), (AlState::PreOp, false, 0));
    }
}

/// The Shadow palm's layout (docs/devices/shadow.md): command and bridge command written by the
/// MainDevice, status and bridge status read, all one-buffer.
fn palm_sms() -> Vec<SmSetting> {
    vec![
        SmSetting {
            start: 0x1000,
            len: 58,
            control: 0x26,
        },
        SmSetting {
            start: 0x103A,
            len: 12,
            control: 0x26,
        },
        SmSetting {
            start: 0x1046,
            len: 220,
            control: 0x02,
        },
        SmSetting {
            start: 0x1122,
            len: 12,
            control: 0x02,
        },
    ]
}

#[test]
fn programmed_sync_managers_are_one_buffer_process_data() {
    let config = EscConfig {
        sync_managers: SyncManagers::Programmed(palm_sms()),
        ..EscConfig::default()
    };
    let mut bus = Bus::with_config(config, App::new(0, 0));
    // The SII announces no mailbox and no sync managers.
    let image = bus.sd.sii_image().to_vec();
    assert!(image[0x14 * 2..0x1D * 2].iter().all(|b| *b == 0));
    let mut word = sii::FIRST_CATEGORY;
    let mut kinds = Vec::new();
    loop {
        let kind = u16::from_le_bytes([image[word * 2], image[word * 2 + 1]]);
        if kind == sii::CAT_END {
            break;
        }
        kinds.push(kind);
        word += 2 + usize::from(u16::from_le_bytes([
            image[word * 2 + 2],
            image[word * 2 + 3],
        ]));
    }
    assert_eq!(kinds, [sii::CAT_STRINGS, sii::CAT_GENERAL]);
    // PRE-OP needs no mailbox; SAFE-OP needs every SM as the firmware expects it.
    assert_eq!(bus.request(0x02), (0x02, 0));
    assert_eq!(bus.request(0x04), (0x12, 0x0017));
    let sms = palm_sms();
    for (n, sm) in sms.iter().enumerate() {
        let len = if n == 2 { sm.len - 1 } else { sm.len };
        bus.sm(n, sm.start, len, sm.control, true);
    }
    assert_eq!(bus.request(0x14), (0x12, 0x0017), "SM2 one byte short");
    bus.sm(2, 0x1046, 220, 0x02, true);
    bus.fmmu(0, 0x0001_0000, 70, 0x1000, 2);
    bus.fmmu(1, 0x0001_0046, 232, 0x1046, 1);
    assert_eq!(bus.request(0x14), (0x04, 0));
    assert_eq!(bus.request(0x08), (0x08, 0));
    assert_eq!(bus.request(0x03), (0x18, 0x0011), "no BOOT from OP");
    assert_eq!(bus.request(0x18), (0x08, 0));

    let lrw = |bus: &mut Bus, first: u8| {
        let mut data = vec![0u8; 302];
        for (i, b) in data[..58].iter_mut().enumerate() {
            *b = first.wrapping_add(i as u8);
        }
        let (data, wkc) = bus.one(ldg(LRW, 0x0001_0000, &data));
        (data[70..128].to_vec(), wkc)
    };
    // The command is written (+2); the status was never filled: not read, data untouched.
    let (status, wkc) = lrw(&mut bus, 1);
    assert_eq!((wkc, status), (2, vec![0; 58]));
    // The firmware has not taken the command yet: the next one is refused, nothing to read.
    assert_eq!(lrw(&mut bus, 100).1, 0);
    // The firmware takes it and answers; the next command goes in, the answer comes out.
    bus.now += Duration::from_millis(1);
    bus.sd.tick(bus.now);
    assert_eq!(bus.sd.app().taken.len(), 1);
    let (status, wkc) = lrw(&mut bus, 7);
    assert_eq!(wkc, 3);
    assert_eq!(status[..3], [1, 2, 3], "the first command, echoed");
    // Read once: the status is empty again until the firmware refills it.
    assert_eq!(lrw(&mut bus, 9).1, 0);
    bus.now += Duration::from_millis(1);
    bus.sd.tick(bus.now);
    let (status, wkc) = lrw(&mut bus, 11);
    assert_eq!((wkc, status[0]), (3, 7));
    // A firmware writing twice before the MainDevice read is refused the second time.
    bus.now += Duration::from_millis(1);
    bus.sd.tick(bus.now);
    assert_eq!(bus.sd.app().echo_refused, 0);
    assert_eq!(bus.fprd(0x1046, 1).1, 1, "the status is there");
    bus.fpwr(0x1000, &[0; 58]);
    bus.now += Duration::from_millis(1);
    bus.sd.tick(bus.now);
    assert_eq!(bus.sd.app().echo_refused, 1);
}

#[test]
fn programmed_sync_managers_are_validated() {
    let mut sms = palm_sms();
    sms[1].start = 0x1030;
    let overlap = EscConfig {
        sync_managers: SyncManagers::Programmed(sms),
        ..EscConfig::default()
    };
    assert_eq!(
        overlap.validate((0, 0)),
        Err(ConfigError::Overlap("SM0", "SM1"))
    );
    let mut five = palm_sms();
    five.push(five[0]);
    let five = EscConfig {
        sync_managers: SyncManagers::Programmed(five),
        ..EscConfig::default()
    };
    assert_eq!(
        five.validate((0, 0)),
        Err(ConfigError::TooManySyncManagers(5))
    );
}
