//! EtherCAT object dictionary and process data of the BrainCo Revo2
//! dexterous hand ("BrainCo-Revo2Slave", CoE SDO, PDO, FoE).
//!
//! "Section N" is the device document's, restated by number in docs/devices/revo2.md.
//!
//! # What this crate owns
//!
//! * Identity and orders (section 1, 2.2): [`VENDOR_ID`], [`PRODUCT_CODE`],
//!   [`REVISION`], [`Joint`] / [`JOINT_NAMES`] (`finger_index_t`),
//!   [`FINGERTIP_NAMES`] (tactile arrays).
//! * The object dictionary as typed static entries ([`DICTIONARY`],
//!   [`entry`], [`Entry`], [`DataType`] with CoE codes), the PDO mappings
//!   ([`mapping_entries`], [`MappingEntry`]) and assignments
//!   ([`DEFAULT_RX_ASSIGNMENT`], [`DEFAULT_TX_ASSIGNMENT`], [`image_len`]).
//! * The process images ([`Outputs`], [`JointData`], [`TactileData`],
//!   [`Inputs`]): little-endian, tightly packed in mapping order, packed
//!   and unpacked without heap; the decoders are total (any bytes give a
//!   value or an [`ImageError`], never a panic).
//! * Control modes and units (section 5): [`ControlMode`], [`UnitMode`],
//!   [`multi_command`] / [`single_command`] (convert and range-check),
//!   [`param_limits`], percent/physical conversions, [`JointRange`].
//! * Tactile units (section 2.4): [`newtons`], [`direction`],
//!   [`TouchStatus`].
//! * Configuration 0x8000 / 0x8010 (sections 3, 4): [`parse_config_value`],
//!   [`decode_config_value`], [`ConfigValue`].
//! * FoE firmware files (section 6): [`Board`], [`FirmwareHeader`],
//!   [`check_file_name`], [`check_firmware`].
//!
//! It is pure: no I/O, no clock, no threads; the cyclic-path code (images,
//! commands, tactile units) does not allocate. Configuration values and
//! firmware errors may allocate (they are off the cyclic path).
//!
//! # What it must not depend on
//!
//! No EtherCAT master (no ethercrab), no iceoryx2, no message/IPC crate
//! (`teleop-msgs`), no runtime crate, no logging. Talking to the hand
//! (SDO, FoE, the cyclic exchange) is the driver's job, and answering like
//! the hand is the simulator's; both use this crate for the bytes.
//!
//! # Process data
//!
//! ```text
//! RxPDO 0x1600 (31 bytes): mode u8 | param1 6 x i16 | param2 6 x u16     (0x7000)
//!                          mode u8 | joint u8 | param1 i16 | param2 u16  (0x7010)
//! TxPDO 0x1A00 (48 bytes): position 6 x u16 | speed 6 x i16 | current 6 x i16 | status 6 x u16
//! TxPDO 0x1A01 (60 bytes): normal 5 x u16 | tangential 5 x u16 | direction 5 x u16
//!                          | proximity 5 x u32 | touch_status 5 x u16
//! ```
//!
//! ```
//! use teleop_revo2_protocol::{
//!     multi_command, ControlMode, Inputs, Outputs, UnitMode, DEFAULT_TX_ASSIGNMENT, RX_LEN,
//! };
//!
//! let multi = multi_command(
//!     ControlMode::PositionTime,
//!     [500.0; 6],
//!     [200.0; 6],
//!     UnitMode::Percent,
//! )?;
//! let mut out = [0u8; RX_LEN];
//! Outputs { multi, ..Outputs::default() }.pack(&mut out)?;
//! assert_eq!(out[..3], [1, 0xF4, 0x01]); // mode 1, param1[0] = 500
//!
//! let inputs = Inputs::unpack(&[0u8; 108], &DEFAULT_TX_ASSIGNMENT)?;
//! assert!(inputs.tactile.is_some());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Ambiguities of the document, and what we chose
//!
//! 1. **Tactile TxPDO index**: the document does not give the PDO that maps
//!    0x6010. We use 0x1A01, the next free TxPDO ([`obj::TACTILE_TX_PDO`]),
//!    mapping 0x6010:01..05 in order.
//! 2. **SM3 assignment**: section 2.1 lists only 0x1A00, while 2.4 says the
//!    tactile data is "directly mapped" too. 0x1C13 defaults to
//!    `[0x1A00, 0x1A01]` ([`DEFAULT_TX_ASSIGNMENT`]) and is writable;
//!    [`Inputs::unpack`] takes the assignment as a parameter, so a master
//!    that reads 0x1C13 back (as ethercrab does) handles both readings.
//! 3. **Tactile array order**: 0x8010 orders its per-finger entries thumb,
//!    index, middle, ring, pinky; 0x6010's arrays are assumed the same.
//! 4. **Tangential force and direction signedness**: the table says UINT16,
//!    the bullet list INT16, the text "16-bit unsigned" (and 0xFFFF =
//!    invalid only makes sense unsigned). Decoded as `u16`.
//! 5. **Direction values 360..=0xFFFE** are undocumented; [`direction`]
//!    treats them as invalid like 0xFFFF.
//! 6. **Touch status validity**: [`TouchStatus::is_valid`] is "none of bits
//!    0..=2 set" ("not updated" counts as not valid); bits 3..=7 ignored.
//! 7. **Joint status word** (0x6000:04): no bit meanings are given; it stays
//!    a raw `u16`.
//! 8. **Mode 0**: only modes 1..=5 are defined; 0 ([`MODE_NONE`]) is used
//!    as "no command" (the all-zero image). What the hand does with it is
//!    not documented.
//! 9. **Multi and single command in one cycle**: precedence undocumented;
//!    the builders and [`Outputs::default`] leave the other mode at 0.
//! 10. **Physical-mode resolution**: units (°, °/s, mA) are given, scales
//!     are not. 1 raw = 1 unit is assumed ([`POSITION_RAW_PER_DEG`],
//!     [`SPEED_RAW_PER_DEG_S`], [`CURRENT_RAW_PER_MA`]) and configurable
//!     through [`PhysicalScale`] ([`multi_command_scaled`]).
//! 11. **Position range**: targets are non-negative (positions read back
//!     in 0x6000:01 are UINT16): 0..=1000 in percent mode, 0..=32767 raw in
//!     physical mode. Joint angular ranges are not given; [`JointRange`]
//!     with [`DEFAULT_JOINT_RANGES`] (0..90° each) is an assumption.
//! 12. **Position direction**: percent 0 is taken as open/straight and 1000
//!     as fully bent (section 5: positive is the bending direction).
//! 13. **Unused param2** (speed, current, PWM): written as 0, the caller's
//!     second value is ignored. Position + speed's param2 is UINT16, so it
//!     is a speed magnitude (0..=1000 in percent mode).
//! 14. **Current**: percent mode is per-mille of 1000 mA, so 1 unit = 1 mA
//!     in both modes; physical currents are limited to ±1000 mA.
//! 15. **Firmware header version**: "0x00010203" with "highest byte
//!     reserved" is read as a little-endian `u32` (file bytes `03 02 01
//!     00`); [`VersionByteOrder`] makes this a parameter.
//! 16. **0x8010 sub-indices** are written in decimal (1..=17: 10 = 0x0A),
//!     unlike 0x8000's hex; read as decimal since they are consecutive.
//! 17. **Names**: configuration names keep the document's spelling
//!     (`thumb_aux_pro_cur`, `pink_pro_cur`, `prink_acq_param_update`,
//!     ...); 0x8000:09 is `turbo_param`, set as `a,b`; the output objects
//!     use the names of section 5.4 (`mult_finger_ctrl_mode`, ...).
//! 18. **Defaults**: the document gives none for sections 2 to 4. 0x1000
//!     is assumed 0x00001389 (modular device profile, what the slave stack
//!     code generates for this 0x6000/0x7000/0x8000 layout); 0x1009/0x100A
//!     are assumed 20-character strings with unknown content.
//! 19. **String downloads**: whether a string shorter than its object may
//!     be written is not said. [`ConfigValue::to_bytes`] gives the bare
//!     bytes, [`ConfigValue::to_bytes_padded`] NUL-pads to the declared
//!     size. Neither fits an expedited SDO: the master needs a normal
//!     (segmented) download.
//! 20. **String uploads** are C strings: cut at the first NUL, trailing
//!     spaces trimmed, any length accepted ([`decode_config_value`]).
//! 21. **Firmware file names**: `x` is 1..=3 digits (a header byte);
//!     `$time` is 10 digits (the example `2506231346`) or 12; the name is
//!     case-sensitive (section 6.3).
//! 22. **FoE file type**: 1 = wrist board, 2 = control board (3.3 and 6.2
//!     agree); the auth code is the board's magic number.
//! 23. **FoE payload**: the whole file, header included, is sent; the
//!     device checks and strips the header (section 6.5).
//! 24. **Configuration value ranges**: documented enumerations are enforced
//!     (`hand_type` and `unit_mode` 0/1, `foe_file_type` 1/2); switches and
//!     calibration triggers have no documented values and accept any byte.
//! 25. **PDO mapping** is fixed (0x1600/0x1A00/0x1A01 read-only); only the
//!     assignments 0x1C12/0x1C13 are writable.
//! 26. **Force unit** "100 * N" with the example 1000 = 10 N: raw is
//!     0.01 N ([`NEWTONS_PER_RAW`]). Proximity has no unit and stays raw.

mod config;
mod control;
mod dictionary;
mod firmware;
mod identity;
mod image;
mod tactile;

pub use config::{
    decode_config_value, parse_config_value, ConfigError, ConfigValue, EXPEDITED_MAX,
};
pub use control::{
    current_ma_to_percent, current_percent_to_ma, multi_command, multi_command_scaled,
    normalised_to_percent, param_limits, percent_to_normalised, single_command,
    single_command_scaled, CommandError, ControlMode, JointRange, ParamLimits, PhysicalScale,
    UnitMode, CURRENT_RAW_PER_MA, DEFAULT_JOINT_RANGES, MAX_CURRENT_MA, MODE_NONE, PERCENT_FULL,
    POSITION_RAW_PER_DEG, SPEED_RAW_PER_DEG_S,
};
pub use dictionary::{
    config_entries, config_entry, entry, image_len, is_config_object, mapping_bits,
    mapping_entries, obj, object_entries, Access, DataType, DefaultValue, Entry, MappingEntry,
    PdoDirection, DEFAULT_RX_ASSIGNMENT, DEFAULT_TX_ASSIGNMENT, DICTIONARY,
    JOINT_ONLY_TX_ASSIGNMENT, JOINT_TX_MAPPING, RX_MAPPING, TACTILE_TX_MAPPING,
};
pub use firmware::{
    check_file_name, check_firmware, parse_file_name, Board, FirmwareError, FirmwareHeader,
    Version, VersionByteOrder, FOE_AUTH_CODE, FOE_FILE_TYPE, HEADER_LEN,
};
pub use identity::{
    Joint, DEVICE_NAME, FINGERTIPS, FINGERTIP_NAMES, JOINTS, JOINT_NAMES, PRODUCT_CODE, REVISION,
    VENDOR_ID, VENDOR_NAME,
};
pub use image::{
    ImageError, Inputs, JointData, MultiFingerCommand, Outputs, SingleFingerCommand, TactileData,
    JOINT_TX_LEN, RX_LEN, TACTILE_TX_LEN,
};
pub use tactile::{
    direction, newtons, TouchStatus, DIRECTION_INVALID, DIRECTION_MAX_DEG, MAX_FORCE_N,
    NEWTONS_PER_RAW,
};
