//! The simulated EH55BF1 exoskeleton glove, for running the pipeline without hardware.
//!
//! It speaks the real wire protocol (the `teleop-glove-protocol` codecs) on a pseudo-terminal,
//! but implements the device's behaviour on its own: it answers only its id, keeps a register
//! file with the documented permissions (writes to read-only registers are refused), applies
//! ID and baud changes after the acknowledge, paces every byte at 10 bit times of the current
//! baud rate, and moves a simulated operator hand that the actuators push on (measured forces,
//! currents and temperatures follow the load; sustained overload sets error bits). Faults
//! (garbage, dropped answers, corrupted checksums, answers from another id, late answers,
//! unplug/replug) are selectable at start and at run time.
//!
//! - [`hand`]: the operator's hand and the actuators (pure);
//! - [`device`]: the firmware's behaviour on the wire (pure);
//! - [`serve`]: the line timing and faults on the simulator kit's pty;
//! - [`control`]: the control socket's commands (the kit's vocabulary and the glove's own).
//!
//! Must not depend on: the glove node (a driver bug must not hide behind shared driver code).

pub mod control;
pub mod device;
pub mod hand;
pub mod serve;

pub use serve::{AnswerTiming, DeviceView, Faults, ForceTiming, SimGlove, SimOptions, SimStats};
