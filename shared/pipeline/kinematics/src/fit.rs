//! Fitting the operator's thumb to recorded pinches: the calibration's pinch step.
//!
//! The operator pinches the thumb to each long finger in turn; the glove records each pinch.
//! With the default hand those glove poses rarely make the model's pads meet (hands differ,
//! and so does how each operator's thumb sits in the glove), so [`fit_pinches`] adjusts a
//! small set of thumb parameters ([`ThumbParams`]) until each recorded pinch closes in the
//! model. The finger geometry stays: four pinches cannot tell a longer finger from a longer
//! thumb, and the thumb is what the glove measures worst (one flexion and one rotation
//! channel for three joints).
//!
//! The fit is Levenberg-Marquardt over the gaps (millimetres) with central-difference
//! derivatives, Tikhonov regularisation towards the starting hand (so parameters the pinches
//! do not determine stay where they were) and box bounds that keep the hand human
//! ([`ThumbParams::check`] states them). Pure and deterministic: the same samples give the same
//! hand.

use core::fmt;

use glam::Vec3;

use crate::{OperatorHand, OperatorPose, FINGERS};

/// Glove channels of one sample ([`OperatorPose::from_glove`]'s input).
const GLOVE_CHANNELS: usize = 6;

/// Number of fitted parameters.
const PARAMS: usize = 7;

/// One fitted parameter: its name, its unit, its human range and its scale (the change that
/// counts as one unit both for the regulariser and for the finite-difference step).
struct Param {
    name: &'static str,
    unit: &'static str,
    min: f64,
    max: f64,
    scale: f64,
}

impl Param {
    const fn new(
        name: &'static str,
        unit: &'static str,
        (min, max): (f64, f64),
        scale: f64,
    ) -> Self {
        Self {
            name,
            unit,
            min,
            max,
            scale,
        }
    }
}

/// The fitted parameters in [`ThumbParams::to_array`] order. The ranges are wide enough for
/// adult hands and a glove worn loose or tight, and narrow enough that the model stays a hand:
/// the thumb's CMC joint stays on the thumb side of the palm between the wrist and mid-palm,
/// the relaxed thumb points forward and out, opposition stays a rotation under the palm, and the
/// thumb's joint range (0.6 to 1.6 times) and length (0.75 to 1.3 times) stay near the hand's it
/// is applied to.
const PARAMS_TABLE: [Param; PARAMS] = [
    Param::new("thumb base x", "mm", (-50.0, -5.0), 10.0),
    Param::new("thumb base y", "mm", (0.0, 50.0), 10.0),
    Param::new("thumb base z", "mm", (-35.0, 10.0), 10.0),
    Param::new("thumb direction", "deg", (10.0, 65.0), 10.0),
    Param::new("opposition", "deg", (40.0, 120.0), 10.0),
    Param::new("thumb flexion scale", "", (0.6, 1.6), 0.1),
    Param::new("thumb length scale", "", (0.75, 1.3), 0.1),
];

/// Weight of the regulariser: a change of one parameter scale (10 mm of thumb base, 10 degrees,
/// a tenth of a scale) costs as much as a 0.1 mm gap, so the pinches decide wherever they can
/// and the start holds only what they leave open.
const REGULARISATION: f64 = 0.1;

/// Finite-difference step, in parameter scales (0.01 mm of base, 0.01 degrees): large enough
/// that the `f32` model's rounding (about 1e-8 m at hand size) is a thousandth of the change.
const DIFF_STEP: f64 = 1e-3;

/// Most Levenberg-Marquardt iterations; the fit converges in far fewer (8 to 14 in the tests).
const MAX_ITERATIONS: usize = 100;

/// Largest damping tried before giving up on a better step (the start is then a minimum to
/// the model's precision).
const MAX_DAMPING: f64 = 1e10;

/// The thumb parameters the pinch fit adjusts, in the units people read (millimetres,
/// degrees), relative to the hand they are applied to ([`apply`](Self::apply)): the position,
/// direction and opposition are absolute, the two scales multiply that hand's thumb joint range
/// and lengths.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThumbParams {
    /// The thumb's CMC joint, hand frame, millimetres ([`crate::ThumbGeometry::base`]).
    pub base_mm: [f32; 3],
    /// The relaxed thumb's direction in the palm plane: degrees from +Y (the fingers) towards
    /// -X (the thumb side); [`crate::ThumbGeometry::direction`] is the unit vector
    /// `(-sin, cos, 0)`.
    pub direction_deg: f32,
    /// [`OperatorHand::opposition_rad`], in degrees.
    pub opposition_deg: f32,
    /// Multiplies [`OperatorHand::thumb_fist_rad`] (all three joints).
    pub flexion_scale: f32,
    /// Multiplies the thumb's three segment lengths.
    pub length_scale: f32,
}

impl ThumbParams {
    /// The parameters that leave `hand` as it is (scales 1).
    pub fn of(hand: &OperatorHand) -> Self {
        let d = hand.thumb.direction;
        let base = hand.thumb.base;
        Self::from_array([
            f64::from(base.x) * 1000.0,
            f64::from(base.y) * 1000.0,
            f64::from(base.z) * 1000.0,
            f64::from((-d.x).atan2(d.y)).to_degrees(),
            f64::from(hand.opposition_rad).to_degrees(),
            1.0,
            1.0,
        ])
    }

    /// `hand` with these parameters; its fingers and pads stay.
    pub fn apply(&self, hand: &OperatorHand) -> OperatorHand {
        let p = self.to_array();
        let mut out = hand.clone();
        out.thumb.base = Vec3::new(
            (p[0] / 1000.0) as f32,
            (p[1] / 1000.0) as f32,
            (p[2] / 1000.0) as f32,
        );
        let (sin, cos) = p[3].to_radians().sin_cos();
        out.thumb.direction = Vec3::new(-sin as f32, cos as f32, 0.0);
        out.opposition_rad = p[4].to_radians() as f32;
        out.thumb_fist_rad = hand.thumb_fist_rad.map(|a| a * self.flexion_scale);
        out.thumb.lengths = hand.thumb.lengths.map(|l| l * self.length_scale);
        out
    }

    /// Checks every parameter is finite and within the human range the fit keeps to:
    /// thumb base x -50..-5 mm, y 0..50 mm, z -35..10 mm; direction 10..65 degrees;
    /// opposition 40..120 degrees; flexion scale 0.6..1.6; length scale 0.75..1.3.
    pub fn check(&self) -> Result<(), FitError> {
        for (value, param) in self.to_array().into_iter().zip(&PARAMS_TABLE) {
            // Written so that NaN fails too.
            if !(value >= param.min && value <= param.max) {
                return Err(FitError::OutOfRange {
                    parameter: param.name,
                    value,
                    min: param.min,
                    max: param.max,
                    unit: param.unit,
                });
            }
        }
        Ok(())
    }

    /// The parameters as one vector, in [`PARAMS_TABLE`] order and units.
    fn to_array(self) -> [f64; PARAMS] {
        let [x, y, z] = self.base_mm;
        [
            x,
            y,
            z,
            self.direction_deg,
            self.opposition_deg,
            self.flexion_scale,
            self.length_scale,
        ]
        .map(f64::from)
    }

    fn from_array(p: [f64; PARAMS]) -> Self {
        let p = p.map(|v| v as f32);
        Self {
            base_mm: [p[0], p[1], p[2]],
            direction_deg: p[3],
            opposition_deg: p[4],
            flexion_scale: p[5],
            length_scale: p[6],
        }
    }
}

/// One recorded pinch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinchSample {
    /// The finger the thumb pinches ([`FINGERS`] index: 1 = index .. 4 = little).
    pub finger: usize,
    /// The glove's normalised positions while pinching ([`OperatorPose::from_glove`]).
    pub glove: [f32; GLOVE_CHANNELS],
}

/// One pinch's thumb-finger pad gap before and after the fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinchGap {
    /// [`PinchSample::finger`].
    pub finger: usize,
    /// With the starting hand, millimetres (negative: the pads overlap).
    pub before_mm: f32,
    /// With the fitted hand, millimetres.
    pub after_mm: f32,
}

/// What [`fit_pinches`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct PinchFit {
    /// The starting hand with the fitted thumb.
    pub hand: OperatorHand,
    /// The fitted parameters, relative to the starting hand.
    pub params: ThumbParams,
    /// Per sample, in the samples' order.
    pub gaps: Vec<PinchGap>,
    /// Levenberg-Marquardt iterations run.
    pub iterations: usize,
}

/// Why a pinch fit, or a parameter set, was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FitError {
    /// No pinch was given.
    NoSamples,
    /// A sample names no long finger.
    NotAFinger {
        /// Index of the sample.
        sample: usize,
        /// The finger it names.
        finger: usize,
    },
    /// A sample's glove value is NaN or infinite.
    NonFiniteSample {
        /// Index of the sample.
        sample: usize,
        /// The glove channel.
        channel: usize,
    },
    /// The starting hand's thumb parameters or geometry are not finite.
    NonFiniteStart,
    /// A parameter is outside the human range ([`ThumbParams::check`]).
    OutOfRange {
        /// Which parameter, e.g. `thumb base x`.
        parameter: &'static str,
        /// Its value, in `unit`.
        value: f64,
        /// The smallest accepted value, in `unit`.
        min: f64,
        /// The largest accepted value, in `unit`.
        max: f64,
        /// The unit (`mm`, `deg`; empty for a ratio).
        unit: &'static str,
    },
}

impl fmt::Display for FitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            FitError::NoSamples => write!(f, "no pinch samples to fit"),
            FitError::NotAFinger { sample, finger } => write!(
                f,
                "pinch sample {sample}: finger {finger} is not a long finger (1 = index .. 4 = little)"
            ),
            FitError::NonFiniteSample { sample, channel } => write!(
                f,
                "pinch sample {sample}: glove channel {channel} is not a finite number"
            ),
            FitError::NonFiniteStart => {
                write!(f, "the starting hand's thumb is not finite")
            }
            FitError::OutOfRange {
                parameter,
                value,
                min,
                max,
                unit,
            } => {
                // "12.00 mm", but a ratio bare: "1.70".
                let space = if unit.is_empty() { "" } else { " " };
                write!(
                    f,
                    "{parameter} ({value:.2}{space}{unit}) is outside the human range \
                     {min}..{max}{space}{unit}"
                )
            }
        }
    }
}

impl std::error::Error for FitError {}

/// Fits the thumb of `start` so that each sample's thumb and finger pads meet
/// ([`OperatorHand::pad_gap`] 0), as described in the [module docs](self). Errors: no
/// samples, a sample naming no long finger, a non-finite glove value or a non-finite start.
/// A start outside the human range is first clamped into it.
pub fn fit_pinches(start: &OperatorHand, samples: &[PinchSample]) -> Result<PinchFit, FitError> {
    if samples.is_empty() {
        return Err(FitError::NoSamples);
    }
    for (sample, s) in samples.iter().enumerate() {
        if !(1..FINGERS.len()).contains(&s.finger) {
            return Err(FitError::NotAFinger {
                sample,
                finger: s.finger,
            });
        }
        if let Some(channel) = s.glove.iter().position(|v| !v.is_finite()) {
            return Err(FitError::NonFiniteSample { sample, channel });
        }
    }
    let p_start = ThumbParams::of(start).to_array();
    let thumb_finite = start.thumb.lengths.iter().all(|l| l.is_finite())
        && start.thumb_fist_rad.iter().all(|a| a.is_finite());
    if !thumb_finite || p_start.iter().any(|p| !p.is_finite()) {
        return Err(FitError::NonFiniteStart);
    }
    let problem = Problem {
        start,
        poses: samples
            .iter()
            .map(|s| (s.finger, OperatorPose::from_glove(&s.glove)))
            .collect(),
        origin: core::array::from_fn(|k| {
            p_start[k].clamp(PARAMS_TABLE[k].min, PARAMS_TABLE[k].max)
        }),
    };
    let before: Vec<f64> = problem
        .poses
        .iter()
        .map(|(finger, pose)| gap_mm(start, pose, *finger))
        .collect();
    let (u, iterations) = problem.solve();
    let params = ThumbParams::from_array(problem.params(&u));
    let hand = params.apply(start);
    let gaps = problem
        .poses
        .iter()
        .zip(before)
        .map(|((finger, pose), before)| PinchGap {
            finger: *finger,
            before_mm: before as f32,
            after_mm: gap_mm(&hand, pose, *finger) as f32,
        })
        .collect();
    Ok(PinchFit {
        hand,
        params,
        gaps,
        iterations,
    })
}

/// The thumb-`finger` pad gap of `hand` in `pose`, millimetres.
fn gap_mm(hand: &OperatorHand, pose: &OperatorPose, finger: usize) -> f64 {
    f64::from(hand.pad_gap(pose, 0, finger)) * 1000.0
}

/// The least-squares problem in scaled coordinates `u`: parameter `k` is
/// `origin[k] + u[k] * scale[k]`.
struct Problem<'a> {
    start: &'a OperatorHand,
    poses: Vec<(usize, OperatorPose)>,
    /// The start's parameters, clamped into the human range: the regulariser's target.
    origin: [f64; PARAMS],
}

impl Problem<'_> {
    fn params(&self, u: &[f64; PARAMS]) -> [f64; PARAMS] {
        core::array::from_fn(|k| self.origin[k] + u[k] * PARAMS_TABLE[k].scale)
    }

    /// `u` moved into the bounds.
    fn project(&self, u: [f64; PARAMS]) -> [f64; PARAMS] {
        core::array::from_fn(|k| {
            let p = &PARAMS_TABLE[k];
            u[k].clamp(
                (p.min - self.origin[k]) / p.scale,
                (p.max - self.origin[k]) / p.scale,
            )
        })
    }

    /// The pinch gaps (mm) at `u`.
    fn gaps(&self, u: &[f64; PARAMS]) -> Vec<f64> {
        let hand = ThumbParams::from_array(self.params(u)).apply(self.start);
        self.poses
            .iter()
            .map(|(finger, pose)| gap_mm(&hand, pose, *finger))
            .collect()
    }

    /// The objective: squared gaps plus the regulariser.
    fn cost(&self, u: &[f64; PARAMS]) -> f64 {
        let gaps: f64 = self.gaps(u).iter().map(|g| g * g).sum();
        gaps + REGULARISATION * REGULARISATION * u.iter().map(|x| x * x).sum::<f64>()
    }

    /// Levenberg-Marquardt (Marquardt's diagonal scaling) from `u = 0`, projected onto the
    /// bounds: the solution and the iterations run.
    fn solve(&self) -> ([f64; PARAMS], usize) {
        let mut u = [0.0; PARAMS];
        let mut cost = self.cost(&u);
        let mut damping = 1e-3;
        let mut iterations = 0;
        while iterations < MAX_ITERATIONS {
            iterations += 1;
            let (normal, gradient) = self.normal_equations(&u);
            let mut improved = None;
            while damping <= MAX_DAMPING {
                let mut a = normal;
                for (k, row) in a.iter_mut().enumerate() {
                    row[k] += damping * normal[k][k];
                }
                let step = solve_spd(a, gradient.map(|g| -g));
                if let Some(step) = step {
                    let next = self.project(core::array::from_fn(|k| u[k] + step[k]));
                    let next_cost = self.cost(&next);
                    if next_cost < cost {
                        improved = Some((next, next_cost));
                        damping = (damping / 3.0).max(1e-9);
                        break;
                    }
                }
                damping *= 4.0;
            }
            let Some((next, next_cost)) = improved else {
                break;
            };
            let moved = next
                .iter()
                .zip(&u)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            let gain = cost - next_cost;
            u = next;
            cost = next_cost;
            // Converged: the step is below the derivatives' resolution or the cost stopped
            // falling (1e-12 mm^2 is far below the model's f32 precision).
            if moved < DIFF_STEP * 1e-3 || gain < 1e-12 {
                break;
            }
        }
        (u, iterations)
    }

    /// `J^T J` and `J^T r` of the residuals (gaps, then the regulariser's rows) at `u`, the
    /// gaps' Jacobian by central differences.
    fn normal_equations(&self, u: &[f64; PARAMS]) -> ([[f64; PARAMS]; PARAMS], [f64; PARAMS]) {
        let r = self.gaps(u);
        let mut jacobian = vec![[0.0; PARAMS]; r.len()];
        for k in 0..PARAMS {
            let mut plus = *u;
            let mut minus = *u;
            plus[k] += DIFF_STEP;
            minus[k] -= DIFF_STEP;
            for (row, (p, m)) in jacobian
                .iter_mut()
                .zip(self.gaps(&plus).into_iter().zip(self.gaps(&minus)))
            {
                row[k] = (p - m) / (2.0 * DIFF_STEP);
            }
        }
        let reg = REGULARISATION * REGULARISATION;
        let mut normal = [[0.0; PARAMS]; PARAMS];
        let mut gradient = [0.0; PARAMS];
        for i in 0..PARAMS {
            for j in 0..PARAMS {
                normal[i][j] = jacobian.iter().map(|row| row[i] * row[j]).sum();
            }
            normal[i][i] += reg;
            gradient[i] = jacobian
                .iter()
                .zip(&r)
                .map(|(row, ri)| row[i] * ri)
                .sum::<f64>()
                + reg * u[i];
        }
        (normal, gradient)
    }
}

/// Solves `a x = b` for a symmetric positive definite `a` by Cholesky decomposition; `None`
/// when `a` is not positive definite (to working precision).
fn solve_spd(a: [[f64; PARAMS]; PARAMS], b: [f64; PARAMS]) -> Option<[f64; PARAMS]> {
    let mut l = [[0.0; PARAMS]; PARAMS];
    for i in 0..PARAMS {
        for j in 0..=i {
            let s = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if s.is_nan() || s <= 0.0 {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut y = [0.0; PARAMS];
    for i in 0..PARAMS {
        y[i] = (b[i] - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
    }
    let mut x = [0.0; PARAMS];
    for i in (0..PARAMS).rev() {
        x[i] = (y[i] - (i + 1..PARAMS).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
    }
    Some(x)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::{GLOVE_CHANNEL_OF_FINGER, GLOVE_THUMB_ROTATION};

    /// The glove vector of `pose` (other fingers open).
    fn glove_of(pose: &OperatorPose) -> [f32; GLOVE_CHANNELS] {
        let mut glove = [1.0; GLOVE_CHANNELS];
        for (finger, &channel) in GLOVE_CHANNEL_OF_FINGER.iter().enumerate() {
            glove[channel] = 1.0 - pose.flexion[finger];
        }
        glove[GLOVE_THUMB_ROTATION] = 1.0 - pose.thumb_opposition;
        glove
    }

    /// A pinch of `hand`'s thumb and `finger` with that finger's flexion and the thumb's
    /// opposition given: the thumb flexion at which the pads first touch as the thumb closes
    /// (a scan, then bisection to 1e-6), if they touch at all.
    fn pinch(
        hand: &OperatorHand,
        finger: usize,
        finger_flexion: f32,
        opposition: f32,
    ) -> Option<PinchSample> {
        let pose = |thumb: f32| {
            let mut p = OperatorPose {
                thumb_opposition: opposition,
                ..Default::default()
            };
            p.flexion[finger] = finger_flexion;
            p.flexion[0] = thumb;
            p
        };
        let gap = |thumb: f32| hand.pad_gap(&pose(thumb), 0, finger);
        let steps = 50;
        let (mut lo, mut hi) = (0..steps).map(|i| i as f32 / steps as f32).find_map(|t| {
            let next = t + 1.0 / steps as f32;
            (gap(t) > 0.0 && gap(next) <= 0.0).then_some((t, next))
        })?;
        while hi - lo > 1e-6 {
            let mid = 0.5 * (lo + hi);
            if gap(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(PinchSample {
            finger,
            glove: glove_of(&pose(hi)),
        })
    }

    /// A pinch of `hand`'s thumb and `finger`: of the (finger flexion, opposition) pairs on a
    /// grid where the pads meet, the nearest to a typical pinch of that finger (the further
    /// the finger, the more it bends and the more the thumb turns in).
    fn typical_pinch(hand: &OperatorHand, finger: usize) -> Option<PinchSample> {
        let (flexion, opposition) = [(0.67, 0.6), (0.7, 0.8), (0.76, 0.9), (0.76, 1.0)][finger - 1];
        let distance = |f: f32, o: f32| (f - flexion).hypot(o - opposition);
        (0..=15)
            .flat_map(|i| (0..=10).map(move |j| (0.4 + 0.04 * i as f32, 0.1 * j as f32)))
            .filter_map(|(f, o)| Some((distance(f, o), pinch(hand, finger, f, o)?)))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, sample)| sample)
    }

    /// One typical pinch per long finger.
    fn pinches(hand: &OperatorHand) -> Vec<PinchSample> {
        (1..FINGERS.len())
            .map(|finger| typical_pinch(hand, finger).unwrap())
            .collect()
    }

    /// The parameters' largest change in scales (10 mm, 10 degrees, 0.1).
    fn change(a: &ThumbParams, b: &ThumbParams) -> f64 {
        let (a, b) = (a.to_array(), b.to_array());
        (0..PARAMS)
            .map(|k| (a[k] - b[k]).abs() / PARAMS_TABLE[k].scale)
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_fit_from_the_default_hand_closes_the_pinches_of_another_hand() {
        let default = OperatorHand::default();
        // Another operator: the thumb's CMC 8 mm further towards the fingers, opposition 10
        // degrees more.
        let mut truth = ThumbParams::of(&default);
        truth.base_mm[1] += 8.0;
        truth.opposition_deg += 10.0;
        let true_hand = truth.apply(&default);
        let samples = pinches(&true_hand);
        for s in &samples {
            let pose = OperatorPose::from_glove(&s.glove);
            assert!(true_hand.pad_gap(&pose, 0, s.finger).abs() < 1e-5);
        }

        let fit = fit_pinches(&default, &samples).unwrap();
        for g in &fit.gaps {
            assert!(g.after_mm.abs() < 1.0, "{g:?}");
        }
        // The default hand misses these pinches (by 0.6 to 4.9 mm), so the fit had work to do.
        let missed = fit
            .gaps
            .iter()
            .map(|g| g.before_mm.abs())
            .fold(0.0, f32::max);
        assert!(missed > 3.0, "{:?}", fit.gaps);
        assert!(fit.iterations < MAX_ITERATIONS, "{}", fit.iterations);
        fit.params.check().unwrap();
        assert_eq!(fit.hand, fit.params.apply(&default));
        // The fingers stay.
        assert_eq!(fit.hand.fingers, default.fingers);
        assert_eq!(fit.hand.finger_fist_rad, default.finger_fist_rad);
        // Deterministic.
        assert_eq!(fit_pinches(&default, &samples).unwrap(), fit);
    }

    #[test]
    fn the_default_hand_keeps_its_parameters_on_its_own_pinches() {
        let default = OperatorHand::default();
        let samples = pinches(&default);
        let fit = fit_pinches(&default, &samples).unwrap();
        let change = change(&fit.params, &ThumbParams::of(&default));
        assert!(change < 1e-3, "{change} {:?}", fit.params);
        for g in &fit.gaps {
            assert!(g.after_mm.abs() < 0.01, "{g:?}");
        }
    }

    #[test]
    fn one_pinch_moves_the_hand_little() {
        // One equation, seven unknowns: the regulariser picks the smallest change that
        // closes it, instead of wandering to a bound.
        let default = OperatorHand::default();
        let mut truth = ThumbParams::of(&default);
        truth.base_mm[1] += 8.0;
        let samples = [typical_pinch(&truth.apply(&default), 1).unwrap()];
        let fit = fit_pinches(&default, &samples).unwrap();
        assert!(fit.gaps[0].before_mm.abs() > 2.0, "{:?}", fit.gaps);
        assert!(fit.gaps[0].after_mm.abs() < 0.1, "{:?}", fit.gaps);
        let change = change(&fit.params, &ThumbParams::of(&default));
        assert!(change < 0.8, "{change} {:?}", fit.params);
    }

    #[test]
    fn bad_input_is_an_error() {
        let default = OperatorHand::default();
        let good = pinches(&default);
        assert_eq!(fit_pinches(&default, &[]), Err(FitError::NoSamples));
        for bad in [f32::NAN, f32::INFINITY] {
            let mut samples = good.clone();
            samples[2].glove[5] = bad;
            assert_eq!(
                fit_pinches(&default, &samples),
                Err(FitError::NonFiniteSample {
                    sample: 2,
                    channel: 5
                })
            );
        }
        let mut samples = good.clone();
        samples[0].finger = 0;
        assert_eq!(
            fit_pinches(&default, &samples),
            Err(FitError::NotAFinger {
                sample: 0,
                finger: 0
            })
        );
        let mut start = default.clone();
        start.thumb.base.y = f32::NAN;
        assert_eq!(fit_pinches(&start, &good), Err(FitError::NonFiniteStart));
        start = default.clone();
        start.thumb.lengths[1] = f32::INFINITY;
        assert_eq!(fit_pinches(&start, &good), Err(FitError::NonFiniteStart));
    }

    #[test]
    fn a_start_outside_the_range_is_brought_into_it() {
        let default = OperatorHand::default();
        let mut wide = ThumbParams::of(&default);
        wide.opposition_deg = 170.0;
        let fit = fit_pinches(&wide.apply(&default), &pinches(&default)).unwrap();
        fit.params.check().unwrap();
    }

    #[test]
    fn check_names_the_parameter_out_of_range() {
        let default = OperatorHand::default();
        ThumbParams::of(&default).check().unwrap();
        let mut p = ThumbParams::of(&default);
        p.base_mm[2] = 20.0;
        assert_eq!(
            p.check().unwrap_err().to_string(),
            "thumb base z (20.00 mm) is outside the human range -35..10 mm"
        );
        p = ThumbParams::of(&default);
        p.length_scale = f32::NAN;
        let err = p.check().unwrap_err().to_string();
        assert!(err.starts_with("thumb length scale (NaN)"), "{err}");
    }

    #[test]
    fn of_then_apply_is_the_hand() {
        let default = OperatorHand::default();
        let again = ThumbParams::of(&default).apply(&default);
        assert!(again
            .thumb
            .direction
            .abs_diff_eq(default.thumb.direction, 1e-6));
        assert_eq!(again.thumb.base, default.thumb.base);
        assert_eq!(again.thumb.lengths, default.thumb.lengths);
        assert_eq!(again.thumb_fist_rad, default.thumb_fist_rad);
        assert_eq!(again.opposition_rad, default.opposition_rad);
    }
}
