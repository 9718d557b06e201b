//! Finding the servos and bringing them up: ping every ID and check its Model Number, then the
//! shipped API's steps (docs/devices/leap.md, "Bring-up") in an order safe whatever state an
//! earlier session left the servos in, step by step over all servos, each checked by its status:
//! torque off; the EEPROM items, which a servo refuses under torque (docs/devices/leap.md,
//! "Status packets and the error byte"): Operating Mode 5 (current-based position), Drive Mode
//! 0 (bit 0 would reverse the direction), Return Delay Time and Homing Offset 0, written only
//! where they differ; the position gains; Profile Acceleration and Velocity 0 (no profile: the
//! node ramps), where they differ; Goal Current; Goal Position = Present Position (no jump; the
//! state read there is where the hand is); torque on last, and only when no servo refused a
//! step (a refusal names the servo and the item). A setting another tool left that differs from
//! what the node relies on is logged when it is written back.
//!
//! The same steps bring one servo back (one rebooted after a hardware error); a servo back from
//! silence that still has its torque on in mode 5 only has its goal set where it is (no limp
//! moment). Every exchange goes through [`Bus`].

use teleop_hand_node::ConnectError;
use teleop_leap_protocol::packet::ErrorByte;
use teleop_leap_protocol::xc330::{self, State};

use crate::bus::{Bus, BusError, Line, Reply};
use crate::config::{Settings, SERVOS};
use crate::servos::{bit, Mask};

/// How often an exchange of the bring-up is tried before it counts as failed (a reply lost to
/// noise is asked again).
pub const ATTEMPTS: u32 = 3;

/// Current-based position control (ROBOTIS e-manual, XC330 control table, Operating Mode).
pub const CURRENT_BASED_POSITION: u8 = 5;

/// What the servos told when they were found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Identity {
    /// Model Number per joint (0: did not answer).
    pub models: [u16; SERVOS],
    /// Firmware Version per joint.
    pub firmware: [u8; SERVOS],
    /// Joints whose servo did not answer.
    pub silent: Mask,
}

/// A servo's name for messages: `ring_dip (id 11)`.
pub struct Names<'a> {
    /// Joint names, in joint order.
    pub joints: &'a [String],
    /// IDs, in joint order.
    pub ids: &'a [u8; SERVOS],
}

impl Names<'_> {
    /// Joint `j`'s servo.
    pub fn of(&self, j: usize) -> String {
        let name = self.joints.get(j).map_or("?", String::as_str);
        format!("{name} (id {})", self.ids[j])
    }
}

/// Why one servo's bring-up failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepError {
    /// No usable reply after [`ATTEMPTS`].
    NoReply(BusError),
    /// The line failed.
    Io(BusError),
    /// The servo refused (an error number), naming the item.
    Refused(ErrorByte),
    /// The servo reports a hardware error (Alert): it keeps its torque off until rebooted.
    Alert,
}

/// Pings every servo and checks its Model Number: `WrongDevice` naming the ID and model when
/// one is another servo; `Lost` when none answers (or the line fails). Silent servos are
/// returned, not an error: the hand comes up without them and looks for them again.
pub fn find<L: Line>(
    bus: &mut Bus<L>,
    settings: &Settings,
    names: &Names<'_>,
) -> Result<Identity, ConnectError> {
    let mut identity = Identity {
        models: [0; SERVOS],
        firmware: [0; SERVOS],
        silent: 0,
    };
    for (j, &id) in settings.ids.iter().enumerate() {
        match ping(bus, id) {
            Ok((model, firmware)) => {
                if model != settings.model {
                    return Err(ConnectError::WrongDevice(format!(
                        "{} is a {} (model {model}); expected a {} (model {}) (set `model` for \
                         a Lite hand's XL330-M077)",
                        names.of(j),
                        model_text(model),
                        model_text(settings.model),
                        settings.model
                    )));
                }
                identity.models[j] = model;
                identity.firmware[j] = firmware;
            }
            Err(BusError::Io(kind)) => {
                return Err(ConnectError::Lost(format!(
                    "{}: {}",
                    settings.port,
                    std::io::Error::from(kind)
                )))
            }
            Err(_) => identity.silent |= bit(j),
        }
    }
    if identity.silent == Mask::MAX >> (Mask::BITS as usize - SERVOS) {
        return Err(ConnectError::Lost(format!(
            "no servo answers on {} at {} bit/s (IDs {:?}): is the hand powered, and are its \
             servos at this baud rate?",
            settings.port, settings.baud, settings.ids
        )));
    }
    Ok(identity)
}

/// A model's name, or its number.
pub fn model_text(model: u16) -> String {
    xc330::model_name(model).map_or_else(|| format!("model {model}"), str::to_string)
}

/// Pings `id`, asking again after a lost or corrupt reply.
pub fn ping<L: Line>(bus: &mut Bus<L>, id: u8) -> Result<(u16, u8), BusError> {
    retry(|| bus.ping(id))
}

/// Tries `f` up to [`ATTEMPTS`] times while it times out or the reply is corrupt.
fn retry<T>(mut f: impl FnMut() -> Result<T, BusError>) -> Result<T, BusError> {
    let mut last = BusError::Timeout;
    for _ in 0..ATTEMPTS {
        match f() {
            Ok(v) => return Ok(v),
            Err(e @ BusError::Io(_)) | Err(e @ BusError::Encode(_)) => return Err(e),
            Err(e) => last = e,
        }
    }
    Err(last)
}

/// One step of the bring-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    TorqueOff,
    Eeprom,
    Gains,
    Profiles,
    GoalCurrent,
    GoalAtPresent,
    TorqueOn,
}

const STEPS: [Step; 7] = [
    Step::TorqueOff,
    Step::Eeprom,
    Step::Gains,
    Step::Profiles,
    Step::GoalCurrent,
    Step::GoalAtPresent,
    Step::TorqueOn,
];

/// A servo's failed step: the item, and why.
pub type Failure = (&'static str, StepError);

/// Brings up the servos of `joints` step by step (each step on every servo before the next);
/// their state at the goal step (Present Position: the goal they hold) goes into `states`. A
/// servo that fails is left out of the later steps and returned with why, in joint order; the
/// others come up, but none has its torque turned on when one refused a step (the node does not
/// run with a setting refused).
pub fn bring_up<L: Line>(
    bus: &mut Bus<L>,
    settings: &Settings,
    joints: Mask,
    states: &mut [Option<State>; SERVOS],
    failed: &mut [Option<Failure>; SERVOS],
) {
    let mut going = joints;
    for step in STEPS {
        if step == Step::TorqueOn
            && failed
                .iter()
                .flatten()
                .any(|(_, e)| matches!(e, StepError::Refused(_)))
        {
            return;
        }
        for j in 0..SERVOS {
            if going & bit(j) == 0 {
                continue;
            }
            if let Err(e) = run_step(bus, settings, j, step, states) {
                going &= !bit(j);
                failed[j] = Some(e);
                if matches!(e.1, StepError::Io(_)) {
                    // The line is gone: no other servo will answer either.
                    for (k, f) in failed.iter_mut().enumerate() {
                        if going & bit(k) != 0 {
                            *f = Some(e);
                        }
                    }
                    return;
                }
            }
        }
    }
}

/// Brings joint `j`'s servo back into the loop (it answers again, or its hardware error was
/// cleared): with its torque still on in mode 5 (it held through a lost reply or a cable
/// glitch) only its goal is set where it is; otherwise every step of [`bring_up`]. Its state
/// at the goal step (where it holds).
pub fn bring_up_again<L: Line>(
    bus: &mut Bus<L>,
    settings: &Settings,
    j: usize,
) -> Result<State, Failure> {
    let id = settings.ids[j];
    let mut states = [None; SERVOS];
    let what = "Operating Mode (read)";
    let mode = exchange(|| bus.read(id, xc330::OPERATING_MODE, 1), what)?;
    let what = "Torque Enable (read)";
    let torque = exchange(|| bus.read(id, xc330::TORQUE_ENABLE, 1), what)?;
    if mode.data() == [CURRENT_BASED_POSITION] && torque.data() == [1] {
        run_step(bus, settings, j, Step::GoalAtPresent, &mut states)?;
    } else {
        let mut failed = [None; SERVOS];
        bring_up(bus, settings, bit(j), &mut states, &mut failed);
        if let Some(f) = failed[j] {
            return Err(f);
        }
    }
    states[j].ok_or((
        "Present Position (read)",
        StepError::NoReply(BusError::Timeout),
    ))
}

/// One step on joint `j`'s servo; on failure the item and why.
fn run_step<L: Line>(
    bus: &mut Bus<L>,
    settings: &Settings,
    j: usize,
    step: Step,
    states: &mut [Option<State>; SERVOS],
) -> Result<(), Failure> {
    let id = settings.ids[j];
    match step {
        Step::TorqueOff => write(bus, id, xc330::TORQUE_ENABLE, &[0], "Torque Enable (off)"),
        Step::Eeprom => {
            // Return Delay Time (9), Drive Mode (10), Operating Mode (11), Homing Offset (20):
            // written only where they differ, sparing the EEPROM.
            let what = "Return Delay Time, Drive Mode and Operating Mode (read)";
            let reply = exchange(|| bus.read(id, xc330::RETURN_DELAY_TIME, 3), what)?;
            let (delay, drive, mode) = match reply.data() {
                [delay, drive, mode] => (*delay, *drive, *mode),
                _ => return Err((what, StepError::NoReply(BusError::Timeout))),
            };
            if mode != CURRENT_BASED_POSITION {
                write(
                    bus,
                    id,
                    xc330::OPERATING_MODE,
                    &[CURRENT_BASED_POSITION],
                    "Operating Mode (5, current-based position)",
                )?;
            }
            if drive != 0 {
                // Bit 0 reverses the direction, bit 2 makes the profile time-based (ROBOTIS
                // e-manual, XC330 control table, Drive Mode).
                tracing::warn!("servo id {id}: Drive Mode was {drive} (another tool's): set to 0");
                write(bus, id, xc330::DRIVE_MODE, &[0], "Drive Mode (0)")?;
            }
            if delay != settings.return_delay {
                write(
                    bus,
                    id,
                    xc330::RETURN_DELAY_TIME,
                    &[settings.return_delay],
                    "Return Delay Time",
                )?;
            }
            let what = "Homing Offset (read)";
            let reply = exchange(|| bus.read(id, xc330::HOMING_OFFSET, 4), what)?;
            let offset = match reply.data() {
                [a, b, c, d] => i32::from_le_bytes([*a, *b, *c, *d]),
                _ => return Err((what, StepError::NoReply(BusError::Timeout))),
            };
            if offset != 0 {
                // Present Position = actual + offset: the profile's zero would move.
                tracing::warn!(
                    "servo id {id}: Homing Offset was {offset} (another tool's): set to 0"
                );
                write(bus, id, xc330::HOMING_OFFSET, &[0; 4], "Homing Offset (0)")?;
            }
            Ok(())
        }
        Step::Profiles => {
            // Profile Acceleration (108) and Velocity (112): 0, no profile between the goals
            // the node writes (it ramps them itself).
            let what = "Profile Acceleration and Velocity (read)";
            let reply = exchange(|| bus.read(id, xc330::PROFILE_ACCELERATION, 8), what)?;
            if reply.data().len() != 8 {
                return Err((what, StepError::NoReply(BusError::Timeout)));
            }
            if reply.data() != [0; 8] {
                tracing::warn!(
                    "servo id {id}: Profile Acceleration/Velocity were {:?} (another tool's): \
                     set to 0",
                    reply.data()
                );
                write(
                    bus,
                    id,
                    xc330::PROFILE_ACCELERATION,
                    &[0; 8],
                    "Profile Acceleration and Velocity (0)",
                )?;
            }
            Ok(())
        }
        Step::Gains => {
            // Position D (80), I (82), P (84): one write of the three.
            let [p, i, d] = settings.gains[j];
            let mut data = [0u8; 6];
            data[..2].copy_from_slice(&d.to_le_bytes());
            data[2..4].copy_from_slice(&i.to_le_bytes());
            data[4..].copy_from_slice(&p.to_le_bytes());
            write(
                bus,
                id,
                xc330::POSITION_D_GAIN,
                &data,
                "Position D/I/P Gain",
            )
        }
        Step::GoalCurrent => write(
            bus,
            id,
            xc330::GOAL_CURRENT,
            &settings.current_limit_ma.to_le_bytes(),
            "Goal Current",
        ),
        Step::GoalAtPresent => {
            // Current, velocity and position: where the hand is, published before any command.
            let what = "Present Current, Velocity and Position (read)";
            let reply = exchange(|| bus.read(id, xc330::STATE_ADDR, xc330::STATE_LEN), what)?;
            let state = State::decode(reply.data())
                .map_err(|_| (what, StepError::NoReply(BusError::Timeout)))?;
            write(
                bus,
                id,
                xc330::GOAL_POSITION,
                &state.position.to_le_bytes(),
                "Goal Position",
            )?;
            states[j] = Some(state);
            Ok(())
        }
        Step::TorqueOn => write(bus, id, xc330::TORQUE_ENABLE, &[1], "Torque Enable (on)"),
    }
}

/// Writes `data` at `addr` of `id`, checked by its status.
fn write<L: Line>(
    bus: &mut Bus<L>,
    id: u8,
    addr: u16,
    data: &[u8],
    what: &'static str,
) -> Result<(), Failure> {
    exchange(|| bus.write(id, addr, data), what).map(|_| ())
}

/// One checked exchange: its reply, or why not (the item named).
fn exchange(
    f: impl FnMut() -> Result<Reply, BusError>,
    what: &'static str,
) -> Result<Reply, Failure> {
    let reply = retry(f).map_err(|e| match e {
        BusError::Io(_) => (what, StepError::Io(e)),
        e => (what, StepError::NoReply(e)),
    })?;
    if reply.error.number().is_some() {
        return Err((what, StepError::Refused(reply.error)));
    }
    if reply.error.alert() {
        return Err((what, StepError::Alert));
    }
    Ok(reply)
}

/// A failed step in words: `ring_dip (id 11): Operating Mode (5, ...) refused: Access Error`.
pub fn describe(name: &str, what: &str, e: &StepError) -> String {
    match e {
        StepError::NoReply(b) => format!("{name}: {what}: {b}"),
        StepError::Io(b) => format!("{name}: {what}: {b}"),
        StepError::Refused(err) => format!("{name}: {what} refused: {err}"),
        StepError::Alert => format!("{name}: {what}: the servo reports a hardware error"),
    }
}

/// A servo's Hardware Error Status in words: `overload, overheating`.
pub fn hardware_error_text(status: u8) -> String {
    xc330::HardwareError(status).to_string()
}
