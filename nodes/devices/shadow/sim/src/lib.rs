//! The emulated Shadow Hand E, for running the pipeline without hardware:
//! - [`ethercat`]: the hand on an EtherCAT bus as two SubDevices of `teleop-ecat-sim` (the
//!   bridge, then the palm) whose SII announces no sync managers, so the MainDevice must program
//!   them; the palm's firmware behind its one-buffer sync managers;
//! - [`palm`]: the palm's PIC32 firmware one cycle at a time (boot status, even/odd motor
//!   replies with arrival and error masks, demands, idle time, PST tactile, CAN direct mode
//!   bridging to the boards) over 20 motor boards, each its bootloader and a first-order torque
//!   loop with temperature and flags;
//! - [`bootloader`]: a motor board's PIC18F CAN bootloader (flash memory, EEPROM, the
//!   document's commands and the shipped bootloader's behaviour);
//! - [`hand`]: the 24 joints the motors move (J1/J2 coupled), their ADCs, a virtual ball and
//!   the fingertip pressure it causes;
//! - [`control`]: its control socket's commands on the simulator kit (`teleop-sim-kit`).
//!
//! It shares the codecs of `teleop-shadow-protocol` and nothing of the driver side.
//!
//! Must not depend on: the Shadow node, ethercrab, or the flasher's logic (a driver bug must not
//! hide behind shared code).

pub mod bootloader;
pub mod control;
pub mod ethercat;
pub mod hand;
pub mod palm;
