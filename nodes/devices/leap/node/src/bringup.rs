//! Finding the servos and bringing them up: ping every ID and check its Model Number, then the
//! shipped API's steps (docs/devices/leap.md, "Bring-up") in an order safe whatever state an
//! earlier session left the servos in, step by step over all servos, each checked by its status:
//! torque off; the EEPROM items, which a servo refuses under torque (docs/devices/leap.md,
//! "Status packets and the error byte"): Operating Mode 5 (current-based position) and Return
//! Delay Time, written only where they differ; the position gains; Goal Current; Goal Position =
//! Present Position (no jump); torque on last. A refusal names the servo and the item.
//!
//! The same steps bring one servo back (a silent one that answers again, one rebooted after a
//! hardware error). Every exchange goes through [`Bus`].

use teleop_hand_node::ConnectError;
use teleop_leap_protocol::packet::ErrorByte;
use teleop_leap_protocol::xc330;

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
    GoalCurrent,
    GoalAtPresent,
    TorqueOn,
}

const STEPS: [Step; 6] = [
    Step::TorqueOff,
    Step::Eeprom,
    Step::Gains,
    Step::GoalCurrent,
    Step::GoalAtPresent,
    Step::TorqueOn,
];

/// Brings up the servos of `joints` step by step (each step on every servo before the next);
/// their Present Positions (the goals they hold) go into `goals`. A servo that fails is left
/// out of the later steps and returned with why, in joint order; the others come up.
pub fn bring_up<L: Line>(
    bus: &mut Bus<L>,
    settings: &Settings,
    joints: Mask,
    goals: &mut [i32; SERVOS],
    failed: &mut [Option<(&'static str, StepError)>; SERVOS],
) {
    let mut going = joints;
    for step in STEPS {
        for j in 0..SERVOS {
            if going & bit(j) == 0 {
                continue;
            }
            if let Err(e) = run_step(bus, settings, j, step, goals) {
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

/// One step on joint `j`'s servo; on failure the item and why.
fn run_step<L: Line>(
    bus: &mut Bus<L>,
    settings: &Settings,
    j: usize,
    step: Step,
    goals: &mut [i32; SERVOS],
) -> Result<(), (&'static str, StepError)> {
    let id = settings.ids[j];
    match step {
        Step::TorqueOff => write(bus, id, xc330::TORQUE_ENABLE, &[0], "Torque Enable (off)"),
        Step::Eeprom => {
            // Return Delay Time (9), Drive Mode (10), Operating Mode (11): written only where
            // they differ, sparing the EEPROM.
            let what = "Return Delay Time and Operating Mode (read)";
            let reply = exchange(|| bus.read(id, xc330::RETURN_DELAY_TIME, 3), what)?;
            let (delay, mode) = match reply.data() {
                [delay, _, mode] => (*delay, *mode),
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
            if delay != settings.return_delay {
                write(
                    bus,
                    id,
                    xc330::RETURN_DELAY_TIME,
                    &[settings.return_delay],
                    "Return Delay Time",
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
            let what = "Present Position (read)";
            let reply = exchange(|| bus.read(id, xc330::PRESENT_POSITION, 4), what)?;
            let present = match reply.data() {
                [a, b, c, d] => i32::from_le_bytes([*a, *b, *c, *d]),
                _ => return Err((what, StepError::NoReply(BusError::Timeout))),
            };
            write(
                bus,
                id,
                xc330::GOAL_POSITION,
                &present.to_le_bytes(),
                "Goal Position",
            )?;
            goals[j] = present;
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
) -> Result<(), (&'static str, StepError)> {
    exchange(|| bus.write(id, addr, data), what).map(|_| ())
}

/// One checked exchange: its reply, or why not (the item named).
fn exchange(
    f: impl FnMut() -> Result<Reply, BusError>,
    what: &'static str,
) -> Result<Reply, (&'static str, StepError)> {
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
