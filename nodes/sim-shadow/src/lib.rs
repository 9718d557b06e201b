//! The emulated Shadow Hand E, built up from its parts. So far: [`bootloader`], a motor board's
//! PIC18F CAN bootloader (flash memory, EEPROM, the document's commands and the shipped
//! bootloader's behaviour), which `teleop shadow flash` is tested against. The palm (two
//! EtherCAT SubDevices on `teleop-ecat-sim`), the motor boards' application and the hand behind
//! them, and the `teleop-sim-shadow` executable are still to come (issue 14).
//!
//! It shares the codecs of `teleop-shadow-protocol` and nothing of the driver side.
//!
//! Must not depend on: the Shadow node or the flasher's logic.

pub mod bootloader;
