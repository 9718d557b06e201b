//! The emulated Shadow Hand E, built up from its parts. So far:
//! - [`bootloader`]: a motor board's PIC18F CAN bootloader (flash memory, EEPROM, the
//!   document's commands and the shipped bootloader's behaviour), which the flasher is tested
//!   against;
//! - [`palm`]: the palm's PIC32 firmware one cycle at a time (boot status, even/odd motor
//!   replies with arrival and error masks, demands, idle time, CAN direct mode bridging to the
//!   boards) over 20 motor boards, each its bootloader and a first-order torque loop with
//!   temperature and flags.
//!
//! Still to come (issue 14): the palm and the bridge as two EtherCAT SubDevices on
//! `teleop-ecat-sim` (SII without sync managers, one-buffer sync managers), the 24 joints and
//! the virtual object behind the motors, PST fingertips, and the `teleop-sim-shadow` executable.
//!
//! It shares the codecs of `teleop-shadow-protocol` and nothing of the driver side.
//!
//! Must not depend on: the Shadow node or the flasher's logic.

pub mod bootloader;
pub mod palm;
