//! The Revo2 firmware upgrade over FoE (document section 6), as `teleop revo2 flash` runs it:
//!
//! 1. [`Firmware::load`]: the file is checked before anything goes to the device: its name
//!    (section 6.1, case-sensitive, for the board asked for), its 16-byte header (magic number
//!    of that board, reserved bytes zero, version equal to the name's) and an image after it;
//! 2. the bus is scanned (PRE-OP) and the SII read: FoE must be announced, and the bootstrap
//!    mailbox (words 0x14..0x17) is where the sync managers go for BOOT;
//! 3. [`write_upgrade_settings`]: the upgrade type (0x8000:15) and the authentication code
//!    (0x8000:16, 8 bytes: a normal SDO download, which ethercrab cannot send) in PRE-OP;
//! 4. [`enter_boot`]: INIT, SM0/SM1 moved to the bootstrap mailbox, BOOT (AL control 0x0003);
//! 5. the FoE write of the whole file (header included: the device checks it) through
//!    `teleop-foe` on the bootstrap mailbox; the device answers BUSY while it erases and writes;
//! 6. [`wait_for_restart`]: the device restarts by itself with the new firmware (it leaves the
//!    bus for a while and comes back in INIT);
//! 7. the bus is scanned again and the version read back from 0x8000:11 (control board) or
//!    0x8000:13 (wrist board).
//!
//! A failed transfer sends the device back to INIT ([`leave_boot`]), so that the next bus scan
//! finds it as before.

use std::path::Path;
use std::time::{Duration, Instant};

use ethercrab::{AlStatusCode, Command, MainDevice};
use futures_lite::future::block_on;
use teleop_foe::Client;
pub use teleop_foe::{ClientConfig, FoeError, Progress, Summary};
use teleop_revo2_protocol::{
    check_file_name, obj, Board, FirmwareError, FirmwareHeader, Version, FOE_AUTH_CODE,
    FOE_FILE_TYPE, HEADER_LEN,
};

use crate::bus;
use crate::mailbox::{sdo_download, EcatMailbox, MailboxArea};

/// AL states as AL control / status encode them.
const INIT: u8 = 0x01;
const BOOT: u8 = 0x03;
/// AL control: acknowledge the error indication.
const AL_ACKNOWLEDGE: u16 = 0x10;
/// AL status: error indication.
const AL_ERROR: u16 = 0x10;
/// Registers.
const AL_CONTROL: u16 = 0x0120;
const AL_STATUS: u16 = 0x0130;
const AL_STATUS_CODE: u16 = 0x0134;
const SM0: u16 = 0x0800;
/// SM control bytes of mailboxes: SM0 written by the MainDevice, SM1 read (with interrupts).
const SM_MAILBOX_WRITE: u8 = 0x26;
const SM_MAILBOX_READ: u8 = 0x22;
/// SII words: bootstrap mailbox (receive offset, size, send offset, size), mailbox protocols.
const SII_BOOTSTRAP: u16 = 0x14;
const SII_PROTOCOLS: u16 = 0x1C;
const FOE_PROTOCOL: u16 = 0x08;

/// A firmware file that passed every check that can be made without the device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Firmware {
    name: String,
    bytes: Vec<u8>,
    header: FirmwareHeader,
}

impl Firmware {
    /// Reads and checks the file at `path` for `board`. The FoE file name is the path's last
    /// component.
    pub fn load(path: &Path, board: Board) -> Result<Self, FlashError> {
        let shown = path.display().to_string();
        let name =
            path.file_name()
                .and_then(|n| n.to_str())
                .ok_or_else(|| FlashError::Invalid {
                    file: shown.clone(),
                    reason: "the file name is not valid UTF-8".into(),
                })?;
        let bytes = std::fs::read(path).map_err(|e| FlashError::Read {
            file: shown,
            message: e.to_string(),
        })?;
        Self::new(name, bytes, board)
    }

    /// Checks `bytes` as the file `name` for `board` (see the module documentation).
    pub fn new(name: &str, bytes: Vec<u8>, board: Board) -> Result<Self, FlashError> {
        let invalid = |reason: String| FlashError::Invalid {
            file: name.to_owned(),
            reason,
        };
        let name_version = check_file_name(name, board).map_err(|e| invalid(e.to_string()))?;
        let header = match FirmwareHeader::parse(&bytes) {
            Ok(h) => h,
            Err(FirmwareError::TooShort { got }) => {
                return Err(invalid(format!(
                    "the file has {got} bytes, fewer than the {HEADER_LEN}-byte firmware header: truncated"
                )))
            }
            Err(FirmwareError::UnknownMagic(m)) => {
                return Err(invalid(format!(
                    "the header's magic number {:?} is not a Revo2 firmware's ({} for the wrist board, {} for the control board)",
                    String::from_utf8_lossy(&m),
                    String::from_utf8_lossy(Board::Wrist.magic()),
                    String::from_utf8_lossy(Board::Control.magic()),
                )))
            }
            Err(e) => return Err(invalid(format!("bad firmware header: {e}"))),
        };
        if header.board != board {
            return Err(invalid(format!(
                "the header's magic number {} is the {}'s, not the {}'s ({})",
                String::from_utf8_lossy(header.board.magic()),
                header.board,
                board,
                String::from_utf8_lossy(board.magic())
            )));
        }
        if header.version != name_version {
            return Err(invalid(format!(
                "the file name says version {}, the header {}",
                version_text(name_version),
                version_text(header.version)
            )));
        }
        if bytes.len() == HEADER_LEN {
            return Err(invalid(
                "the file holds the 16-byte header and no firmware image: truncated".into(),
            ));
        }
        Ok(Self {
            name: name.to_owned(),
            bytes,
            header,
        })
    }

    /// The FoE file name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The whole file, header included.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The board.
    pub fn board(&self) -> Board {
        self.header.board
    }

    /// The version in the header.
    pub fn version(&self) -> Version {
        self.header.version
    }
}

/// A version as the device shows it: "major.minor.patch".
pub fn version_text((major, minor, patch): Version) -> String {
    format!("{major}.{minor}.{patch}")
}

/// The configuration sub-index of 0x8000 that shows `board`'s firmware version.
pub fn version_sub(board: Board) -> u8 {
    match board {
        Board::Control => 0x11,
        Board::Wrist => 0x13,
    }
}

/// Timeouts and overrides of a flash.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FlashOptions {
    /// The authentication code to write to 0x8000:16 instead of the document's code for the
    /// board (for devices whose code differs).
    pub auth_code: Option<String>,
    /// The FoE client's timeouts and repeats.
    pub foe: ClientConfig,
    /// Longest wait for a requested AL state.
    pub state_timeout: Duration,
    /// Longest wait for the device to restart and come back after the transfer.
    pub restart_timeout: Duration,
    /// Longest wait for the answer to an SDO download.
    pub sdo_timeout: Duration,
}

impl Default for FlashOptions {
    fn default() -> Self {
        Self {
            auth_code: None,
            foe: ClientConfig::default(),
            state_timeout: Duration::from_secs(3),
            restart_timeout: Duration::from_secs(20),
            sdo_timeout: Duration::from_secs(1),
        }
    }
}

/// What a flash is doing, for display.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FlashEvent {
    /// A step begins.
    Step(String),
    /// Transfer progress.
    Transfer(Progress),
}

/// How a flash went.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FlashReport {
    /// The board written.
    pub board: Board,
    /// Its version before.
    pub before: String,
    /// Its version after the restart (equal to the file's).
    pub after: String,
    /// The FoE transfer.
    pub transfer: Summary,
    /// From the end of the transfer until the device was back.
    pub restart: Duration,
}

/// Why a flash failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FlashError {
    /// The file could not be read.
    #[error("{file}: {message}")]
    Read {
        /// The path.
        file: String,
        /// The error.
        message: String,
    },
    /// The file is refused (nothing was sent to the device).
    #[error("{file}: {reason} (refused before contacting the device)")]
    Invalid {
        /// The file.
        file: String,
        /// Why.
        reason: String,
    },
    /// The bus or the device could not be reached or read.
    #[error("{0}")]
    Bus(String),
    /// The SII does not announce FoE.
    #[error("the device does not support FoE (SII mailbox protocols {0:#06x})")]
    NoFoe(u16),
    /// The SII has no bootstrap mailbox.
    #[error("the device has no bootstrap mailbox (SII words 0x14..0x17 are empty): it cannot go to BOOT")]
    NoBootstrap,
    /// Writing the upgrade type or the authentication code failed.
    #[error("writing the {what} ({index:#06x}:{sub:02x}) failed: {message}")]
    Settings {
        /// What was written.
        what: &'static str,
        /// Object index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The error.
        message: String,
    },
    /// The device refused an AL state.
    #[error("the device refused {state}: AL status code {code}")]
    StateRefused {
        /// The state asked for.
        state: &'static str,
        /// The AL status code.
        code: String,
    },
    /// The device did not reach an AL state in time.
    #[error("the device did not reach {state} within {timeout:?} (AL status {status:#06x})")]
    StateTimeout {
        /// The state asked for.
        state: &'static str,
        /// The wait.
        timeout: Duration,
        /// The last AL status.
        status: u16,
    },
    /// The FoE transfer failed; the device was sent back to INIT (when it still answered).
    #[error("firmware transfer failed: {0}")]
    Transfer(FoeError),
    /// The device did not restart and come back.
    #[error("the device did not come back within {0:?} after the firmware was written: power-cycle it, then check its version with `teleop revo2 info`")]
    NoRestart(Duration),
    /// The device came back with another version than the file's.
    #[error(
        "the device restarted but reports version {found:?} for the {board}, expected {expected}"
    )]
    VersionMismatch {
        /// The board.
        board: Board,
        /// The file's version.
        expected: String,
        /// What the device reports.
        found: String,
    },
}

fn bus_error(context: &str) -> impl Fn(ethercrab::error::Error) -> FlashError + '_ {
    move |e| FlashError::Bus(format!("{context}: {e}"))
}

fn fprd_u16(md: &MainDevice<'_>, address: u16, register: u16) -> Result<u16, FlashError> {
    block_on(Command::fprd(address, register).receive::<u16>(md))
        .map_err(bus_error("reading a register"))
}

fn fpwr(md: &MainDevice<'_>, address: u16, register: u16, data: &[u8]) -> Result<(), FlashError> {
    block_on(Command::fpwr(address, register).send_receive_slice(md, data))
        .map(|_| ())
        .map_err(bus_error("writing a register"))
}

/// Requests AL state `state` (with the error acknowledge) and waits for it.
fn request_state(
    md: &MainDevice<'_>,
    address: u16,
    state: u8,
    name: &'static str,
    timeout: Duration,
) -> Result<(), FlashError> {
    fpwr(
        md,
        address,
        AL_CONTROL,
        &(u16::from(state) | AL_ACKNOWLEDGE).to_le_bytes(),
    )?;
    let start = Instant::now();
    loop {
        let status = fprd_u16(md, address, AL_STATUS)?;
        if status & AL_ERROR != 0 {
            let code = block_on(Command::fprd(address, AL_STATUS_CODE).receive::<AlStatusCode>(md))
                .map(|c| c.to_string())
                .unwrap_or_else(|e| format!("unreadable ({e})"));
            return Err(FlashError::StateRefused { state: name, code });
        }
        if status & 0x0F == u16::from(state) {
            return Ok(());
        }
        if start.elapsed() > timeout {
            return Err(FlashError::StateTimeout {
                state: name,
                timeout,
                status,
            });
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// What the SII and the ESC say about a SubDevice's mailboxes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mailboxes {
    /// Configured station address.
    pub address: u16,
    /// SM0 and SM1 as configured now (the standard mailbox in PRE-OP).
    pub standard: (MailboxArea, MailboxArea),
    /// The bootstrap mailbox from the SII (receive, send).
    pub bootstrap: (MailboxArea, MailboxArea),
}

/// Reads the mailbox layout of the first SubDevice of `group` (in PRE-OP): the SII must
/// announce FoE and a bootstrap mailbox.
pub fn mailboxes(
    md: &MainDevice<'static>,
    group: &bus::PreOpGroup,
) -> Result<Mailboxes, FlashError> {
    let sd = group.subdevice(md, 0).map_err(bus_error("no SubDevice"))?;
    let address = sd.configured_address();
    let mut words = [0u8; 2];
    block_on(sd.eeprom_read_raw(md, SII_PROTOCOLS, &mut words))
        .map_err(bus_error("reading the SII"))?;
    let protocols = u16::from_le_bytes(words);
    if protocols & FOE_PROTOCOL == 0 {
        return Err(FlashError::NoFoe(protocols));
    }
    let mut boot = [0u8; 8];
    block_on(sd.eeprom_read_raw(md, SII_BOOTSTRAP, &mut boot))
        .map_err(bus_error("reading the SII"))?;
    let word = |i: usize| u16::from_le_bytes([boot[2 * i], boot[2 * i + 1]]);
    let bootstrap = (
        MailboxArea {
            start: word(0),
            len: word(1),
        },
        MailboxArea {
            start: word(2),
            len: word(3),
        },
    );
    if bootstrap.0.len == 0 || bootstrap.1.len == 0 {
        return Err(FlashError::NoBootstrap);
    }
    let sms = block_on(Command::fprd(address, SM0).receive::<[u8; 16]>(md))
        .map_err(bus_error("reading the sync managers"))?;
    let area = |o: usize| MailboxArea {
        start: u16::from_le_bytes([sms[o], sms[o + 1]]),
        len: u16::from_le_bytes([sms[o + 2], sms[o + 3]]),
    };
    Ok(Mailboxes {
        address,
        standard: (area(0), area(8)),
        bootstrap,
    })
}

/// Writes the upgrade type (0x8000:15) and the authentication code (0x8000:16) for `board`,
/// in PRE-OP, through the standard mailbox (section 6.2 step 1).
pub fn write_upgrade_settings(
    md: &MainDevice<'static>,
    mailboxes: &Mailboxes,
    board: Board,
    auth_code: &str,
    timeout: Duration,
) -> Result<(), FlashError> {
    let (rx, tx) = mailboxes.standard;
    let mut port = EcatMailbox::new(md, mailboxes.address, rx, tx);
    for (what, (index, sub), value) in [
        ("upgrade type", FOE_FILE_TYPE, vec![board.foe_file_type()]),
        (
            "authentication code",
            FOE_AUTH_CODE,
            auth_code.as_bytes().to_vec(),
        ),
    ] {
        sdo_download(&mut port, index, sub, &value, timeout).map_err(|e| FlashError::Settings {
            what,
            index,
            sub,
            message: e.to_string(),
        })?;
    }
    Ok(())
}

/// INIT, then SM0/SM1 on the bootstrap mailbox, then BOOT.
pub fn enter_boot(
    md: &MainDevice<'static>,
    mailboxes: &Mailboxes,
    timeout: Duration,
) -> Result<(), FlashError> {
    let address = mailboxes.address;
    request_state(md, address, INIT, "INIT", timeout)?;
    let (rx, tx) = mailboxes.bootstrap;
    for (n, area, control) in [(0u16, rx, SM_MAILBOX_WRITE), (1, tx, SM_MAILBOX_READ)] {
        let sm = SM0 + 8 * n;
        // Start, length and control can only be written while the SM is disabled.
        fpwr(md, address, sm + 6, &[0])?;
        let [s0, s1] = area.start.to_le_bytes();
        let [l0, l1] = area.len.to_le_bytes();
        fpwr(md, address, sm, &[s0, s1, l0, l1, control, 0, 1, 0])?;
    }
    request_state(md, address, BOOT, "BOOT", timeout)
}

/// Sends the device back to INIT (best effort: a device that stopped answering cannot be).
pub fn leave_boot(md: &MainDevice<'static>, address: u16, timeout: Duration) {
    if let Err(e) = request_state(md, address, INIT, "INIT", timeout) {
        tracing::warn!("could not send the device back to INIT: {e}");
    }
}

/// Waits until the device has restarted: it shows INIT again (typically after a time off the
/// bus, which also clears its station address, so the AL status is read by broadcast).
pub fn wait_for_restart(
    md: &MainDevice<'static>,
    timeout: Duration,
) -> Result<Duration, FlashError> {
    let start = Instant::now();
    let mut away = false;
    loop {
        match block_on(Command::brd(AL_STATUS).receive::<u16>(md)) {
            Ok(status) if status & 0x0F == u16::from(INIT) => {
                tracing::debug!(away, "device back in INIT after {:?}", start.elapsed());
                return Ok(start.elapsed());
            }
            Ok(_) => {}
            Err(_) => {
                if !away {
                    tracing::debug!("device off the bus: restarting");
                }
                away = true;
            }
        }
        if start.elapsed() > timeout {
            return Err(FlashError::NoRestart(timeout));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Reads the firmware version of `board` (0x8000:11 or 0x8000:13) in PRE-OP.
pub fn read_version(
    md: &MainDevice<'static>,
    group: &bus::PreOpGroup,
    board: Board,
) -> Result<String, FlashError> {
    block_on(bus::read_string(md, group, obj::CONFIG, version_sub(board)))
        .map_err(|e| FlashError::Bus(format!("{e:#}")))
}

/// Writes `firmware` to the Revo2 on the bus and reads the new version back (the whole of
/// section 6.2; see the module documentation). The Revo2 node must not be running.
pub fn flash(
    md: &MainDevice<'static>,
    firmware: &Firmware,
    options: &FlashOptions,
    events: &mut dyn FnMut(&FlashEvent),
) -> Result<FlashReport, FlashError> {
    let board = firmware.board();
    let step = |events: &mut dyn FnMut(&FlashEvent), text: String| {
        tracing::debug!("{text}");
        events(&FlashEvent::Step(text));
    };
    step(events, "scanning the bus".into());
    let group = block_on(bus::discover(md)).map_err(|e| FlashError::Bus(format!("{e:#}")))?;
    let layout = mailboxes(md, &group)?;
    let before = read_version(md, &group, board)?;
    step(
        events,
        format!(
            "{board} firmware {before}; writing the upgrade type (0x8000:15) and authentication code (0x8000:16)"
        ),
    );
    let auth = options
        .auth_code
        .clone()
        .unwrap_or_else(|| board.auth_code().to_owned());
    write_upgrade_settings(md, &layout, board, &auth, options.sdo_timeout)?;
    step(
        events,
        format!(
            "requesting BOOT (bootstrap mailbox {:#06x}+{} / {:#06x}+{})",
            layout.bootstrap.0.start,
            layout.bootstrap.0.len,
            layout.bootstrap.1.start,
            layout.bootstrap.1.len
        ),
    );
    drop(group);
    if let Err(e) = enter_boot(md, &layout, options.state_timeout) {
        leave_boot(md, layout.address, options.state_timeout);
        return Err(e);
    }
    step(
        events,
        format!(
            "sending {} ({} bytes, version {}) over FoE",
            firmware.name(),
            firmware.bytes().len(),
            version_text(firmware.version())
        ),
    );
    let (rx, tx) = layout.bootstrap;
    let port = EcatMailbox::new(md, layout.address, rx, tx);
    let mut client = Client::new(port, options.foe.clone());
    let transfer = client.write(firmware.name(), firmware.bytes(), &mut |p| {
        events(&FlashEvent::Transfer(p.clone()))
    });
    let transfer = match transfer {
        Ok(summary) => summary,
        Err(e) => {
            leave_boot(md, layout.address, options.state_timeout);
            return Err(FlashError::Transfer(e));
        }
    };
    step(
        events,
        "firmware written; waiting for the device to restart".into(),
    );
    let restart = wait_for_restart(md, options.restart_timeout)?;
    step(events, "scanning the bus again".into());
    let group = block_on(bus::discover(md)).map_err(|e| FlashError::Bus(format!("{e:#}")))?;
    let after = read_version(md, &group, board)?;
    let expected = version_text(firmware.version());
    if after != expected {
        return Err(FlashError::VersionMismatch {
            board,
            expected,
            found: after,
        });
    }
    Ok(FlashReport {
        board,
        before,
        after,
        transfer,
        restart,
    })
}
