//! An emulated EtherCAT SubDevice (slave) that a real MainDevice (ethercrab, SOEM, ...) can bring
//! to OP.
//!
//! # What this crate owns
//!
//! Generic EtherCAT SubDevice emulation, frame in, frame out:
//!
//! - the **ESC** (EtherCAT SubDevice Controller): datagram execution for every command
//!   (APRD/APWR/APRW, FPRD/FPWR/FPRW, BRD/BWR/BRW, LRD/LWR/LRW, ARMW/FRMW), auto-increment and
//!   configured-address handling, working counters that only count accessible memory, the
//!   register file ([`registers`]), 3 FMMUs and 4 SyncManagers with mailbox and buffered
//!   semantics;
//! - the **SII EEPROM** ([`sii`]): identity, mailbox layout, Strings/General/FMMU/SyncManager
//!   categories, CRC, and the 0x0500 EEPROM interface with 4- or 8-byte reads;
//! - the **AL state machine** (INIT, PRE-OP, BOOT, SAFE-OP, OP) with real AL status codes, the
//!   error flag and its acknowledge; BOOT on the bootstrap mailbox (SII words 0x14..0x17: SM0/SM1
//!   must be moved there before INIT -> BOOT) with FoE only;
//! - **restarts** requested by the application ([`AppRequest::Restart`], e.g. after a firmware
//!   update) or by the caller ([`SubDevice::restart`]): offline for a while, then as at power-on;
//! - the **mailbox** (SM0/SM1 handshake, counters, repeat, mailbox error replies) and **CoE SDO**
//!   (expedited, normal and segmented upload and download, abort codes);
//! - **process data** through the configured FMMUs, only exchanged in SAFE-OP (inputs) and OP
//!   (inputs and outputs), and the **SM watchdog** (OP -> SAFE-OP + ERR, AL status code 0x001B);
//! - **fault injection** ([`Faults`]) and counters ([`Stats`]);
//! - devices whose SII announces **no mailbox and no sync managers** ([`SyncManagers::Programmed`],
//!   as the Shadow palm): the MainDevice programs the sync managers the firmware expects, and the
//!   firmware reads and writes their one-buffer process data through [`Pdi`].
//!
//! The device behind the ESC (its object dictionary, its PDO mapping, its reaction to outputs) is
//! an [`Application`] written by the user of this crate.
//!
//! # What it must not depend on
//!
//! No device specifics (the BrainCo Revo2 hand lives in its own crate as an [`Application`]), no
//! IPC (no iceoryx2), no I/O (the caller moves the frames: in-process, veth, raw socket;
//! `teleop-ecat-link` only for its `Responder` trait, which a [`SubDevice`] implements), and no
//! EtherCAT MainDevice: ethercrab is only a dev-dependency, for the tests. The emulator must stay
//! independent of the master so that a master bug is not hidden by a matching simulator bug.
//!
//! # What it does not implement (yet)
//!
//! Distributed clocks (the DC registers 0x0900.. are absent: reads leave the datagram untouched
//! and do not count in the working counter, exactly like an ESC without DC), FoE/EoE/SoE/AoE
//! (mailbox types other than CoE are handed to [`Application::mailbox_request`], which answers
//! with a mailbox error by default; in BOOT only FoE reaches it, on the bootstrap mailbox, so a
//! firmware update is the application's), SDO Information, CoE complete access (aborted with 0x0601_0000),
//! CoE emergencies (never sent), bit-granular FMMU mappings (FMMUs map whole bytes), explicit
//! device identification (AL control bit 5), EEPROM emulation by the PDI, ESC write protection,
//! and ports 2 and 3 (port 0 has the link; port 1 is closed unless
//! [`EscConfig::port1_linked`] says a SubDevice follows).
//!
//! # Known MainDevice limits this emulator exposes
//!
//! ethercrab 0.7.1 cannot read SDO values that need a segmented upload (longer than the reply
//! mailbox minus 16 bytes, i.e. 112 bytes with the default 128-byte mailbox): it rejects the
//! standard upload segment response. Values up to that size (normal upload) are fine. Its
//! `sdo_write` only sends expedited downloads (at most 4 bytes); this SubDevice also accepts
//! normal and segmented downloads (SOEM sends them).
//!
//! # Example
//!
//! ```
//! use teleop_ecat_sim::{AlState, Application, EscConfig, SdoAbort, SubDevice};
//! use core::time::Duration;
//!
//! struct Nothing;
//! impl Application for Nothing {
//!     fn sdo_read(&mut self, _: u16, _: u8) -> Result<Vec<u8>, SdoAbort> {
//!         Err(SdoAbort::OBJECT_DOES_NOT_EXIST)
//!     }
//!     fn sdo_write(&mut self, _: u16, _: u8, _: &[u8], _: AlState) -> Result<(), SdoAbort> {
//!         Err(SdoAbort::OBJECT_DOES_NOT_EXIST)
//!     }
//!     fn process_image_sizes(&self) -> Result<(usize, usize), u16> {
//!         Ok((0, 0))
//!     }
//!     fn write_outputs(&mut self, _: &[u8], _: Duration) {}
//!     fn read_inputs(&mut self, _: &mut [u8], _: Duration) {}
//! }
//!
//! let mut sd = SubDevice::new(EscConfig::default(), Nothing);
//! // A BRD of register 0x0000 (ESC type), as a MainDevice sends it to count SubDevices.
//! let mut frame = vec![0xff; 6];
//! frame.extend_from_slice(&[0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x88, 0xa4]);
//! frame.extend_from_slice(&[13, 0x10]); // EtherCAT header: 13 bytes of datagrams, type 1
//! frame.extend_from_slice(&[0x07, 0x00, 0, 0, 0x00, 0x00, 1, 0, 0, 0, 0x00, 0, 0]);
//! let reply = sd.process_frame(&frame, Duration::ZERO).expect("an EtherCAT frame");
//! assert_eq!(u16::from_le_bytes([reply[27], reply[28]]), 1); // working counter
//! assert_eq!(sd.al_state(), (AlState::Init, false, 0));
//! ```

mod al;
mod coe;
mod esc;
mod fault;
mod frame;
mod mailbox;
pub mod registers;
pub mod sii;

use core::time::Duration;

pub use esc::SubDevice;
pub use fault::{Faults, Stats};
pub use frame::ETHERCAT_ETHERTYPE;
pub use mailbox::mailbox_error;

/// AL (application layer) states, with their AL control / AL status register encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum AlState {
    /// INIT: no mailbox, no process data.
    Init = 1,
    /// PRE-OPERATIONAL: mailbox communication.
    PreOp = 2,
    /// BOOTSTRAP: firmware update over the bootstrap mailbox (FoE only).
    Boot = 3,
    /// SAFE-OPERATIONAL: mailbox, inputs; outputs are ignored.
    SafeOp = 4,
    /// OPERATIONAL: mailbox, inputs and outputs.
    Op = 8,
}

impl AlState {
    /// Decodes the state bits (0..=3) of AL control / AL status; `None` for an unknown state.
    pub fn from_bits(bits: u8) -> Option<Self> {
        match bits & 0x0f {
            1 => Some(Self::Init),
            2 => Some(Self::PreOp),
            3 => Some(Self::Boot),
            4 => Some(Self::SafeOp),
            8 => Some(Self::Op),
            _ => None,
        }
    }

    /// The register encoding of this state.
    pub fn bits(self) -> u8 {
        self as u8
    }
}

impl core::fmt::Display for AlState {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Init => "INIT",
            Self::PreOp => "PRE-OP",
            Self::Boot => "BOOT",
            Self::SafeOp => "SAFE-OP",
            Self::Op => "OP",
        })
    }
}

/// AL status codes (register 0x0134) used by this crate and useful to applications
/// (ETG.1000.6 table 11).
pub mod al_status {
    /// No error.
    pub const NO_ERROR: u16 = 0x0000;
    /// Unspecified error.
    pub const UNSPECIFIED: u16 = 0x0001;
    /// Invalid requested state change (e.g. INIT -> OP).
    pub const INVALID_STATE_CHANGE: u16 = 0x0011;
    /// Unknown requested state.
    pub const UNKNOWN_STATE: u16 = 0x0012;
    /// Bootstrap not supported.
    pub const BOOTSTRAP_NOT_SUPPORTED: u16 = 0x0013;
    /// No valid firmware.
    pub const NO_VALID_FIRMWARE: u16 = 0x0014;
    /// Invalid mailbox configuration (BOOT).
    pub const INVALID_MAILBOX_CONFIG_BOOT: u16 = 0x0015;
    /// Invalid mailbox configuration (PRE-OP).
    pub const INVALID_MAILBOX_CONFIG: u16 = 0x0016;
    /// Invalid sync manager configuration.
    pub const INVALID_SM_CONFIG: u16 = 0x0017;
    /// No valid inputs available.
    pub const NO_VALID_INPUTS: u16 = 0x0018;
    /// No valid outputs.
    pub const NO_VALID_OUTPUTS: u16 = 0x0019;
    /// Synchronization error.
    pub const SYNC_ERROR: u16 = 0x001A;
    /// Sync manager watchdog.
    pub const SM_WATCHDOG: u16 = 0x001B;
    /// Invalid output configuration.
    pub const INVALID_OUTPUT_CONFIG: u16 = 0x001D;
    /// Invalid input configuration.
    pub const INVALID_INPUT_CONFIG: u16 = 0x001E;
    /// Invalid input mapping.
    pub const INVALID_INPUT_MAPPING: u16 = 0x0024;
    /// Invalid output mapping.
    pub const INVALID_OUTPUT_MAPPING: u16 = 0x0025;
}

/// A CoE SDO abort code (ETG.1000.6 table 41, CiA 301).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
#[error("SDO abort {0:#010x}")]
pub struct SdoAbort(pub u32);

impl SdoAbort {
    /// Toggle bit not changed.
    pub const TOGGLE: Self = Self(0x0503_0000);
    /// SDO protocol timeout.
    pub const TIMEOUT: Self = Self(0x0504_0000);
    /// Client/server command specifier not valid or unknown.
    pub const COMMAND: Self = Self(0x0504_0001);
    /// Out of memory.
    pub const OUT_OF_MEMORY: Self = Self(0x0504_0005);
    /// Unsupported access to an object (also: complete access, which this ESC does not offer).
    pub const UNSUPPORTED_ACCESS: Self = Self(0x0601_0000);
    /// Attempt to read a write-only object.
    pub const WRITE_ONLY: Self = Self(0x0601_0001);
    /// Attempt to write a read-only object.
    pub const READ_ONLY: Self = Self(0x0601_0002);
    /// Sub-index cannot be written, sub-index 0 must be 0 for write access.
    pub const SUBINDEX_CANNOT_BE_WRITTEN: Self = Self(0x0601_0003);
    /// Object does not exist in the object dictionary.
    pub const OBJECT_DOES_NOT_EXIST: Self = Self(0x0602_0000);
    /// Object cannot be mapped to the PDO.
    pub const CANNOT_BE_MAPPED: Self = Self(0x0604_0041);
    /// The number and length of the objects to be mapped would exceed the PDO length.
    pub const PDO_LENGTH_EXCEEDED: Self = Self(0x0604_0042);
    /// General parameter incompatibility.
    pub const PARAMETER_INCOMPATIBLE: Self = Self(0x0604_0043);
    /// General internal incompatibility in the device.
    pub const INTERNAL_INCOMPATIBILITY: Self = Self(0x0604_0047);
    /// Access failed due to a hardware error.
    pub const HARDWARE_ERROR: Self = Self(0x0606_0000);
    /// Data type does not match, length of service parameter does not match.
    pub const LENGTH_MISMATCH: Self = Self(0x0607_0010);
    /// Data type does not match, length of service parameter too high.
    pub const LENGTH_TOO_HIGH: Self = Self(0x0607_0012);
    /// Data type does not match, length of service parameter too low.
    pub const LENGTH_TOO_LOW: Self = Self(0x0607_0013);
    /// Sub-index does not exist.
    pub const SUBINDEX_DOES_NOT_EXIST: Self = Self(0x0609_0011);
    /// Value range of parameter exceeded (only for write access).
    pub const VALUE_RANGE: Self = Self(0x0609_0030);
    /// Value of parameter written too high.
    pub const VALUE_TOO_HIGH: Self = Self(0x0609_0031);
    /// Value of parameter written too low.
    pub const VALUE_TOO_LOW: Self = Self(0x0609_0032);
    /// General error.
    pub const GENERAL: Self = Self(0x0800_0000);
    /// Data cannot be transferred or stored to the application.
    pub const TRANSFER: Self = Self(0x0800_0020);
    /// Data cannot be transferred because of local control.
    pub const LOCAL_CONTROL: Self = Self(0x0800_0021);
    /// Data cannot be transferred in the present device state (e.g. PDO mapping outside PRE-OP).
    pub const STATE: Self = Self(0x0800_0022);
    /// Object dictionary dynamic generation fails or no object dictionary is present.
    pub const NO_DICTIONARY: Self = Self(0x0800_0023);
}

/// The [`Application`] methods of a SubDevice without an object dictionary or process data
/// (a bridge, a bootloader, a test's bare device): every SDO is refused with
/// [`SdoAbort::OBJECT_DOES_NOT_EXIST`], both process images are empty. Write it inside the
/// `impl Application` block.
#[macro_export]
macro_rules! no_objects {
    () => {
        fn sdo_read(&mut self, _: u16, _: u8) -> Result<Vec<u8>, $crate::SdoAbort> {
            Err($crate::SdoAbort::OBJECT_DOES_NOT_EXIST)
        }
        fn sdo_write(
            &mut self,
            _: u16,
            _: u8,
            _: &[u8],
            _: $crate::AlState,
        ) -> Result<(), $crate::SdoAbort> {
            Err($crate::SdoAbort::OBJECT_DOES_NOT_EXIST)
        }
        fn process_image_sizes(&self) -> Result<(usize, usize), u16> {
            Ok((0, 0))
        }
        fn write_outputs(&mut self, _: &[u8], _: ::core::time::Duration) {}
        fn read_inputs(&mut self, _: &mut [u8], _: ::core::time::Duration) {}
    };
}

/// The device behind the ESC: its object dictionary and its reaction to process data.
///
/// All methods are called synchronously from [`SubDevice::process_frame`]; keep them short.
pub trait Application {
    /// SDO upload (read) of `index:sub`. Sub-index 0 of a record/array is its number of entries.
    ///
    /// CoE complete access is not offered by this ESC (the SII says so and such requests are
    /// aborted with [`SdoAbort::UNSUPPORTED_ACCESS`] before reaching the application).
    fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, SdoAbort>;

    /// SDO download (write) of `index:sub`. `state` is the current AL state, so that the
    /// application can refuse writes that are only allowed in PRE-OP (e.g. PDO assignment and
    /// mapping: [`SdoAbort::STATE`] outside PRE-OP). The application checks the length.
    fn sdo_write(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        state: AlState,
    ) -> Result<(), SdoAbort>;

    /// Output (RxPDO) and input (TxPDO) image sizes in bytes (the mapped bits of all assigned
    /// PDOs, rounded up to whole bytes, as a MainDevice computes the SM2/SM3 lengths from
    /// 0x1C12/0x1C13 and the mapping objects) for the current PDO assignment and mapping; `Err` with the AL status code ([`al_status::INVALID_OUTPUT_CONFIG`] /
    /// [`al_status::INVALID_INPUT_CONFIG`], or a mapping code) if the assignment is unusable.
    ///
    /// Called once by [`SubDevice::new`] for the SII SyncManager category defaults, and at
    /// PRE-OP -> SAFE-OP to check SM2/SM3.
    fn process_image_sizes(&self) -> Result<(usize, usize), u16>;

    /// New outputs from the MainDevice (only called in OP; in SAFE-OP outputs are ignored as the
    /// standard says). `outputs` is the whole SM2 buffer.
    fn write_outputs(&mut self, outputs: &[u8], now: Duration);

    /// Fills the inputs (the whole SM3 buffer) just before the MainDevice reads them, in SAFE-OP
    /// and OP.
    fn read_inputs(&mut self, inputs: &mut [u8], now: Duration);

    /// A requested state transition (the ESC has already checked the SyncManagers).
    /// `Err(AL status code)` refuses it; the ESC then stays in `from`, sets the error flag and the
    /// code. Only upward transitions (and INIT -> BOOT) can be refused: downward transitions
    /// always happen, as the standard requires, and their result is ignored.
    fn transition(&mut self, from: AlState, to: AlState) -> Result<(), u16> {
        let _ = (from, to);
        Ok(())
    }

    /// The SM watchdog fired (outputs stopped arriving in OP); the ESC is now in SAFE-OP with the
    /// error flag and code 0x001B. The application should go to its safe state (e.g. hold).
    fn outputs_lost(&mut self) {}

    /// A mailbox request of a protocol other than CoE (`mailbox_type`: 1 AoE, 2 EoE, 4 FoE,
    /// 5 SoE, 15 VoE) that the SII advertises in [`EscConfig::mailbox_protocols`]. `payload` is
    /// the mailbox data after the 6-byte mailbox header. Return the reply payload (sent back with
    /// the same mailbox type), or `None` to answer with a mailbox error "unsupported protocol"
    /// (the default). In BOOT only FoE reaches it (CoE and the others get "unsupported
    /// protocol" there), so a boot loader is built on it. Called through the default
    /// [`mailbox_request`](Self::mailbox_request); implement that one instead to know the time
    /// and the mailbox sizes, or to stay silent.
    fn mailbox(&mut self, mailbox_type: u8, payload: &[u8], state: AlState) -> Option<Vec<u8>> {
        let _ = (mailbox_type, payload, state);
        None
    }

    /// The full form of [`mailbox`](Self::mailbox), which is what the ESC calls: `cx` also says
    /// when the request came and how large the mailboxes are (a file transfer sizes its packets
    /// from the receive mailbox), and the reply may be [`MailboxReply::Silent`] (no answer at
    /// all: a request that is not answered, such as an FoE ERR, or a device that hangs). The
    /// default calls [`mailbox`](Self::mailbox).
    fn mailbox_request(
        &mut self,
        mailbox_type: u8,
        payload: &[u8],
        cx: &MailboxContext,
    ) -> MailboxReply {
        match self.mailbox(mailbox_type, payload, cx.state) {
            Some(reply) => MailboxReply::Reply(reply),
            None => MailboxReply::Unsupported,
        }
    }

    /// Called with the ESC's clock before every frame is processed and on every
    /// [`SubDevice::tick`] (not while the device restarts): lets the application run its own
    /// timers (e.g. a flash write) and ask the ESC for something ([`AppRequest`]).
    fn poll(&mut self, now: Duration, state: AlState) -> AppRequest {
        let _ = (now, state);
        AppRequest::None
    }

    /// The firmware's access to programmed one-buffer sync managers (only with
    /// [`SyncManagers::Programmed`]): called right after [`poll`](Self::poll), in SAFE-OP and
    /// OP, before every frame and on every [`SubDevice::tick`].
    fn pdi(&mut self, now: Duration, state: AlState, pdi: &mut Pdi<'_>) {
        let _ = (now, state, pdi);
    }
}

/// When and where a mailbox request arrived (see [`Application::mailbox_request`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MailboxContext {
    /// The AL state.
    pub state: AlState,
    /// The ESC's clock when the request was written.
    pub now: Duration,
    /// Length of the receive mailbox (SM0) as the MainDevice configured it: the longest
    /// request, header included.
    pub request_size: usize,
    /// The longest reply payload (the send mailbox, SM1, minus the 6-byte mailbox header).
    pub reply_capacity: usize,
}

/// The application's answer to a mailbox request (see [`Application::mailbox_request`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MailboxReply {
    /// Reply with this payload, in a mailbox message of the request's type.
    Reply(Vec<u8>),
    /// No reply at all.
    Silent,
    /// A mailbox error "unsupported protocol".
    Unsupported,
}

/// What the application asks of its ESC (see [`Application::poll`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AppRequest {
    /// Nothing.
    #[default]
    None,
    /// The device restarts (e.g. after a firmware update): the ESC stops answering frames for
    /// `offline` (a device that reboots forwards nothing) and comes back as at power-on: INIT,
    /// station address 0, sync managers and FMMUs cleared, SII reloaded. See
    /// [`SubDevice::restart`].
    Restart {
        /// How long the device does not answer.
        offline: Duration,
    },
}

/// The identity object as the SII EEPROM (words 0x08..0x0F) carries it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Identity {
    /// Vendor ID (ETG-assigned).
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision number.
    pub revision: u32,
    /// Serial number.
    pub serial: u32,
}

/// Mailbox protocol bits of SII word 0x1C (`EscConfig::mailbox_protocols`).
pub mod mailbox_protocols {
    /// ADS over EtherCAT.
    pub const AOE: u16 = 0x01;
    /// Ethernet over EtherCAT.
    pub const EOE: u16 = 0x02;
    /// CAN application protocol over EtherCAT.
    pub const COE: u16 = 0x04;
    /// File access over EtherCAT.
    pub const FOE: u16 = 0x08;
    /// Servo drive profile over EtherCAT.
    pub const SOE: u16 = 0x10;
    /// Vendor specific.
    pub const VOE: u16 = 0x20;
}

/// Configuration of the emulated ESC and its SII EEPROM.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EscConfig {
    /// Identity (SII words 0x08..0x0F).
    pub identity: Identity,
    /// Device name (SII string 1, referenced as order and name string by the General category;
    /// ethercrab shows it as `SubDevice::name`, at most 64 bytes there).
    pub name: String,
    /// Source MAC address of returned frames. Must not be the MainDevice's own address
    /// (ethercrab: 10:10:10:10:10:10), or the MainDevice drops the replies as its own frames; if
    /// it is, the ESC flips the locally administered bit of the incoming source address instead,
    /// as a real first ESC does.
    pub mac: [u8; 6],
    /// Standard receive mailbox (MainDevice -> SubDevice, SM0): offset, size.
    pub rx_mailbox: (u16, u16),
    /// Standard send mailbox (SubDevice -> MainDevice, SM1): offset, size.
    pub tx_mailbox: (u16, u16),
    /// Bootstrap receive mailbox (SII words 0x14/0x15), used in BOOT; size 0: no BOOT.
    pub bootstrap_rx_mailbox: (u16, u16),
    /// Bootstrap send mailbox (SII words 0x16/0x17), used in BOOT.
    pub bootstrap_tx_mailbox: (u16, u16),
    /// SM2 (outputs) start address.
    pub outputs_address: u16,
    /// SM3 (inputs) start address.
    pub inputs_address: u16,
    /// SM watchdog: no outputs for this long in OP -> SAFE-OP + ERR, AL status code 0x001B.
    /// Sets the power-on value of register 0x0420 in units of 100 µs (divider 0x0400 = 2498);
    /// `Duration::ZERO` disables it. The MainDevice may reprogram both registers.
    pub watchdog: Duration,
    /// Mailbox protocols (SII word 0x1C): see [`mailbox_protocols`].
    pub mailbox_protocols: u16,
    /// Another SubDevice is linked behind this one on port 1 (DL status: link and
    /// communication on port 1, its loop open), as on a bus of several SubDevices whose frames
    /// the caller passes through each in turn. `false`: the last SubDevice (port 1 closed).
    pub port1_linked: bool,
    /// Period of the application firmware's main loop, which reads AL control once per loop:
    /// writes between two loops are seen as one, the latest value (ETG.1000.6 leaves the
    /// sampling to the application; a firmware polling the register does this). A MainDevice
    /// that writes an acknowledge and a state request back to back has the acknowledge missed.
    /// `Duration::ZERO`: every write is acted on at once (an ESC whose PDI handles each AL
    /// event interrupt).
    pub firmware_loop: Duration,
    /// How the firmware uses its sync managers: the standard layout the SII announces, or sync
    /// managers the MainDevice must program itself (see [`SyncManagers`]).
    pub sync_managers: SyncManagers,
}

/// How the firmware behind the ESC uses its sync managers.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum SyncManagers {
    /// The standard layout: the SII announces the mailbox (SM0/SM1, served as a CoE/FoE
    /// mailbox) and buffered process data (SM2/SM3, sized by the application's PDOs), with
    /// their FMMU usage.
    #[default]
    Standard,
    /// A device whose SII announces no mailbox, no FMMUs and no sync managers (as the Shadow
    /// palm): the MainDevice must program SM *n* as entry *n* says (checked at PRE-OP ->
    /// SAFE-OP, refused with [`al_status::INVALID_SM_CONFIG`] otherwise) and map them with
    /// FMMUs of its own. The firmware serves them in SAFE-OP and OP; their buffers belong to
    /// the application, through [`Application::pdi`]. The standard mailbox and process data
    /// areas of the configuration are unused.
    Programmed(Vec<SmSetting>),
}

/// One sync manager as a firmware expects the MainDevice to program it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SmSetting {
    /// Physical start address.
    pub start: u16,
    /// Length in bytes.
    pub len: u16,
    /// Control byte (register +4): mode, direction, event enables.
    pub control: u8,
}

/// The application's access to the buffers of one-buffer (mailbox-mode) sync managers, as its
/// firmware has them through the PDI (see [`SyncManagers::Programmed`]): a buffer the
/// MainDevice wrote is taken (which empties it for the next write), a buffer the MainDevice
/// reads is put (refused while the previous one has not been read).
pub struct Pdi<'a> {
    pub(crate) esc: &'a mut dyn PdiAccess,
}

/// What [`Pdi`] needs of the ESC.
pub(crate) trait PdiAccess {
    fn written(&self, sm: usize) -> Option<Duration>;
    fn take(&mut self, sm: usize) -> Option<&[u8]>;
    fn put(&mut self, sm: usize, data: &[u8]) -> bool;
}

impl Pdi<'_> {
    /// When the MainDevice completed the buffer of SM `sm` that waits to be taken (the "SM
    /// written" AL event a firmware polls); `None` when nothing waits.
    pub fn written(&self, sm: usize) -> Option<Duration> {
        self.esc.written(sm)
    }

    /// The buffer of SM `sm` if the MainDevice wrote it completely since it was last taken
    /// (the "SM written" AL event); taking it lets the MainDevice write the next one. `None`
    /// when nothing new is there, or SM `sm` is not an enabled one-buffer SM the MainDevice
    /// writes.
    pub fn take(&mut self, sm: usize) -> Option<&[u8]> {
        self.esc.take(sm)
    }

    /// Writes `data` (cut or zero-padded to its length) into SM `sm` for the MainDevice to
    /// read; `false` (nothing written) while the MainDevice has not read the previous one, or
    /// when SM `sm` is not an enabled one-buffer SM the MainDevice reads.
    pub fn put(&mut self, sm: usize, data: &[u8]) -> bool {
        self.esc.put(sm, data)
    }
}

impl Default for EscConfig {
    fn default() -> Self {
        Self {
            identity: Identity {
                vendor_id: 0,
                product_code: 1,
                revision: 1,
                serial: 1,
            },
            name: "teleop-ecat-sim".to_owned(),
            // Locally administered, unicast.
            mac: [0x02, 0x00, 0x00, 0x00, 0xec, 0x01],
            rx_mailbox: (0x1000, 128),
            tx_mailbox: (0x1080, 128),
            bootstrap_rx_mailbox: (0x1000, 128),
            bootstrap_tx_mailbox: (0x1080, 128),
            outputs_address: 0x1100,
            inputs_address: 0x1400,
            watchdog: Duration::from_millis(100),
            mailbox_protocols: mailbox_protocols::COE,
            port1_linked: false,
            firmware_loop: Duration::ZERO,
            sync_managers: SyncManagers::Standard,
        }
    }
}

/// Programmed sync managers must lie in the process RAM, not overlap, and be at most 4.
fn validate_programmed(sms: &[SmSetting]) -> Result<(), ConfigError> {
    const NAMES: [&str; 4] = ["SM0", "SM1", "SM2", "SM3"];
    if sms.len() > NAMES.len() {
        return Err(ConfigError::TooManySyncManagers(sms.len()));
    }
    let mut areas: Vec<(&'static str, (usize, usize))> = Vec::with_capacity(sms.len());
    for (name, sm) in NAMES.iter().zip(sms) {
        let end = usize::from(sm.start) + usize::from(sm.len);
        if sm.start < 0x1000 || end > 0x1_0000 || sm.len == 0 {
            return Err(ConfigError::Area {
                what: name,
                start: sm.start,
                len: sm.len.into(),
            });
        }
        for (other, (s, e)) in &areas {
            if usize::from(sm.start) < *e && *s < end {
                return Err(ConfigError::Overlap(other, name));
            }
        }
        areas.push((name, (usize::from(sm.start), end)));
    }
    Ok(())
}

/// A configuration that the ESC cannot honour as given (see [`SubDevice::try_new`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// The MAC address is ethercrab's own (10:10:10:10:10:10) or a multicast address.
    #[error("MAC address {0:02x?} cannot be a SubDevice source address")]
    Mac([u8; 6]),
    /// A mailbox or process data area lies outside the process RAM (0x1000..0x10000) or a
    /// mailbox is smaller than 16 bytes.
    #[error("{what} area {start:#06x}+{len} is invalid")]
    Area {
        /// Which area.
        what: &'static str,
        /// Start address.
        start: u16,
        /// Length in bytes.
        len: usize,
    },
    /// Two areas of the same state overlap.
    #[error("{0} overlaps {1}")]
    Overlap(&'static str, &'static str),
    /// More programmed sync managers than the ESC has.
    #[error("{0} programmed sync managers, the ESC has 4")]
    TooManySyncManagers(usize),
    /// The device name does not fit an SII string (255 bytes).
    #[error("device name is {0} bytes long, at most 255 fit the SII")]
    NameTooLong(usize),
}

impl EscConfig {
    /// Checks the configuration against the image sizes `(outputs, inputs)` the SII will
    /// announce.
    pub fn validate(&self, image_sizes: (usize, usize)) -> Result<(), ConfigError> {
        let mac = self.mac;
        if mac == [0x10; 6] || mac[0] & 0x01 != 0 {
            return Err(ConfigError::Mac(mac));
        }
        if self.name.len() > 255 {
            return Err(ConfigError::NameTooLong(self.name.len()));
        }
        if let SyncManagers::Programmed(sms) = &self.sync_managers {
            return validate_programmed(sms);
        }
        let area = |what: &'static str, (start, len): (u16, usize), mailbox: bool| {
            let end = usize::from(start) + len;
            if start < 0x1000 || end > 0x1_0000 || (mailbox && len < 16) {
                Err(ConfigError::Area { what, start, len })
            } else {
                Ok((usize::from(start), end))
            }
        };
        let rx = area(
            "rx mailbox",
            (self.rx_mailbox.0, self.rx_mailbox.1.into()),
            true,
        )?;
        let tx = area(
            "tx mailbox",
            (self.tx_mailbox.0, self.tx_mailbox.1.into()),
            true,
        )?;
        let out = area("outputs", (self.outputs_address, image_sizes.0), false)?;
        let inp = area("inputs", (self.inputs_address, image_sizes.1), false)?;
        let overlaps = |a: (usize, usize), b: (usize, usize)| a.0 < b.1 && b.0 < a.1;
        let named = [
            ("rx mailbox", rx),
            ("tx mailbox", tx),
            ("outputs", out),
            ("inputs", inp),
        ];
        for (i, (na, a)) in named.iter().enumerate() {
            for (nb, b) in named.iter().skip(i + 1) {
                if overlaps(*a, *b) {
                    return Err(ConfigError::Overlap(na, nb));
                }
            }
        }
        if self.bootstrap_rx_mailbox.1 > 0 || self.bootstrap_tx_mailbox.1 > 0 {
            let brx = area(
                "bootstrap rx mailbox",
                (
                    self.bootstrap_rx_mailbox.0,
                    self.bootstrap_rx_mailbox.1.into(),
                ),
                true,
            )?;
            let btx = area(
                "bootstrap tx mailbox",
                (
                    self.bootstrap_tx_mailbox.0,
                    self.bootstrap_tx_mailbox.1.into(),
                ),
                true,
            )?;
            if overlaps(brx, btx) {
                return Err(ConfigError::Overlap(
                    "bootstrap rx mailbox",
                    "bootstrap tx mailbox",
                ));
            }
        }
        Ok(())
    }
}
