//! The simulated operator's hand inside the glove: scripted finger motion, the five actuators
//! pushing on the fingers, and the measured forces, currents, temperatures and error bits that
//! follow from the load.
//!
//! Units are the glove's: positions 0 (bent) .. 1000 (open), forces -1000..1000 (a positive
//! command pushes the hand open; a positive measured force means the finger pushes towards a
//! fist), currents in mA, temperatures in degrees Celsius. Pure: time comes in as seconds, on
//! the simulator kit's plant clock.
//!
//! Each channel is one of the operator's fingers: a mass, damper and spring in the range
//! measured for human fingertips, pulled by the operator's muscles toward where the script
//! means it to be, pushed by its actuator, stiffening while the operator squeezes
//! ([`HandModel`]), so that force feedback moves it and a badly timed push can make it ring.
//! Inside, travel is in metres and force in newtons ([`METRES_PER_RAW`],
//! [`NEWTONS_PER_FORCE`]). The thumb's rotation moves the same way, pushed by nothing. What the
//! glove measures is the force between finger and actuator: under force control the cable's
//! pull, i.e. the command; under position control what the stiff servo needs to hold the
//! finger against the operator.

use std::path::Path;

use teleop_sim_kit::plant::{lag, Clock, Joint};

/// Longest integration step, s. Semi-implicit Euler (the kit's [`Joint`], the damper taken at
/// the step's mean velocity) is stable while `omega * h < 2`; the stiffest default finger
/// (1500 N/m, 6 g: omega = 500 rad/s) has `omega * h = 0.125`, and its frequency and damping
/// ratio then come out within 0.2 % of the continuous system's (the unit tests measure them to
/// 1 %).
const STEP_S: f64 = 0.000_25;

/// Channels: little, ring, middle, index, thumb, thumb rotation.
pub const CHANNELS: usize = 6;
/// Actuated fingers: little, ring, middle, index, thumb.
pub const FINGERS: usize = 5;

/// What the operator does.
#[derive(Debug, Clone, PartialEq)]
pub enum Script {
    /// Hold these raw positions.
    Hold([f32; CHANNELS]),
    /// Open and close the whole hand with this period in seconds.
    OpenClose {
        /// Seconds per open-close cycle.
        period_s: f32,
    },
    /// The thumb pinches one finger and releases, the other fingers relaxed open: a quarter of
    /// the period closing, three eighths holding the pinch, a quarter opening, an eighth open.
    Pinch {
        /// The finger the thumb meets.
        finger: PinchFinger,
        /// Seconds per pinch cycle.
        period_s: f32,
    },
    /// Reach for an object with an open hand, close around it and squeeze, hold, release.
    Grasp {
        /// Seconds per grasp cycle.
        period_s: f32,
    },
    /// A slow free motion: each channel swings smoothly over most of its range at its own
    /// frequency, the six frequencies incommensurate so that the pose never repeats; no pinch
    /// is intended.
    Free,
    /// Linear interpolation through `(t_s, positions)` points, looped.
    Trajectory(Vec<(f32, [f32; CHANNELS])>),
}

/// The long finger a [`Script::Pinch`] brings the thumb to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PinchFinger {
    /// Thumb to index.
    Index,
    /// Thumb to middle.
    Middle,
    /// Thumb to ring.
    Ring,
}

impl PinchFinger {
    /// The raw positions of the held pinch.
    pub const fn positions(self) -> [f32; CHANNELS] {
        match self {
            PinchFinger::Index => PINCH_INDEX,
            PinchFinger::Middle => PINCH_MIDDLE,
            PinchFinger::Ring => PINCH_RING,
        }
    }
}

/// The script names [`Script::parse`] knows (besides a trajectory file), for help and errors.
pub const SCRIPT_NAMES: &str =
    "hold, open-close, grasp, pinch-index (or pinch), pinch-middle, pinch-ring, free";

/// Positions of an open, relaxed hand.
const OPEN: [f32; CHANNELS] = [950.0, 950.0, 950.0, 950.0, 900.0, 700.0];
/// Positions of a fist.
const FIST: [f32; CHANNELS] = [80.0, 80.0, 80.0, 80.0, 150.0, 300.0];

// The held pinches. In the operator model posed from the glove node's positions (`raw / 1000`,
// `teleop_kinematics::OperatorHand::default()`), the thumb's and the finger's fingertip pads
// touch (gap under 0.1 mm), pulp to pulp; the other fingers stay as in `OPEN`. Found once by a
// grid search over the three moving channels (raw 0..950 in steps of 10, the finger's value
// bisected to the gap's zero): of the poses whose pads touch, one close to those whose pads
// face each other most squarely (the larger the lesser of the two cosines between the line
// joining the pad centres and each distal segment's palm-side normal), off the glove's ends.
// Poses closing further also touch (e.g. flexions of 0.275 thumb, 0.625 rotation, 0.675 index),
// but with a pad on the back or the side of the other finger. The unit tests check these
// against the model, so a change to the model that moves the pinches fails there.
/// The thumb pinches the index finger: a nearly straight thumb rotated in, the index half bent.
const PINCH_INDEX: [f32; CHANNELS] = [950.0, 950.0, 950.0, 483.0, 920.0, 150.0];
/// The thumb pinches the middle finger.
const PINCH_MIDDLE: [f32; CHANNELS] = [950.0, 950.0, 427.0, 950.0, 800.0, 60.0];
/// The thumb pinches the ring finger, rotated in almost fully and reaching across the palm.
const PINCH_RING: [f32; CHANNELS] = [950.0, 415.0, 950.0, 950.0, 610.0, 30.0];

/// Frequencies of the free motion's channels, Hz: 0.05 times the square roots of the primes 3
/// to 17, pairwise incommensurate (square roots of distinct primes are linearly independent
/// over the rationals); periods from 4.8 to 11.5 s.
const FREE_HZ: [f32; CHANNELS] = [0.0866, 0.1118, 0.1323, 0.1658, 0.1803, 0.2062];
/// The middle of the free motion's swing (raw): each channel swings between 100 and 900.
const FREE_MID: f32 = 500.0;
/// The free motion's amplitude (raw), see [`FREE_MID`].
const FREE_AMPLITUDE: f32 = 400.0;

impl Script {
    /// Parses a script name ([`SCRIPT_NAMES`]) or loads a trajectory CSV file
    /// (`t_s,little,ring,middle,index,thumb,thumb_rotation` per line; `#` comments).
    pub fn parse(spec: &str) -> Result<Self, String> {
        let pinch = |finger| Script::Pinch {
            finger,
            period_s: 4.0,
        };
        Ok(match spec {
            "hold" => Script::Hold(OPEN),
            "open-close" => Script::OpenClose { period_s: 4.0 },
            "pinch" | "pinch-index" => pinch(PinchFinger::Index),
            "pinch-middle" => pinch(PinchFinger::Middle),
            "pinch-ring" => pinch(PinchFinger::Ring),
            "grasp" => Script::Grasp { period_s: 6.0 },
            "free" => Script::Free,
            path => Script::Trajectory(load_trajectory(Path::new(path))?),
        })
    }

    /// The operator's intended raw positions at time `t` seconds.
    pub fn at(&self, t: f32) -> [f32; CHANNELS] {
        let blend = |a: &[f32; CHANNELS], b: &[f32; CHANNELS], s: f32| -> [f32; CHANNELS] {
            let s = s.clamp(0.0, 1.0);
            core::array::from_fn(|i| a[i] + (b[i] - a[i]) * s)
        };
        // Smooth 0..1..0 over a period.
        let wave = |period: f32| (1.0 - (core::f32::consts::TAU * t / period.max(0.1)).cos()) / 2.0;
        match self {
            Script::Hold(p) => *p,
            Script::OpenClose { period_s } => blend(&OPEN, &FIST, wave(*period_s)),
            Script::Pinch { finger, period_s } => {
                let pinch = finger.positions();
                // Each move starts and stops smoothly (smoothstep).
                let ease = |s: f32| {
                    let s = s.clamp(0.0, 1.0);
                    s * s * (3.0 - 2.0 * s)
                };
                match (t / period_s.max(0.1)).rem_euclid(1.0) {
                    p if p < 0.25 => blend(&OPEN, &pinch, ease(p / 0.25)),
                    p if p < 0.625 => pinch,
                    p if p < 0.875 => blend(&pinch, &OPEN, ease((p - 0.625) / 0.25)),
                    _ => OPEN,
                }
            }
            Script::Grasp { period_s } => {
                // 0-20 % reach (open), 20-45 % close around the object, 45-80 % squeeze and
                // hold, 80-100 % release.
                let phase = (t / period_s.max(0.1)).rem_euclid(1.0);
                let mut around = FIST;
                for p in around.iter_mut().take(FINGERS) {
                    *p = (*p + 2.0 * 950.0) / 3.0; // an object about a third of a fist
                }
                let mut squeeze = around;
                for p in squeeze.iter_mut().take(FINGERS) {
                    *p -= 150.0;
                }
                match phase {
                    p if p < 0.2 => OPEN,
                    p if p < 0.45 => blend(&OPEN, &around, (p - 0.2) / 0.25),
                    p if p < 0.55 => blend(&around, &squeeze, (p - 0.45) / 0.1),
                    p if p < 0.8 => squeeze,
                    p => blend(&squeeze, &OPEN, (p - 0.8) / 0.2),
                }
            }
            // Each channel starts open (at the top of its swing).
            Script::Free => FREE_HZ
                .map(|hz| FREE_MID + FREE_AMPLITUDE * (core::f32::consts::TAU * hz * t).cos()),
            Script::Trajectory(points) => trajectory_at(points, t),
        }
    }
}

fn trajectory_at(points: &[(f32, [f32; CHANNELS])], t: f32) -> [f32; CHANNELS] {
    let (Some(first), Some(last)) = (points.first(), points.last()) else {
        return OPEN;
    };
    let span = last.0 - first.0;
    let t = if span > 0.0 {
        first.0 + (t - first.0).rem_euclid(span)
    } else {
        first.0
    };
    for w in points.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if t >= a.0 && t <= b.0 {
            let s = if b.0 > a.0 {
                (t - a.0) / (b.0 - a.0)
            } else {
                0.0
            };
            return core::array::from_fn(|i| a.1[i] + (b.1[i] - a.1[i]) * s);
        }
    }
    last.1
}

fn load_trajectory(path: &Path) -> Result<Vec<(f32, [f32; CHANNELS])>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        format!(
            "{}: not a script name ({SCRIPT_NAMES}) and not a readable trajectory file: {e}",
            path.display()
        )
    })?;
    let mut points = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<f32> = line
            .split(',')
            .map(|f| f.trim().parse::<f32>())
            .collect::<Result<_, _>>()
            .map_err(|e| format!("{}:{}: {e}", path.display(), n + 1))?;
        if fields.len() != CHANNELS + 1 || fields.iter().any(|v| !v.is_finite()) {
            return Err(format!(
                "{}:{}: expected t_s and 6 finite positions, got {line:?}",
                path.display(),
                n + 1
            ));
        }
        if points.last().is_some_and(|(t, _)| fields[0] < *t) {
            return Err(format!("{}:{}: time goes backwards", path.display(), n + 1));
        }
        points.push((
            fields[0],
            core::array::from_fn(|i| fields[i + 1].clamp(0.0, 1000.0)),
        ));
    }
    if points.is_empty() {
        return Err(format!("{}: no trajectory points", path.display()));
    }
    Ok(points)
}

/// What an actuator is told to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drive {
    /// Apply this force (-1000..1000; positive opens the hand).
    Force(f32),
    /// Move the finger to this position (0..1000).
    Position(f32),
}

/// Fingertip travel per raw position unit, m: the index fingertip pad's path from open (1000)
/// to fist (0) in the operator model (`teleop_kinematics::OperatorHand::default()`) is 0.169 m
/// long (measured by the unit test `a_raw_unit_is_a_thousandth_of_the_index_pads_travel`); the
/// other fingers' pads travel 0.14 to 0.19 m, and one scale serves every channel.
pub const METRES_PER_RAW: f64 = 0.169 / 1000.0;

/// Newtons per glove force unit: each finger pushes with up to 3 N actively (the manual, 1.1),
/// the full scale of a force command (1000).
pub const NEWTONS_PER_FORCE: f64 = 3.0 / 1000.0;

/// The whole travel, m.
const TRAVEL_M: f64 = 1000.0 * METRES_PER_RAW;

/// The operator's fingers and the glove's actuators.
///
/// Each channel's fingertip, `x` metres along its travel from the fist, is a mass on a spring
/// and a damper (SI; positive opens):
///
/// `m x'' = k (x_eq - x) - b x' + F`, stopped hard at both ends of the travel,
///
/// where `x_eq` is the operator's equilibrium point, which follows the script's intent no faster
/// than `max_speed`, and `F` the actuator's push. Squeezing stiffens the finger: the operator's
/// effort `e` follows the muscles' pull `|k (x_eq - x)|` with the time constant `effort_tau_s`,
/// and
///
/// `k = min(stiffness_n_per_m + stiffening_per_m * e, max_stiffness_n_per_m)`,
/// `b = damping_n_s_per_m * sqrt(k / stiffness_n_per_m)`
///
/// (the damping keeps the relaxed finger's damping ratio). At rest under a steady push `F` the
/// effort is `|F|` and the finger gives way by `F / k`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandModel {
    /// The finger's effective mass at the fingertip, kg.
    pub mass_kg: f32,
    /// The relaxed finger's stiffness about its equilibrium point, N/m.
    pub stiffness_n_per_m: f32,
    /// The relaxed finger's damping, N s/m.
    pub damping_n_s_per_m: f32,
    /// Stiffness gained per newton of the operator's effort, N/m per N.
    pub stiffening_per_m: f32,
    /// The stiffest the finger gets, N/m.
    pub max_stiffness_n_per_m: f32,
    /// Time constant by which the operator's effort follows the muscles' pull, s.
    pub effort_tau_s: f32,
    /// Fastest the operator's equilibrium point and the position servo move, raw units per
    /// second.
    pub max_speed: f32,
    /// Time constant of the position servo following its set-point, s.
    pub servo_tau_s: f32,
    /// Idle current in mA.
    pub idle_ma: f32,
    /// Current per unit of force, mA.
    pub ma_per_force: f32,
    /// Temperature of the room, degrees Celsius.
    pub ambient_c: f32,
    /// Temperature rise per mA at steady state.
    pub c_per_ma: f32,
    /// Thermal time constant, seconds.
    pub thermal_tau_s: f32,
    /// A force of at least this magnitude for `overload_s` sets the locked-rotor and
    /// over-current bits.
    pub overload_force: f32,
    /// See `overload_force`.
    pub overload_s: f32,
    /// Above this temperature the over-temperature bit is set; it clears 10 degrees below.
    pub over_temperature_c: f32,
}

impl Default for HandModel {
    /// The finger's figures are chosen within the ranges commonly cited for human fingertips
    /// (masses of a few grams, damping of a few N s/m, stiffness of a few hundred N/m), not
    /// copied from one table. Sources: Hajian and Howe (1997, "Identification of the
    /// mechanical impedance at the human finger tip", J. Biomech. Eng.), the usual reference
    /// for the fingertip as a mass, damper and spring (read here through others' summaries,
    /// not its tables); Hasser and Cutkosky (2002, a lumped second-order model of nine subjects
    /// pinching a haptic knob), who report damping and stiffness rising steadily with grip
    /// force and the inertia staying about constant except at very large grip forces; Van
    /// Doren (1998, Motor Control 2, "Grasp stiffness as a function of grasp force and finger
    /// span") and Höppner, McIntyre and van der Smagt (2013, PLOS ONE, "Task dependency of grip
    /// stiffness"), who find grasp stiffness rising about linearly with grip force. The
    /// relaxed finger here: 6 g, 1 N s/m, 200 N/m (29 Hz, damping ratio 0.46); 100 N/m more
    /// per newton of effort, 500 N/m at the glove's full 3 N, at most 1500 N/m (80 Hz, from
    /// 13 N). The effort's time constant, 0.1 s, is a choice: several of the finger's periods,
    /// so that a quick disturbance meets a steady stiffness as in the identification
    /// experiments, and shorter than a voluntary reaction.
    fn default() -> Self {
        Self {
            mass_kg: 0.006,
            stiffness_n_per_m: 200.0,
            damping_n_s_per_m: 1.0,
            stiffening_per_m: 100.0,
            max_stiffness_n_per_m: 1500.0,
            effort_tau_s: 0.1,
            max_speed: 4000.0,
            servo_tau_s: 0.05,
            idle_ma: 40.0,
            ma_per_force: 0.8,
            ambient_c: 30.0,
            c_per_ma: 0.06,
            thermal_tau_s: 20.0,
            overload_force: 900.0,
            overload_s: 2.0,
            over_temperature_c: 75.0,
        }
    }
}

/// Error bits as the device reports them (see the protocol crate's `ErrorBits`).
const LOCKED_ROTOR: u8 = 1;
const OVER_TEMPERATURE: u8 = 2;
const OVER_CURRENT: u8 = 4;

/// The operator's hand and the glove's actuators.
#[derive(Debug, Clone)]
pub struct Hand {
    model: HandModel,
    script: Script,
    /// Each fingertip's travel from the fist, m.
    travel: [f64; CHANNELS],
    /// Its rate, m/s (positive opens).
    speed: [f64; CHANNELS],
    /// Where the operator's muscles pull each finger, m.
    equilibrium: [f64; CHANNELS],
    /// The operator's effort per finger, N.
    effort: [f64; CHANNELS],
    drive: [Drive; FINGERS],
    /// The force each actuator measures, glove units.
    force: [f32; FINGERS],
    temperature: [f32; FINGERS],
    overload_for: [f32; FINGERS],
    errors: [u8; FINGERS],
    clock: Clock,
}

impl Hand {
    /// A hand following `script`, at rest where the script starts, actuators applying no force.
    pub fn new(script: Script, model: HandModel) -> Self {
        let travel = script
            .at(0.0)
            .map(|p| f64::from(p.clamp(0.0, 1000.0)) * METRES_PER_RAW);
        Self {
            model,
            script,
            travel,
            speed: [0.0; CHANNELS],
            equilibrium: travel,
            effort: [0.0; CHANNELS],
            drive: [Drive::Force(0.0); FINGERS],
            force: [0.0; FINGERS],
            temperature: [model.ambient_c; FINGERS],
            overload_for: [0.0; FINGERS],
            errors: [0; FINGERS],
            clock: Clock::new(STEP_S),
        }
    }

    /// Sets what one actuator does (finger 0..5, glove order).
    pub fn set_drive(&mut self, finger: usize, drive: Drive) {
        if let Some(d) = self.drive.get_mut(finger) {
            *d = drive;
        }
    }

    /// The actuators' current drives.
    pub fn drives(&self) -> [Drive; FINGERS] {
        self.drive
    }

    /// Advances the model to time `t` seconds.
    pub fn advance_to(&mut self, t: f32) {
        // The operator's intent is taken at each sub-step's time, so that the finger's
        // velocity is the script's and not a staircase of the caller's steps.
        let mut clock = self.clock;
        clock.advance_to(f64::from(t), |now, h| self.step(now as f32, h));
        self.clock = clock;
    }

    /// The stiffness (N/m) and damping (N s/m) of channel `ch` at its present effort.
    fn impedance(&self, ch: usize) -> (f64, f64) {
        let m = &self.model;
        let relaxed = f64::from(m.stiffness_n_per_m);
        let k = (relaxed + f64::from(m.stiffening_per_m) * self.effort[ch])
            .min(f64::from(m.max_stiffness_n_per_m));
        let damping_scale = if relaxed > 0.0 {
            (k / relaxed).sqrt()
        } else {
            1.0
        };
        (k, f64::from(m.damping_n_s_per_m) * damping_scale)
    }

    fn step(&mut self, now: f32, h: f64) {
        let m = self.model;
        let intent = self.script.at(now);
        let max_move = f64::from(m.max_speed) * METRES_PER_RAW * h;
        for (ch, meant) in intent.into_iter().enumerate() {
            let wanted = f64::from(meant.clamp(0.0, 1000.0)) * METRES_PER_RAW;
            self.equilibrium[ch] += (wanted - self.equilibrium[ch]).clamp(-max_move, max_move);
            let (k, b) = self.impedance(ch);
            // The operator's muscles, N (positive opens).
            let pull = k * (self.equilibrium[ch] - self.travel[ch]);
            self.effort[ch] = lag(self.effort[ch], pull.abs(), h, f64::from(m.effort_tau_s));
            // A locked actuator pushes no more; the thumb's rotation has none.
            let drive = self
                .drive
                .get(ch)
                .filter(|_| self.errors[ch] & LOCKED_ROTOR == 0);
            let (x, v) = (&mut self.travel[ch], &mut self.speed[ch]);
            let measured = match drive {
                Some(Drive::Position(p)) => {
                    // A stiff servo: the finger goes where the actuator takes it, and the
                    // actuator feels the operator's spring and damper (the finger's few grams
                    // left out: the servo's abrupt starts would turn them into spikes).
                    let target = f64::from(p.clamp(0.0, 1000.0)) * METRES_PER_RAW;
                    let to = (lag(*x, target, h, f64::from(m.servo_tau_s)) - *x)
                        .clamp(-max_move, max_move);
                    *x += to;
                    *v = to / h;
                    (b * *v - pull) / NEWTONS_PER_FORCE
                }
                other => {
                    // The cable pulls with the commanded force: that is what its sensor reads.
                    let push = match other {
                        Some(Drive::Force(f)) => f64::from(f.clamp(-1000.0, 1000.0)),
                        _ => 0.0,
                    };
                    let force = pull + push * NEWTONS_PER_FORCE;
                    let mass = f64::from(m.mass_kg);
                    // The damper acts at the step's mean velocity (trapezoidal, solved for
                    // in closed form): at the velocity the step starts with, as the kit's
                    // joint takes it, it would damp the stiffest finger 6 % too much.
                    let mean = (*v + 0.5 * h * force / mass) / (1.0 + 0.5 * h * b / mass);
                    let finger = Joint {
                        inertia: mass,
                        damping: 0.0,
                    };
                    finger.step(x, v, force - b * mean, h, (0.0, TRAVEL_M));
                    push
                }
            };
            if let Some(f) = self.force.get_mut(ch) {
                *f = measured.clamp(-1000.0, 1000.0) as f32;
            }
        }
        let h = h as f32;
        for f in 0..FINGERS {
            let load = self.force[f].abs();
            let current = self.current(load);
            let steady = m.ambient_c + m.c_per_ma * current;
            self.temperature[f] = lag(self.temperature[f], steady, h, m.thermal_tau_s);
            if load >= m.overload_force {
                self.overload_for[f] += h;
            } else {
                self.overload_for[f] = 0.0;
            }
            if self.overload_for[f] >= m.overload_s {
                self.errors[f] |= LOCKED_ROTOR | OVER_CURRENT;
            }
            if self.temperature[f] >= m.over_temperature_c {
                self.errors[f] |= OVER_TEMPERATURE;
            } else if self.temperature[f] < m.over_temperature_c - 10.0 {
                self.errors[f] &= !OVER_TEMPERATURE;
            }
        }
    }

    fn current(&self, load: f32) -> f32 {
        (self.model.idle_ma + self.model.ma_per_force * load).clamp(0.0, 1000.0)
    }

    /// Actual raw positions (little, ring, middle, index, thumb, thumb rotation).
    pub fn positions(&self) -> [u16; CHANNELS] {
        self.travel
            .map(|x| (x / METRES_PER_RAW).round().clamp(0.0, 1000.0) as u16)
    }

    /// The fingers' velocities, raw units per second (positive opens), in the order of
    /// [`Hand::positions`].
    pub fn velocities(&self) -> [f32; CHANNELS] {
        self.speed.map(|v| (v / METRES_PER_RAW) as f32)
    }

    /// Measured finger forces (glove units): the force between each finger and its actuator,
    /// positive when the finger pushes towards a fist (the actuator pushing it open).
    pub fn forces(&self) -> [i16; FINGERS] {
        self.force.map(|f| f.round() as i16)
    }

    /// Actuator currents in mA.
    pub fn currents(&self) -> [u16; FINGERS] {
        self.force.map(|f| self.current(f.abs()).round() as u16)
    }

    /// Actuator temperatures in degrees Celsius.
    pub fn temperatures(&self) -> [u8; FINGERS] {
        self.temperature.map(|t| t.round().clamp(0.0, 255.0) as u8)
    }

    /// Actuator error bits.
    pub fn errors(&self) -> [u8; FINGERS] {
        self.errors
    }

    /// Clears the clearable errors (all but over-temperature, which clears itself when cool).
    pub fn clear_errors(&mut self) {
        for (e, o) in self.errors.iter_mut().zip(self.overload_for.iter_mut()) {
            *e &= OVER_TEMPERATURE;
            *o = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use teleop_kinematics::{OperatorHand, OperatorPose};

    use super::*;

    fn still(p: f32) -> Hand {
        Hand::new(Script::Hold([p; CHANNELS]), HandModel::default())
    }

    #[test]
    fn free_hand_follows_the_script() {
        let s = Script::OpenClose { period_s: 4.0 };
        let mut h = Hand::new(s.clone(), HandModel::default());
        // A quarter period: the hand closes fastest.
        h.advance_to(1.0);
        let wanted = (s.at(1.001)[0] - s.at(0.999)[0]) / 0.002;
        let v = h.velocities()[0];
        assert!(
            wanted < -600.0 && (v - wanted).abs() < 0.02 * wanted.abs(),
            "{v} raw/s, the script {wanted}"
        );
        h.advance_to(2.0); // half a period: closed
        assert!(h.positions()[0] < 200, "{:?}", h.positions());
        h.advance_to(4.0);
        assert!(h.positions()[0] > 850, "{:?}", h.positions());
        assert_eq!(h.forces(), [0; 5]);
    }

    #[test]
    fn a_raw_unit_is_a_thousandth_of_the_index_pads_travel() {
        let model = OperatorHand::default();
        let pad = |flexion: f32| {
            let mut pose = OperatorPose::default();
            pose.flexion[1] = flexion;
            model.pads(&pose)[1]
        };
        let steps = 1000;
        let travel: f32 = (0..steps)
            .map(|i| pad(i as f32 / steps as f32).distance(pad((i + 1) as f32 / steps as f32)))
            .sum();
        let per_raw = f64::from(travel) / 1000.0;
        assert!(
            (per_raw - METRES_PER_RAW).abs() < 0.005 * METRES_PER_RAW,
            "the index pad travels {travel} m"
        );
    }

    /// A finger's travel from its equilibrium, raw units.
    fn offset(h: &Hand, ch: usize) -> f64 {
        (h.travel[ch] - h.equilibrium[ch]) / METRES_PER_RAW
    }

    /// The relaxed finger's stiffness with the force it resists (N), as [`HandModel`] states it.
    fn stiffness_at(m: &HandModel, newtons: f64) -> f64 {
        (f64::from(m.stiffness_n_per_m) + f64::from(m.stiffening_per_m) * newtons)
            .min(f64::from(m.max_stiffness_n_per_m))
    }

    #[test]
    fn a_constant_force_gives_way_by_force_over_stiffness_and_is_felt() {
        let mut h = still(300.0);
        h.set_drive(3, Drive::Force(500.0));
        h.advance_to(1.0);
        let newtons = 500.0 * NEWTONS_PER_FORCE;
        let k = stiffness_at(&HandModel::default(), newtons);
        let expected = newtons / k / METRES_PER_RAW;
        assert!(expected > 10.0, "{expected}");
        assert!(
            (offset(&h, 3) - expected).abs() < 0.01 * expected,
            "pushed open {} raw, F/k = {expected}",
            offset(&h, 3)
        );
        assert!(
            h.velocities()[3].abs() < 1.0,
            "at rest: {:?}",
            h.velocities()
        );
        let p = h.positions();
        assert_eq!(p[0], 300, "other fingers untouched");
        assert_eq!(h.forces()[3], 500, "the cable's force");
        assert!(h.currents()[3] > h.currents()[0]);
    }

    #[test]
    fn the_grip_stiffens_with_the_squeeze_and_saturates() {
        let m = HandModel::default();
        let mut secant = Vec::new();
        for force in [100.0, 400.0, 1000.0] {
            let mut h = still(500.0);
            h.set_drive(3, Drive::Force(force));
            h.advance_to(1.5);
            let newtons = f64::from(force) * NEWTONS_PER_FORCE;
            let k = newtons / (offset(&h, 3) * METRES_PER_RAW);
            let law = stiffness_at(&m, newtons);
            assert!((k - law).abs() < 0.01 * law, "{force}: {k} N/m, {law} N/m");
            secant.push(k);
        }
        assert!(
            secant[2] > 1.5 * secant[0] && secant[1] > secant[0],
            "{secant:?} N/m"
        );
        // Held far from where the operator means it to be: as stiff as the model allows.
        let mut h = still(900.0);
        h.set_drive(3, Drive::Position(100.0));
        h.advance_to(1.0);
        let (k, b) = h.impedance(3);
        assert_eq!(k, f64::from(m.max_stiffness_n_per_m));
        let ratio = (k / f64::from(m.stiffness_n_per_m)).sqrt();
        assert!(
            (b - f64::from(m.damping_n_s_per_m) * ratio).abs() < 1e-9,
            "{b}"
        );
    }

    /// The damped natural frequency (Hz) and damping ratio of channel 3 ringing down from a
    /// displacement, measured from the trajectory: zero crossings for the period, successive
    /// extremes (half a period apart) for the logarithmic decrement.
    fn ring_down(model: HandModel) -> (f64, f64) {
        let mut h = Hand::new(Script::Hold([500.0; CHANNELS]), model);
        h.travel[3] += 200.0 * METRES_PER_RAW;
        let (mut crossings, mut extremes) = (Vec::new(), Vec::new());
        let (mut before, mut t) = (offset(&h, 3), 0.0);
        let mut rising = before < 0.0;
        for k in 1..=800 {
            let now = k as f32 * STEP_S as f32;
            h.advance_to(now);
            let x = offset(&h, 3);
            if (x > 0.0) != (before > 0.0) {
                crossings.push(t + STEP_S * before / (before - x));
            }
            if rising != (x > before) {
                extremes.push(before.abs());
                rising = x > before;
            }
            (before, t) = (x, f64::from(now));
        }
        assert!(
            crossings.len() >= 4 && extremes.len() >= 3,
            "{crossings:?} {extremes:?}"
        );
        let period = crossings[2] - crossings[0];
        let decrement = (extremes[0] / extremes[1]).ln();
        let zeta = decrement / (core::f64::consts::PI.powi(2) + decrement.powi(2)).sqrt();
        let damped_hz = 1.0 / period;
        (damped_hz / (1.0 - zeta * zeta).sqrt(), zeta)
    }

    #[test]
    fn a_released_finger_rings_down_at_its_natural_frequency_and_damping() {
        let relaxed = HandModel {
            stiffening_per_m: 0.0,
            ..HandModel::default()
        };
        // As stiff as squeezing makes it, the damping raised alike.
        let squeezed = HandModel {
            stiffness_n_per_m: relaxed.max_stiffness_n_per_m,
            damping_n_s_per_m: relaxed.damping_n_s_per_m
                * (relaxed.max_stiffness_n_per_m / relaxed.stiffness_n_per_m).sqrt(),
            ..relaxed
        };
        for model in [relaxed, squeezed] {
            let (m, b, k) = (
                f64::from(model.mass_kg),
                f64::from(model.damping_n_s_per_m),
                f64::from(model.stiffness_n_per_m),
            );
            let hz = (k / m).sqrt() / core::f64::consts::TAU;
            let zeta = b / (2.0 * (k * m).sqrt());
            let (measured_hz, measured_zeta) = ring_down(model);
            assert!(
                (measured_hz - hz).abs() < 0.01 * hz && (measured_zeta - zeta).abs() < 0.01 * zeta,
                "{k} N/m: {measured_hz} Hz, damping ratio {measured_zeta}; \
                 the parameters give {hz} Hz, {zeta}"
            );
            // Within the human finger's figures: tens of hertz, well but not over damped.
            assert!((20.0..100.0).contains(&hz) && (0.2..0.8).contains(&zeta));
        }
    }

    #[test]
    fn the_travel_stops_hard_at_its_ends() {
        let mut h = Hand::new(
            Script::Hold([10.0, 500.0, 500.0, 990.0, 500.0, 500.0]),
            HandModel::default(),
        );
        h.set_drive(0, Drive::Force(-1000.0));
        h.set_drive(3, Drive::Force(1000.0));
        h.advance_to(0.5);
        assert_eq!((h.positions()[0], h.positions()[3]), (0, 1000));
        assert_eq!((h.velocities()[0], h.velocities()[3]), (0.0, 0.0));
        assert_eq!(
            (h.forces()[0], h.forces()[3]),
            (-1000, 1000),
            "the cables still pull"
        );
    }

    #[test]
    fn position_drive_moves_the_finger() {
        let mut h = still(900.0);
        h.set_drive(4, Drive::Position(100.0));
        h.advance_to(0.02);
        assert!(h.velocities()[4] < -1000.0, "{:?}", h.velocities());
        h.advance_to(1.0);
        assert_eq!(h.positions()[4], 100, "a stiff servo");
        assert!(h.forces()[4] < -900, "the operator resists being closed");
    }

    #[test]
    fn sustained_overload_sets_error_bits_that_can_be_cleared() {
        let mut h = still(500.0);
        h.set_drive(0, Drive::Force(1000.0));
        h.advance_to(1.0);
        assert_eq!(h.errors()[0], 0);
        h.advance_to(3.5);
        assert_eq!(h.errors()[0], LOCKED_ROTOR | OVER_CURRENT);
        // Locked, the actuator pushes no more: the finger goes back to the operator.
        assert_eq!(h.forces()[0], 0);
        h.advance_to(4.5);
        assert!((offset(&h, 0)).abs() < 0.5, "{}", offset(&h, 0));
        h.set_drive(0, Drive::Force(0.0));
        h.clear_errors();
        assert_eq!(h.errors()[0], 0);
    }

    #[test]
    fn temperature_follows_the_load() {
        let mut h = still(500.0);
        h.set_drive(1, Drive::Force(800.0));
        h.advance_to(60.0);
        assert!(
            h.temperatures()[1] > h.temperatures()[0] + 20,
            "{:?}",
            h.temperatures()
        );
    }

    #[test]
    fn grasp_reaches_squeezes_and_releases() {
        let s = Script::Grasp { period_s: 10.0 };
        assert!(s.at(1.0)[3] > 900.0);
        assert!(s.at(6.0)[3] < s.at(4.0)[3]);
        assert!(s.at(9.99)[3] > 850.0);
    }

    /// The operator model's pose for raw glove positions, normalised as the glove node does.
    fn operator(raw: &[f32; CHANNELS]) -> OperatorPose {
        OperatorPose::from_glove(&raw.map(|p| p / 1000.0))
    }

    /// The pinched finger's index in the operator model's finger order (thumb first).
    fn model_finger(finger: PinchFinger) -> usize {
        match finger {
            PinchFinger::Index => 1,
            PinchFinger::Middle => 2,
            PinchFinger::Ring => 3,
        }
    }

    const PINCHES: [PinchFinger; 3] = [PinchFinger::Index, PinchFinger::Middle, PinchFinger::Ring];

    #[test]
    fn pinches_touch_pad_to_pad_in_the_operator_model() {
        let model = OperatorHand::default();
        for finger in PINCHES {
            let pose = operator(&finger.positions());
            let f = model_finger(finger);
            let gap = model.pad_gap(&pose, 0, f);
            assert!(gap.abs() < 0.001, "{finger:?}: pads {gap} m apart");
            // Pulp to pulp: each pad lies on the palm side of the other's distal segment.
            let skeleton = model.pose(&pose);
            // The distal segment turned a right angle further in the plane the finger bends
            // in (`first x last` is the bending axis).
            let palm_side = |i: usize| {
                let chain = &skeleton.fingers[i];
                let (first, last) = (chain[1] - chain[0], chain[3] - chain[2]);
                first.cross(last).cross(last).normalize()
            };
            let pads = model.pads(&pose);
            let to_finger = (pads[f] - pads[0]).normalize();
            let thumb = to_finger.dot(palm_side(0));
            let other = -to_finger.dot(palm_side(f));
            assert!(
                thumb > 0.2 && other > 0.2,
                "{finger:?}: the pads do not face each other ({thumb}, {other})"
            );
            // The simulator reports whole raw units: one unit off on any channel still pinches.
            for ch in 0..CHANNELS {
                for d in [-1.0, 1.0] {
                    let mut raw = finger.positions();
                    raw[ch] += d;
                    let gap = model.pad_gap(&operator(&raw), 0, f);
                    assert!(gap.abs() < 0.002, "{finger:?} channel {ch} {d:+}: {gap} m");
                }
            }
        }
    }

    #[test]
    fn pinch_closes_holds_and_opens_without_passing_through() {
        let model = OperatorHand::default();
        assert_eq!(Script::parse("pinch"), Script::parse("pinch-index"));
        for (name, finger) in ["pinch-index", "pinch-middle", "pinch-ring"]
            .into_iter()
            .zip(PINCHES)
        {
            let s = Script::parse(name).unwrap();
            assert_eq!(s.at(0.0), OPEN, "{name}");
            assert_eq!(s.at(1.0), finger.positions(), "{name}");
            assert_eq!(s.at(2.4), finger.positions(), "{name}");
            assert_eq!(s.at(3.6), OPEN, "{name}");
            let f = model_finger(finger);
            for k in 0..=400 {
                let t = k as f32 * 0.01;
                let gap = model.pad_gap(&operator(&s.at(t)), 0, f);
                assert!(gap > -0.002, "{name} at {t} s: pads overlap by {gap} m");
            }
            // The simulated finger settles on the pinch while it is held.
            let mut h = Hand::new(s, HandModel::default());
            h.advance_to(2.0);
            let raw = h.positions().map(f32::from);
            let gap = model.pad_gap(&operator(&raw), 0, f);
            assert!(gap.abs() < 0.002, "{name}: the held pinch is {gap} m apart");
        }
    }

    #[test]
    fn free_motion_is_slow_and_covers_most_of_the_range() {
        let s = Script::parse("free").unwrap();
        assert_eq!(s.at(0.0), [900.0; CHANNELS], "starts open");
        let (mut low, mut high) = ([f32::MAX; CHANNELS], [f32::MIN; CHANNELS]);
        let mut before = s.at(0.0);
        for k in 1..=6000 {
            let now = s.at(k as f32 * 0.01);
            for ch in 0..CHANNELS {
                low[ch] = low[ch].min(now[ch]);
                high[ch] = high[ch].max(now[ch]);
                let speed = (now[ch] - before[ch]).abs() / 0.01;
                assert!(speed < 600.0, "channel {ch}: {speed} raw/s");
            }
            before = now;
        }
        for ch in 0..CHANNELS {
            assert!(
                low[ch] < 120.0 && high[ch] > 880.0,
                "channel {ch}: {low:?} {high:?}"
            );
        }
    }

    #[test]
    fn trajectory_files_are_checked() {
        let dir = std::env::temp_dir().join(format!("sim-glove-traj-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("good.csv");
        std::fs::write(
            &good,
            "# t,l,r,m,i,t,rot\n0,1000,1000,1000,1000,1000,500\n1,0,0,0,0,0,500\n",
        )
        .unwrap();
        let s = Script::parse(good.to_str().unwrap()).unwrap();
        assert_eq!(s.at(0.5)[0], 500.0);
        let bad = dir.join("bad.csv");
        std::fs::write(&bad, "0,1,2\n").unwrap();
        let e = Script::parse(bad.to_str().unwrap()).unwrap_err();
        assert!(e.contains("bad.csv:1"), "{e}");
        assert!(Script::parse("no-such-script").is_err());
        let _ = std::fs::remove_dir_all(dir);
    }
}
