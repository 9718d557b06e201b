//! The CoE object dictionary of the Revo2 (sections 1 to 4) as typed static
//! entries, the PDO mappings and the sync-manager assignments.

use crate::identity::{DEVICE_NAME, PRODUCT_CODE, REVISION, VENDOR_ID};

/// CoE data type, with its code from the CoE data-type area (ETG.1000.6).
///
/// Arrays are described by their element type; the array length follows
/// from [`Entry::bit_len`] (`n * element bits`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u16)]
pub enum DataType {
    /// `BOOLEAN`, 0x0001.
    Bool = 0x0001,
    /// `INTEGER8`, 0x0002.
    Int8 = 0x0002,
    /// `INTEGER16`, 0x0003.
    Int16 = 0x0003,
    /// `INTEGER32`, 0x0004.
    Int32 = 0x0004,
    /// `UNSIGNED8`, 0x0005.
    Uint8 = 0x0005,
    /// `UNSIGNED16`, 0x0006.
    Uint16 = 0x0006,
    /// `UNSIGNED32`, 0x0007.
    Uint32 = 0x0007,
    /// `REAL32`, 0x0008.
    Real32 = 0x0008,
    /// `VISIBLE_STRING`, 0x0009 (the document's `STRING(n)`).
    VisibleString = 0x0009,
    /// `OCTET_STRING`, 0x000A.
    OctetString = 0x000A,
    /// `INTEGER64`, 0x0015.
    Int64 = 0x0015,
    /// `UNSIGNED64`, 0x001B.
    Uint64 = 0x001B,
}

impl DataType {
    /// The CoE data-type code.
    pub const fn code(self) -> u16 {
        self as u16
    }

    /// The data type with CoE code `code`, if this crate knows it.
    pub const fn from_code(code: u16) -> Option<DataType> {
        match code {
            0x0001 => Some(DataType::Bool),
            0x0002 => Some(DataType::Int8),
            0x0003 => Some(DataType::Int16),
            0x0004 => Some(DataType::Int32),
            0x0005 => Some(DataType::Uint8),
            0x0006 => Some(DataType::Uint16),
            0x0007 => Some(DataType::Uint32),
            0x0008 => Some(DataType::Real32),
            0x0009 => Some(DataType::VisibleString),
            0x000A => Some(DataType::OctetString),
            0x0015 => Some(DataType::Int64),
            0x001B => Some(DataType::Uint64),
            _ => None,
        }
    }

    /// Bits of one element (one character for the string types).
    pub const fn element_bits(self) -> u16 {
        match self {
            DataType::Bool => 1,
            DataType::Int8 | DataType::Uint8 => 8,
            DataType::VisibleString | DataType::OctetString => 8,
            DataType::Int16 | DataType::Uint16 => 16,
            DataType::Int32 | DataType::Uint32 | DataType::Real32 => 32,
            DataType::Int64 | DataType::Uint64 => 64,
        }
    }

    /// Whether this is a string type (`VISIBLE_STRING` or `OCTET_STRING`).
    pub const fn is_string(self) -> bool {
        matches!(self, DataType::VisibleString | DataType::OctetString)
    }
}

/// SDO access rights of an entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Access {
    /// Read only (the document's "RO").
    Ro,
    /// Read and write (the document's "WR").
    Rw,
    /// Write only (the document's "WO").
    Wo,
}

impl Access {
    /// Whether an SDO upload (read) is allowed.
    pub const fn is_readable(self) -> bool {
        matches!(self, Access::Ro | Access::Rw)
    }

    /// Whether an SDO download (write) is allowed.
    pub const fn is_writable(self) -> bool {
        matches!(self, Access::Rw | Access::Wo)
    }
}

/// Whether (and how) an entry can be mapped into process data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PdoDirection {
    /// Not mappable (SDO only).
    None,
    /// Mapped into an RxPDO: outputs, master to slave.
    Rx,
    /// Mapped into a TxPDO: inputs, slave to master.
    Tx,
}

/// Default (power-on) value of an entry, where one is known.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DefaultValue {
    /// An unsigned integer (of any width up to 32 bits).
    Unsigned(u32),
    /// A string.
    Str(&'static str),
}

/// One sub-index of the object dictionary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Entry {
    /// Object index (e.g. 0x8000).
    pub index: u16,
    /// Sub-index (0 = "highest sub-index" of a record).
    pub sub: u8,
    /// Name; for sections 3 and 4 exactly the document's parameter name
    /// (with its spelling, e.g. `pink_pro_cur`).
    pub name: &'static str,
    /// Element data type.
    pub data_type: DataType,
    /// Size in bits (`n * element bits` for arrays, `8 * n` for strings).
    pub bit_len: u16,
    /// SDO access.
    pub access: Access,
    /// PDO mappability.
    pub pdo: PdoDirection,
    /// Default value when known (the document gives almost none).
    pub default: Option<DefaultValue>,
    /// What the entry means (paraphrased from the document).
    pub description: &'static str,
}

impl Entry {
    /// Size in bytes, rounded up.
    pub const fn byte_len(&self) -> usize {
        (self.bit_len as usize).div_ceil(8)
    }

    /// Number of elements (array length, string capacity in characters).
    pub const fn elements(&self) -> u16 {
        self.bit_len / self.data_type.element_bits()
    }

    const fn rx(mut self) -> Entry {
        self.pdo = PdoDirection::Rx;
        self
    }

    const fn tx(mut self) -> Entry {
        self.pdo = PdoDirection::Tx;
        self
    }

    const fn default_u(mut self, value: u32) -> Entry {
        self.default = Some(DefaultValue::Unsigned(value));
        self
    }

    const fn default_str(mut self, value: &'static str) -> Entry {
        self.default = Some(DefaultValue::Str(value));
        self
    }
}

/// One entry of a PDO mapping object (0x1600, 0x1A00, 0x1A01): which
/// object is mapped, and how many bits of it.
///
/// Encoded in the mapping object's sub-indices as a `UNSIGNED32`:
/// `index << 16 | sub << 8 | bit_len`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MappingEntry {
    /// Mapped object index.
    pub index: u16,
    /// Mapped sub-index.
    pub sub: u8,
    /// Mapped length in bits.
    pub bit_len: u8,
}

impl MappingEntry {
    /// A mapping entry.
    pub const fn new(index: u16, sub: u8, bit_len: u8) -> MappingEntry {
        MappingEntry {
            index,
            sub,
            bit_len,
        }
    }

    /// The `UNSIGNED32` value stored in a mapping object.
    pub const fn encode(self) -> u32 {
        (self.index as u32) << 16 | (self.sub as u32) << 8 | self.bit_len as u32
    }

    /// Splits a mapping object's `UNSIGNED32` value (total: any value gives
    /// an entry; index 0 is a gap in CoE).
    pub const fn decode(raw: u32) -> MappingEntry {
        MappingEntry {
            index: (raw >> 16) as u16,
            sub: (raw >> 8) as u8,
            bit_len: raw as u8,
        }
    }
}

/// Object indices used by this crate.
pub mod obj {
    /// 0x1000 device type.
    pub const DEVICE_TYPE: u16 = 0x1000;
    /// 0x1008 manufacturer device name.
    pub const DEVICE_NAME: u16 = 0x1008;
    /// 0x1009 manufacturer hardware version.
    pub const HW_VERSION: u16 = 0x1009;
    /// 0x100A manufacturer software version.
    pub const SW_VERSION: u16 = 0x100A;
    /// 0x1018 identity object.
    pub const IDENTITY: u16 = 0x1018;
    /// 0x1600 RxPDO mapping (section 2.2).
    pub const RX_PDO: u16 = 0x1600;
    /// 0x1A00 joint-data TxPDO mapping (section 2.3).
    pub const JOINT_TX_PDO: u16 = 0x1A00;
    /// 0x1A01 tactile TxPDO mapping: not given by the document, chosen as
    /// the next free TxPDO index (ambiguity 1 of the crate docs).
    pub const TACTILE_TX_PDO: u16 = 0x1A01;
    /// 0x1C12 SM2 (outputs) PDO assignment.
    pub const SM2_ASSIGN: u16 = 0x1C12;
    /// 0x1C13 SM3 (inputs) PDO assignment.
    pub const SM3_ASSIGN: u16 = 0x1C13;
    /// 0x6000 joint inputs (position, speed, current, status).
    pub const JOINT_INPUTS: u16 = 0x6000;
    /// 0x6010 tactile inputs.
    pub const TACTILE_INPUTS: u16 = 0x6010;
    /// 0x7000 multi-finger outputs.
    pub const MULTI_FINGER: u16 = 0x7000;
    /// 0x7010 single-finger outputs.
    pub const SINGLE_FINGER: u16 = 0x7010;
    /// 0x8000 configuration (section 3).
    pub const CONFIG: u16 = 0x8000;
    /// 0x8010 tactile configuration (section 4).
    pub const TACTILE_CONFIG: u16 = 0x8010;
}

/// Mapping of RxPDO 0x1600 (section 2.2).
pub const RX_MAPPING: &[MappingEntry] = &[
    MappingEntry::new(0x7000, 0x01, 8),
    MappingEntry::new(0x7000, 0x02, 96),
    MappingEntry::new(0x7000, 0x03, 96),
    MappingEntry::new(0x7010, 0x01, 8),
    MappingEntry::new(0x7010, 0x02, 8),
    MappingEntry::new(0x7010, 0x03, 16),
    MappingEntry::new(0x7010, 0x04, 16),
];

/// Mapping of the joint-data TxPDO 0x1A00 (section 2.3).
pub const JOINT_TX_MAPPING: &[MappingEntry] = &[
    MappingEntry::new(0x6000, 0x01, 96),
    MappingEntry::new(0x6000, 0x02, 96),
    MappingEntry::new(0x6000, 0x03, 96),
    MappingEntry::new(0x6000, 0x04, 96),
];

/// Mapping of the tactile TxPDO 0x1A01 (section 2.4; the index is ours).
pub const TACTILE_TX_MAPPING: &[MappingEntry] = &[
    MappingEntry::new(0x6010, 0x01, 80),
    MappingEntry::new(0x6010, 0x02, 80),
    MappingEntry::new(0x6010, 0x03, 80),
    MappingEntry::new(0x6010, 0x04, 160),
    MappingEntry::new(0x6010, 0x05, 80),
];

/// Default SM2 assignment (0x1C12): the RxPDO.
pub const DEFAULT_RX_ASSIGNMENT: [u16; 1] = [obj::RX_PDO];

/// Default SM3 assignment (0x1C13): joint data, then tactile data.
///
/// Ambiguity 2 of the crate docs: section 2.1 lists only 0x1A00 for SM3,
/// while section 2.4 says the tactile data is "directly mapped" too. A
/// vendor's Touch-version ESI would assign both, so that is our default;
/// [`JOINT_ONLY_TX_ASSIGNMENT`] is the document's literal reading. The
/// master should read 0x1C13 back from the device and pass what it reads
/// to [`Inputs::unpack`](crate::Inputs::unpack).
pub const DEFAULT_TX_ASSIGNMENT: [u16; 2] = [obj::JOINT_TX_PDO, obj::TACTILE_TX_PDO];

/// SM3 assignment with joint data only (section 2.1 read literally, or a
/// hand without tactile sensors).
pub const JOINT_ONLY_TX_ASSIGNMENT: [u16; 1] = [obj::JOINT_TX_PDO];

/// Sum of the mapped bits of a mapping.
pub const fn mapping_bits(mapping: &[MappingEntry]) -> usize {
    let mut bits = 0;
    let mut i = 0;
    while i < mapping.len() {
        bits += mapping[i].bit_len as usize;
        i += 1;
    }
    bits
}

/// The mapping of PDO `pdo_index` (0x1600, 0x1A00 or 0x1A01).
pub fn mapping_entries(pdo_index: u16) -> Option<&'static [MappingEntry]> {
    match pdo_index {
        obj::RX_PDO => Some(RX_MAPPING),
        obj::JOINT_TX_PDO => Some(JOINT_TX_MAPPING),
        obj::TACTILE_TX_PDO => Some(TACTILE_TX_MAPPING),
        _ => None,
    }
}

/// Bytes of the process image laid out by the assignment `pdos` (the
/// sub-indices of 0x1C12 or 0x1C13, in order); `None` if a PDO is unknown.
///
/// Process data is tightly packed; the total is rounded up to whole bytes.
pub fn image_len(pdos: &[u16]) -> Option<usize> {
    let mut bits = 0usize;
    for &pdo in pdos {
        bits += mapping_bits(mapping_entries(pdo)?);
    }
    Some(bits.div_ceil(8))
}

const fn var(
    index: u16,
    sub: u8,
    name: &'static str,
    data_type: DataType,
    bit_len: u16,
    access: Access,
    description: &'static str,
) -> Entry {
    Entry {
        index,
        sub,
        name,
        data_type,
        bit_len,
        access,
        pdo: PdoDirection::None,
        default: None,
        description,
    }
}

/// Sub-index 0 of a record: its highest sub-index.
const fn count(index: u16, highest: u8, access: Access) -> Entry {
    var(
        index,
        0,
        "n_entries",
        DataType::Uint8,
        8,
        access,
        "highest sub-index of the object",
    )
    .default_u(highest as u32)
}

/// Sub-index `sub` (1-based) of a mapping object.
const fn map(index: u16, mapping: &[MappingEntry], sub: u8, description: &'static str) -> Entry {
    var(
        index,
        sub,
        "mapping_entry",
        DataType::Uint32,
        32,
        Access::Ro,
        description,
    )
    .default_u(mapping[sub as usize - 1].encode())
}

use Access::{Ro, Rw, Wo};
use DataType::{Int16, Uint16, Uint32, Uint8, VisibleString};

/// The whole object dictionary.
///
/// Decisions (see the crate docs): the PDO mappings are fixed (read-only,
/// ambiguity 25); the assignments 0x1C12/0x1C13 are writable in PRE-OP so a
/// master can drop the tactile PDO; 0x8010's sub-indices are decimal 1..=17
/// (ambiguity 16); the document gives no defaults for sections 3 and 4.
pub const DICTIONARY: &[Entry] = &[
    // --- communication area -------------------------------------------
    // The document does not give 0x1000. The 0x6000/0x7000/0x8000 layout
    // is what the EtherCAT slave stack code generates for a modular-device-
    // profile slave, whose default device type is 0x00001389 (MDP 5001).
    // Nothing should depend on this value.
    var(
        obj::DEVICE_TYPE,
        0,
        "device_type",
        Uint32,
        32,
        Ro,
        "device type (assumed 0x00001389, modular device profile)",
    )
    .default_u(0x0000_1389),
    var(
        obj::DEVICE_NAME,
        0,
        "device_name",
        VisibleString,
        8 * DEVICE_NAME.len() as u16,
        Ro,
        "manufacturer device name",
    )
    .default_str(DEVICE_NAME),
    // 0x1009/0x100A: content and length not given; 20 characters assumed
    // like the firmware version strings of 0x8000.
    var(
        obj::HW_VERSION,
        0,
        "hw_version",
        VisibleString,
        160,
        Ro,
        "manufacturer hardware version (length assumed 20)",
    ),
    var(
        obj::SW_VERSION,
        0,
        "sw_version",
        VisibleString,
        160,
        Ro,
        "manufacturer software version (length assumed 20)",
    ),
    count(obj::IDENTITY, 4, Ro),
    var(obj::IDENTITY, 1, "vendor_id", Uint32, 32, Ro, "vendor ID").default_u(VENDOR_ID),
    var(
        obj::IDENTITY,
        2,
        "product_code",
        Uint32,
        32,
        Ro,
        "product code",
    )
    .default_u(PRODUCT_CODE),
    var(
        obj::IDENTITY,
        3,
        "revision",
        Uint32,
        32,
        Ro,
        "revision number",
    )
    .default_u(REVISION),
    var(
        obj::IDENTITY,
        4,
        "serial_number",
        Uint32,
        32,
        Ro,
        "serial number (per device)",
    ),
    // --- PDO mappings ----------------------------------------------------
    count(obj::RX_PDO, 7, Ro),
    map(
        obj::RX_PDO,
        RX_MAPPING,
        1,
        "0x7000:01 multi-finger control mode",
    ),
    map(obj::RX_PDO, RX_MAPPING, 2, "0x7000:02 multi-finger param1"),
    map(obj::RX_PDO, RX_MAPPING, 3, "0x7000:03 multi-finger param2"),
    map(obj::RX_PDO, RX_MAPPING, 4, "0x7010:01 single-finger mode"),
    map(obj::RX_PDO, RX_MAPPING, 5, "0x7010:02 single-finger joint"),
    map(obj::RX_PDO, RX_MAPPING, 6, "0x7010:03 single-finger param1"),
    map(obj::RX_PDO, RX_MAPPING, 7, "0x7010:04 single-finger param2"),
    count(obj::JOINT_TX_PDO, 4, Ro),
    map(
        obj::JOINT_TX_PDO,
        JOINT_TX_MAPPING,
        1,
        "0x6000:01 positions",
    ),
    map(obj::JOINT_TX_PDO, JOINT_TX_MAPPING, 2, "0x6000:02 speeds"),
    map(obj::JOINT_TX_PDO, JOINT_TX_MAPPING, 3, "0x6000:03 currents"),
    map(obj::JOINT_TX_PDO, JOINT_TX_MAPPING, 4, "0x6000:04 status"),
    count(obj::TACTILE_TX_PDO, 5, Ro),
    map(
        obj::TACTILE_TX_PDO,
        TACTILE_TX_MAPPING,
        1,
        "0x6010:01 force_normal",
    ),
    map(
        obj::TACTILE_TX_PDO,
        TACTILE_TX_MAPPING,
        2,
        "0x6010:02 force_tangential",
    ),
    map(
        obj::TACTILE_TX_PDO,
        TACTILE_TX_MAPPING,
        3,
        "0x6010:03 force_direction",
    ),
    map(
        obj::TACTILE_TX_PDO,
        TACTILE_TX_MAPPING,
        4,
        "0x6010:04 proximity",
    ),
    map(
        obj::TACTILE_TX_PDO,
        TACTILE_TX_MAPPING,
        5,
        "0x6010:05 touch_status",
    ),
    // --- sync-manager assignments ---------------------------------------
    count(obj::SM2_ASSIGN, 1, Rw),
    var(
        obj::SM2_ASSIGN,
        1,
        "assigned_pdo",
        Uint16,
        16,
        Rw,
        "SM2 (outputs) PDO",
    )
    .default_u(obj::RX_PDO as u32),
    count(obj::SM3_ASSIGN, 2, Rw),
    var(
        obj::SM3_ASSIGN,
        1,
        "assigned_pdo",
        Uint16,
        16,
        Rw,
        "SM3 (inputs) PDO 1: joint data",
    )
    .default_u(obj::JOINT_TX_PDO as u32),
    var(
        obj::SM3_ASSIGN,
        2,
        "assigned_pdo",
        Uint16,
        16,
        Rw,
        "SM3 (inputs) PDO 2: tactile data",
    )
    .default_u(obj::TACTILE_TX_PDO as u32),
    // --- inputs 0x6000 (section 2.3) -------------------------------------
    count(obj::JOINT_INPUTS, 4, Ro),
    var(
        obj::JOINT_INPUTS,
        1,
        "joint_position",
        Uint16,
        96,
        Ro,
        "positions of the 6 joints",
    )
    .tx(),
    var(
        obj::JOINT_INPUTS,
        2,
        "joint_speed",
        Int16,
        96,
        Ro,
        "speeds of the 6 joints",
    )
    .tx(),
    var(
        obj::JOINT_INPUTS,
        3,
        "joint_current",
        Int16,
        96,
        Ro,
        "currents of the 6 joints",
    )
    .tx(),
    var(
        obj::JOINT_INPUTS,
        4,
        "joint_status",
        Uint16,
        96,
        Ro,
        "status words of the 6 joints (bits not documented)",
    )
    .tx(),
    // --- inputs 0x6010 (section 2.4) -------------------------------------
    count(obj::TACTILE_INPUTS, 5, Ro),
    var(
        obj::TACTILE_INPUTS,
        1,
        "force_normal",
        Uint16,
        80,
        Ro,
        "normal force of 5 fingertips, 0.01 N",
    )
    .tx(),
    // Table: UINT16; bullet list: INT16; text: "16-bit unsigned". UINT16.
    var(
        obj::TACTILE_INPUTS,
        2,
        "force_tangential",
        Uint16,
        80,
        Ro,
        "tangential force of 5 fingertips, 0.01 N",
    )
    .tx(),
    var(
        obj::TACTILE_INPUTS,
        3,
        "force_direction",
        Uint16,
        80,
        Ro,
        "direction of the tangential force, degrees 0..=359, 0xFFFF invalid",
    )
    .tx(),
    var(
        obj::TACTILE_INPUTS,
        4,
        "proximity",
        Uint32,
        160,
        Ro,
        "proximity of 5 fingertips (no unit given)",
    )
    .tx(),
    var(
        obj::TACTILE_INPUTS,
        5,
        "touch_status",
        Uint16,
        80,
        Ro,
        "tactile status: low byte flags, high byte update counter",
    )
    .tx(),
    // --- outputs 0x7000 / 0x7010 (section 2.2) ---------------------------
    count(obj::MULTI_FINGER, 3, Ro),
    var(
        obj::MULTI_FINGER,
        1,
        "mult_finger_ctrl_mode",
        Uint8,
        8,
        Rw,
        "multi-finger control mode (0 = none, 1..=5 see ControlMode)",
    )
    .rx(),
    var(
        obj::MULTI_FINGER,
        2,
        "mult_finger_param1",
        Int16,
        96,
        Rw,
        "multi-finger parameter 1 of the 6 joints",
    )
    .rx(),
    var(
        obj::MULTI_FINGER,
        3,
        "mult_finger_param2",
        Uint16,
        96,
        Rw,
        "multi-finger parameter 2 of the 6 joints",
    )
    .rx(),
    count(obj::SINGLE_FINGER, 4, Ro),
    var(
        obj::SINGLE_FINGER,
        1,
        "finger_ctrl_mode",
        Uint8,
        8,
        Rw,
        "single-finger control mode (0 = none)",
    )
    .rx(),
    var(
        obj::SINGLE_FINGER,
        2,
        "finger_id",
        Uint8,
        8,
        Rw,
        "single-finger target joint (finger_index_t)",
    )
    .rx(),
    var(
        obj::SINGLE_FINGER,
        3,
        "finger_param1",
        Int16,
        16,
        Rw,
        "single-finger parameter 1",
    )
    .rx(),
    var(
        obj::SINGLE_FINGER,
        4,
        "finger_param2",
        Uint16,
        16,
        Rw,
        "single-finger parameter 2",
    )
    .rx(),
    // --- configuration 0x8000 (section 3) --------------------------------
    count(obj::CONFIG, 0x16, Ro),
    var(
        obj::CONFIG,
        0x01,
        "hand_type",
        Uint8,
        8,
        Rw,
        "0 = left hand, 1 = right hand",
    ),
    var(
        obj::CONFIG,
        0x02,
        "led_switch",
        Uint8,
        8,
        Rw,
        "back-of-hand light switch",
    ),
    var(
        obj::CONFIG,
        0x03,
        "buzzer_switch",
        Uint8,
        8,
        Rw,
        "buzzer switch",
    ),
    var(
        obj::CONFIG,
        0x04,
        "vibrator_switch",
        Uint8,
        8,
        Rw,
        "vibration motor switch",
    ),
    var(
        obj::CONFIG,
        0x05,
        "unit_mode",
        Uint8,
        8,
        Rw,
        "0 = dimensionless (percent), 1 = physical units",
    ),
    var(
        obj::CONFIG,
        0x06,
        "pos_calibration",
        Uint8,
        8,
        Wo,
        "manual position calibration",
    ),
    var(
        obj::CONFIG,
        0x07,
        "auto_calibration",
        Uint8,
        8,
        Rw,
        "automatic calibration on start-up",
    ),
    var(obj::CONFIG, 0x08, "turbo_mode", Uint8, 8, Rw, "turbo mode"),
    var(
        obj::CONFIG,
        0x09,
        "turbo_param",
        Uint16,
        32,
        Rw,
        "turbo parameters turbo_param[0], turbo_param[1]",
    ),
    var(
        obj::CONFIG,
        0x0A,
        "thumb_flex_pro_cur",
        Uint16,
        16,
        Rw,
        "thumb flex protection current",
    ),
    var(
        obj::CONFIG,
        0x0B,
        "thumb_aux_pro_cur",
        Uint16,
        16,
        Rw,
        "thumb abduct protection current",
    ),
    var(
        obj::CONFIG,
        0x0C,
        "index_pro_cur",
        Uint16,
        16,
        Rw,
        "index finger protection current",
    ),
    var(
        obj::CONFIG,
        0x0D,
        "mid_pro_cur",
        Uint16,
        16,
        Rw,
        "middle finger protection current",
    ),
    var(
        obj::CONFIG,
        0x0E,
        "ring_pro_cur",
        Uint16,
        16,
        Rw,
        "ring finger protection current",
    ),
    var(
        obj::CONFIG,
        0x0F,
        "pink_pro_cur",
        Uint16,
        16,
        Rw,
        "little finger protection current",
    ),
    var(
        obj::CONFIG,
        0x10,
        "thumb_aux_lock_cur",
        Uint16,
        16,
        Rw,
        "thumb abduct joint locking current",
    ),
    var(
        obj::CONFIG,
        0x11,
        "ctrl_wrist_fw_version",
        VisibleString,
        160,
        Ro,
        "control board firmware version (high.mid.low)",
    ),
    var(
        obj::CONFIG,
        0x12,
        "ctrl_sn",
        VisibleString,
        144,
        Rw,
        "control board serial number",
    ),
    var(
        obj::CONFIG,
        0x13,
        "wrist_fw_version",
        VisibleString,
        160,
        Ro,
        "wrist board firmware version (high.mid.low)",
    ),
    var(
        obj::CONFIG,
        0x14,
        "wrist_sn",
        VisibleString,
        144,
        Rw,
        "wrist board serial number",
    ),
    var(
        obj::CONFIG,
        0x15,
        "foe_file_type",
        Uint8,
        8,
        Wo,
        "FoE file type: 1 = wrist board, 2 = control board",
    ),
    var(
        obj::CONFIG,
        0x16,
        "foe_auth_code",
        VisibleString,
        64,
        Wo,
        "FoE authentication code (BRCW2025 / BRCC2025)",
    ),
    // --- tactile configuration 0x8010 (section 4) ------------------------
    // The table writes these sub-indices in decimal (1..=17): 10 is 0x0A.
    count(obj::TACTILE_CONFIG, 17, Ro),
    var(
        obj::TACTILE_CONFIG,
        1,
        "thumb_calibration",
        Uint8,
        8,
        Wo,
        "thumb tactile calibration",
    ),
    var(
        obj::TACTILE_CONFIG,
        2,
        "index_calibration",
        Uint8,
        8,
        Wo,
        "index finger tactile calibration",
    ),
    var(
        obj::TACTILE_CONFIG,
        3,
        "mid_calibration",
        Uint8,
        8,
        Wo,
        "middle finger tactile calibration",
    ),
    var(
        obj::TACTILE_CONFIG,
        4,
        "ring_calibration",
        Uint8,
        8,
        Wo,
        "ring finger tactile calibration",
    ),
    var(
        obj::TACTILE_CONFIG,
        5,
        "pinky_calibration",
        Uint8,
        8,
        Wo,
        "pinky tactile calibration",
    ),
    var(
        obj::TACTILE_CONFIG,
        6,
        "touch_vendor",
        Uint8,
        8,
        Ro,
        "tactile sensor kind: 1 = capacitive, 2 = pressure-sensitive",
    ),
    var(
        obj::TACTILE_CONFIG,
        7,
        "thumb_acq_param_update",
        Uint8,
        8,
        Wo,
        "thumb channel value adjustment",
    ),
    var(
        obj::TACTILE_CONFIG,
        8,
        "index_acq_param_update",
        Uint8,
        8,
        Wo,
        "index finger channel value adjustment",
    ),
    var(
        obj::TACTILE_CONFIG,
        9,
        "mid_acq_param_update",
        Uint8,
        8,
        Wo,
        "middle finger channel value adjustment",
    ),
    var(
        obj::TACTILE_CONFIG,
        10,
        "ring_acq_param_update",
        Uint8,
        8,
        Wo,
        "ring finger channel value adjustment",
    ),
    var(
        obj::TACTILE_CONFIG,
        11,
        "prink_acq_param_update",
        Uint8,
        8,
        Wo,
        "little finger channel value adjustment",
    ),
    var(
        obj::TACTILE_CONFIG,
        12,
        "reserved1",
        Uint8,
        8,
        Ro,
        "reserved",
    ),
    var(
        obj::TACTILE_CONFIG,
        13,
        "thumb_touch_fw_version",
        VisibleString,
        160,
        Ro,
        "thumb tactile firmware version",
    ),
    var(
        obj::TACTILE_CONFIG,
        14,
        "index_touch_fw_version",
        VisibleString,
        160,
        Ro,
        "index finger tactile firmware version",
    ),
    var(
        obj::TACTILE_CONFIG,
        15,
        "mid_touch_fw_version",
        VisibleString,
        160,
        Ro,
        "middle finger tactile firmware version",
    ),
    var(
        obj::TACTILE_CONFIG,
        16,
        "ring_touch_fw_version",
        VisibleString,
        160,
        Ro,
        "ring finger tactile firmware version",
    ),
    var(
        obj::TACTILE_CONFIG,
        17,
        "pink_touch_fw_version",
        VisibleString,
        160,
        Ro,
        "pinky tactile firmware version",
    ),
];

/// The dictionary entry `index:sub`, if any.
pub fn entry(index: u16, sub: u8) -> Option<&'static Entry> {
    DICTIONARY.iter().find(|e| e.index == index && e.sub == sub)
}

/// All entries of object `index`, in sub-index order.
pub fn object_entries(index: u16) -> impl Iterator<Item = &'static Entry> {
    DICTIONARY.iter().filter(move |e| e.index == index)
}

/// Whether `index` is one of the configuration objects (0x8000, 0x8010).
pub const fn is_config_object(index: u16) -> bool {
    index == obj::CONFIG || index == obj::TACTILE_CONFIG
}

/// The configuration entry (0x8000 or 0x8010, sub-index >= 1) named `name`
/// (the document's parameter name, case-sensitive).
pub fn config_entry(name: &str) -> Option<&'static Entry> {
    config_entries().find(|e| e.name == name)
}

/// All configuration entries (0x8000 and 0x8010, without sub-index 0).
pub fn config_entries() -> impl Iterator<Item = &'static Entry> {
    DICTIONARY
        .iter()
        .filter(|e| is_config_object(e.index) && e.sub != 0)
}
