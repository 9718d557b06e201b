//! Measuring a retargeter on glove trajectories: does the robot hand do what the operator's
//! hand does?
//!
//! [`Evaluation`] takes each glove sample with the targets a [`Retargeter`] made of it (and the
//! time the step took, measured by the caller: this crate has no clock) and accumulates:
//!
//! - **fingertip error**: per retargeted finger, the distance between the robot's pad centre and
//!   the operator model's pad centre times the hand's scaling, both relative to the wrist (the
//!   hand frame's origin), mm; a frame's value is the mean over its fingers;
//! - **pinch distance**: in the frames where the operator model pinches (a thumb-finger pad gap
//!   under [`OPERATOR_PINCH_M`]), the robot's gap between the same pads' surfaces (centre
//!   distance less both radii; negative when the spheres overlap), mm, and the share under
//!   [`ROBOT_PINCH_M`];
//! - **joint-limit saturation**: the share of joint values within 1 mrad of a profile limit;
//! - **jerk**: the third time derivative from four consecutive outputs (their own stamps) of
//!   each joint's angle, rad/s³, as its RMS over joints and frames, and of each robot pad's
//!   position, m/s³, per frame the mean over fingers (the whole hand's fingertip jerk);
//! - **solve time**: the caller's per-step durations.
//!
//! Pure: the caller reads recordings and times the steps.

// Vectors, joints and fingertips are parallel fixed-size arrays indexed together, as the
// formulas in the docs write them.
#![allow(clippy::needless_range_loop)]

use glam::{DVec3, Vec3};
use teleop_hand_profile::HandProfile;
use teleop_kinematics::{finger_of_glove_finger, Chains, OperatorHand, FINGERS};

use crate::retargeter::{JointTargets, Retargeter};
use crate::solver::Uniform;
use crate::GLOVE_CHANNELS;

/// The operator model pinches a finger when its pad and the thumb's are closer than this
/// (surface to surface), metres.
pub const OPERATOR_PINCH_M: f32 = 0.005;
/// A robot pinch counts as made when its pads are closer than this (surface to surface),
/// metres.
pub const ROBOT_PINCH_M: f64 = 0.010;
/// A joint within this of a limit is saturated, radians.
const SATURATED_RAD: f32 = 1e-3;

/// Percentiles of a set of values.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Spread {
    /// How many values.
    pub count: usize,
    /// Median.
    pub p50: f64,
    /// 95th percentile.
    pub p95: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl Spread {
    /// The spread of `values` (nearest-rank percentiles; all 0 when empty). Sorts in place.
    pub fn of(values: &mut [f64]) -> Self {
        values.sort_by(f64::total_cmp);
        let n = values.len();
        if n == 0 {
            return Self::default();
        }
        let at = |p: f64| values[((p * n as f64).ceil() as usize).clamp(1, n) - 1];
        Self {
            count: n,
            p50: at(0.50),
            p95: at(0.95),
            p99: at(0.99),
            max: values[n - 1],
        }
    }
}

/// A finished evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Frames evaluated.
    pub frames: usize,
    /// Fingertip error relative to the wrist, mm (per frame, mean over fingers).
    pub fingertip_error_mm: Spread,
    /// Robot thumb-finger pad gap in the operator's pinch frames, mm (every pinching finger of
    /// every such frame).
    pub pinch_gap_mm: Spread,
    /// Share of those under [`ROBOT_PINCH_M`], 0..1 (`None` without pinch frames).
    pub pinch_made: Option<f64>,
    /// Per operator finger after the thumb (index, middle, ring, little): operator pinch
    /// frames and, of those, robot pinches made.
    pub pinches_by_finger: [(usize, usize); 4],
    /// Share of joint values at a limit, 0..1.
    pub saturation: f64,
    /// RMS jerk over joints and frames, rad/s³.
    pub jerk_rms: f64,
    /// Fingertip jerk (the robot's pads, per frame the mean over fingers), m/s³.
    pub fingertip_jerk: Spread,
    /// Its RMS over frames, m/s³.
    pub fingertip_jerk_rms: f64,
    /// Step durations, µs.
    pub solve_us: Spread,
    /// The solver's iterations per step (0 in mode `joint`).
    pub iterations: Spread,
}

/// Accumulates the measures of one retargeter over one or more trajectories (see the module
/// docs).
#[derive(Debug, Clone)]
pub struct Evaluation {
    profile: HandProfile,
    chains: Chains,
    operator: OperatorHand,
    scaling: f64,
    /// Per operator finger (`FINGERS` order): the profile finger following it.
    follower: [Option<usize>; 5],
    fingertip_error_mm: Vec<f64>,
    pinch_gap_mm: Vec<f64>,
    pinches_by_finger: [(usize, usize); 4],
    saturated: usize,
    joint_values: usize,
    jerk_sq: f64,
    jerk_terms: usize,
    fingertip_jerk: Vec<f64>,
    solve_us: Vec<f64>,
    iterations: Vec<f64>,
    /// The last four outputs (joints in radians, then pads in metres) and their stamps, for
    /// jerk.
    history: Vec<(u64, Vec<f64>)>,
}

impl Evaluation {
    /// An evaluation of `retargeter`'s outputs for `profile`, against the operator model the
    /// retargeter uses and the scaling of its fingertip mode (the profile's in mode `joint`).
    pub fn new(profile: &HandProfile, retargeter: &Retargeter, scaling: f32) -> Self {
        let mut follower = [None; 5];
        for (f, finger) in profile.fingers.iter().enumerate() {
            if let Some(i) = finger.operator.and_then(finger_of_glove_finger) {
                follower[i] = Some(f);
            }
        }
        Self {
            profile: profile.clone(),
            chains: Chains::new(profile),
            operator: retargeter.operator().clone(),
            scaling: f64::from(scaling),
            follower,
            fingertip_error_mm: Vec::new(),
            pinch_gap_mm: Vec::new(),
            pinches_by_finger: [(0, 0); 4],
            saturated: 0,
            joint_values: 0,
            jerk_sq: 0.0,
            jerk_terms: 0,
            fingertip_jerk: Vec::new(),
            solve_us: Vec::new(),
            iterations: Vec::new(),
            history: Vec::new(),
        }
    }

    /// Starts a new trajectory (jerk is not measured across the join).
    pub fn new_trajectory(&mut self) {
        self.history.clear();
    }

    /// One step: the glove sample's stamp and closures (as [`crate::Calibration::closure`]
    /// gives them), the targets made of it, how long the step took and the solver's iterations.
    pub fn record(
        &mut self,
        t_ns: u64,
        closure: &[f32; GLOVE_CHANNELS],
        targets: &JointTargets,
        solve_ns: u64,
        iterations: u32,
    ) {
        self.iterations.push(f64::from(iterations));
        let q: Vec<f64> = self
            .profile
            .joints
            .iter()
            .zip(targets.positions())
            .map(|(j, &n)| f64::from(j.radians(n)))
            .collect();
        let pose = Retargeter::operator_pose(closure);
        let operator = self.operator.pads(&pose);
        let robot: [Option<DVec3>; 5] =
            core::array::from_fn(|i| self.follower[i].map(|f| self.chains.pad(f, &q)));

        let mut sum = 0.0;
        let mut fingers = 0;
        for (pad, op) in robot.iter().zip(&operator) {
            if let Some(pad) = pad {
                sum += pad.distance(op.as_dvec3() * self.scaling);
                fingers += 1;
            }
        }
        if fingers > 0 {
            self.fingertip_error_mm.push(1e3 * sum / f64::from(fingers));
        }

        if let Some(thumb) = robot[0] {
            for finger in 1..FINGERS.len() {
                let Some(pad) = robot[finger] else { continue };
                if self.operator_gap(&operator, finger) >= OPERATOR_PINCH_M {
                    continue;
                }
                let radii = self.radius(0) + self.radius(finger);
                let gap = thumb.distance(pad) - radii;
                self.pinch_gap_mm.push(1e3 * gap);
                let tally = &mut self.pinches_by_finger[finger - 1];
                tally.0 += 1;
                tally.1 += usize::from(gap < ROBOT_PINCH_M);
            }
        }

        for (j, joint) in self.profile.joints.iter().enumerate() {
            let a = q[j] as f32;
            self.joint_values += 1;
            if a <= joint.lower + SATURATED_RAD || a >= joint.upper - SATURATED_RAD {
                self.saturated += 1;
            }
        }

        // Jerk from the last four outputs: the joints, then the retargeted pads.
        let mut values = q;
        for pad in robot.iter().flatten() {
            values.extend_from_slice(&pad.to_array());
        }
        self.history.push((t_ns, values));
        if self.history.len() > 4 {
            self.history.remove(0);
        }
        if let [(t0, a), (t1, b), (t2, c), (t3, d)] = self.history.as_slice() {
            let dt = |x: u64, y: u64| (y.saturating_sub(x)) as f64 * 1e-9;
            let h = [dt(*t0, *t1), dt(*t1, *t2), dt(*t2, *t3)];
            if h.iter().all(|&h| h > 0.0) {
                let jerk = |i: usize| third_derivative(h, [a[i], b[i], c[i], d[i]]);
                let joints = self.profile.joints.len();
                for j in 0..joints {
                    self.jerk_sq += jerk(j).powi(2);
                    self.jerk_terms += 1;
                }
                let pads = (d.len() - joints) / 3;
                if pads > 0 {
                    let mut sum = 0.0;
                    for p in 0..pads {
                        let i = joints + 3 * p;
                        sum += DVec3::new(jerk(i), jerk(i + 1), jerk(i + 2)).length();
                    }
                    self.fingertip_jerk.push(sum / pads as f64);
                }
            }
        }
        self.solve_us.push(solve_ns as f64 * 1e-3);
    }

    /// The operator model's pad gap between the thumb and `finger` (`FINGERS` index).
    fn operator_gap(&self, pads: &[Vec3; 5], finger: usize) -> f32 {
        pads[0].distance(pads[finger])
            - self.operator.pad_radius[0]
            - self.operator.pad_radius[finger]
    }

    /// The pad radius of the robot finger following operator finger `finger`.
    fn radius(&self, finger: usize) -> f64 {
        self.follower[finger].map_or(0.0, |f| self.chains.chains()[f].pad_radius)
    }

    /// The measures so far.
    pub fn summary(&self) -> Summary {
        let made: usize = self.pinches_by_finger.iter().map(|t| t.1).sum();
        let frames: usize = self.pinches_by_finger.iter().map(|t| t.0).sum();
        Summary {
            frames: self.solve_us.len(),
            fingertip_error_mm: Spread::of(&mut self.fingertip_error_mm.clone()),
            pinch_gap_mm: Spread::of(&mut self.pinch_gap_mm.clone()),
            pinch_made: (frames > 0).then(|| made as f64 / frames as f64),
            pinches_by_finger: self.pinches_by_finger,
            saturation: if self.joint_values == 0 {
                0.0
            } else {
                self.saturated as f64 / self.joint_values as f64
            },
            jerk_rms: if self.jerk_terms == 0 {
                0.0
            } else {
                (self.jerk_sq / self.jerk_terms as f64).sqrt()
            },
            fingertip_jerk: Spread::of(&mut self.fingertip_jerk.clone()),
            fingertip_jerk_rms: rms(&self.fingertip_jerk),
            solve_us: Spread::of(&mut self.solve_us.clone()),
            iterations: Spread::of(&mut self.iterations.clone()),
        }
    }
}

/// Root mean square (0 for none).
fn rms(values: &[f64]) -> f64 {
    if values.is_empty() {
        0.0
    } else {
        (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
    }
}

/// The third derivative at four samples `x` separated by the intervals `h` (seconds): six times
/// their third divided difference (exact for a cubic, whatever the spacing).
fn third_derivative(h: [f64; 3], x: [f64; 4]) -> f64 {
    let t = [0.0, h[0], h[0] + h[1], h[0] + h[1] + h[2]];
    let first = |i: usize| (x[i + 1] - x[i]) / (t[i + 1] - t[i]);
    let second = |i: usize| (first(i + 1) - first(i)) / (t[i + 2] - t[i]);
    6.0 * (second(1) - second(0)) / (t[3] - t[0])
}

/// The closest the robot's thumb pad and the pad of the finger following operator finger
/// `finger` (`FINGERS` index) can come (surface gap, metres), over `samples` joint vectors
/// drawn evenly at random (a fixed seed) within the limits, and the share of those within
/// [`ROBOT_PINCH_M`]: how much of the hand's joint space can pinch that finger at all. `None`
/// when the hand has no such pair.
pub fn pinch_reach(profile: &HandProfile, finger: usize, samples: usize) -> Option<(f64, f64)> {
    let chains = Chains::new(profile);
    let follower = |g: usize| {
        profile
            .fingers
            .iter()
            .position(|f| f.operator.and_then(finger_of_glove_finger) == Some(g))
    };
    let (thumb, other) = (follower(0)?, follower(finger)?);
    let radii = chains.chains()[thumb].pad_radius + chains.chains()[other].pad_radius;
    let mut uniform = Uniform::new(0x9E37_79B9_7F4A_7C15);
    let mut q = vec![0.0; profile.joints.len()];
    let mut best = f64::INFINITY;
    let mut within = 0;
    for _ in 0..samples {
        for (j, joint) in profile.joints.iter().enumerate() {
            let (lo, hi) = (f64::from(joint.lower), f64::from(joint.upper));
            q[j] = lo + uniform.next() * (hi - lo);
        }
        for (j, joint) in profile.joints.iter().enumerate() {
            if let Some(c) = joint.coupling {
                q[j] = (f64::from(c.ratio) * q[c.to])
                    .clamp(f64::from(joint.lower), f64::from(joint.upper));
            }
        }
        let gap = chains.pad(thumb, &q).distance(chains.pad(other, &q)) - radii;
        best = best.min(gap);
        within += usize::from(gap < ROBOT_PINCH_M);
    }
    Some((best, within as f64 / samples.max(1) as f64))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_third_derivative_of_a_cubic_is_exact_on_uneven_stamps() {
        // x = 2 t^3 - t^2 + 3, whose third derivative is 12 everywhere.
        let at = |t: f64| 2.0 * t * t * t - t * t + 3.0;
        let h = [0.003, 0.0041, 0.0027];
        let t = [0.0, h[0], h[0] + h[1], h[0] + h[1] + h[2]];
        let jerk = third_derivative(h, t.map(at));
        assert!((jerk - 12.0).abs() < 1e-6, "{jerk}");
    }

    #[test]
    fn spreads_are_nearest_rank() {
        let s = Spread::of(&mut [5.0, 1.0, 3.0, 2.0, 4.0]);
        assert_eq!((s.count, s.p50, s.p95, s.max), (5, 3.0, 5.0, 5.0));
        assert_eq!(Spread::of(&mut []), Spread::default());
    }
}
