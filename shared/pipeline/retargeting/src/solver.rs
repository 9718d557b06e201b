//! Fingertip retargeting: the robot's joint angles whose fingertip vectors best match the
//! operator's, DexPilot's objective (Handa et al. 2020, as dex-retargeting's `DexPilotOptimizer`
//! 0.5.0 implements it) solved by projected Gauss-Newton in Rust.
//!
//! # The objective
//!
//! The fingertips are the pads of the profile's fingers that follow an operator finger, thumb
//! first, then index, middle, ring, little (the operator's order). The vectors are, in
//! DexPilot's order, every finger pair (from the later finger to the earlier; the first
//! `n - 1` are finger-to-thumb) and then the wrist (the hand frame's origin) to each fingertip.
//! Each vector's target is the operator model's same vector times `scaling`, and its error
//! costs `weight × huber(|robot − target|)` (quadratic below `huber_delta`, linear above),
//! averaged over the vectors; wrist vectors weigh `pairs + fingers`, pairs 1. Moving away from
//! the previous solution costs `smoothness × |Δq|²`, and being away from the middle of the
//! joints' ranges `posture × |q − mid|²` (not in DexPilot): a weak pull that settles the joints a
//! redundant finger leaves free (so a difference in history fades instead of staying) and keeps
//! them off the hard stops.
//!
//! In `pinch` mode a thumb-finger pair whose operator pads come closer than `pinch_engage`
//! switches to a pinch (until they part beyond `pinch_release`): its target becomes the
//! operator's direction at length `pinch_gap` between the robot's pad surfaces (their radii
//! added; centres with `pad_contact = false`, as DexPilot), weight `pinch_weight`. Two fingers
//! both pinched and closer than 3 cm are held `finger_gap` apart, weight `finger_gap_weight`.
//!
//! # The solver
//!
//! Variables: the joints of the retargeted fingers that no other joint drives (a coupled joint
//! follows its leader, and the leader's Jacobian column carries it); wrist joints are not
//! solved. Each iteration linearises the vectors with the chains' analytic Jacobians, weighs
//! each vector by the Huber loss's curvature (iteratively reweighted least squares), adds the
//! smoothness term and a Levenberg damping, and solves the normal equations by Cholesky with the
//! joints held at a limit they push against removed (an active set), then clamps to the limits.
//! A step is kept only when the objective falls. It starts from the previous solution (warm
//! start) and stops when a step moves no joint by more than 1e-7 rad, gains less than 1e-4 of
//! the objective, or after `max_iterations`; restarts (see [`Solver::solve`]) run a few
//! iterations. The first solve, and the first after [`Solver::reset`], starts from the open hand
//! and converges without the smoothness term: an operator holding still at the start gives the
//! same solutions however many samples came before (a recording that starts a little after the
//! node reprocesses to its commands). Fixed-size arrays throughout: a solve allocates nothing
//! and, for the same inputs in the same order, gives bit-identical results.

// Vectors, joints and fingertips are parallel fixed-size arrays indexed together, as the
// formulas in the docs write them.
#![allow(clippy::needless_range_loop)]

use glam::{DVec3, Vec3};
use teleop_hand_profile::{HandProfile, Role, MAX_JOINTS};
use teleop_kinematics::{finger_of_glove_finger, Chains};

use crate::config::FingertipConfig;

/// Most retargeted fingertips.
const MAX_TIPS: usize = 5;
/// Most vectors: every pair of five fingertips and the wrist to each.
pub const MAX_VECTORS: usize = MAX_TIPS * (MAX_TIPS - 1) / 2 + MAX_TIPS;
/// DexPilot keeps two pinched fingers apart only when the operator's are closer than this.
const FINGER_GAP_BELOW_M: f64 = 0.03;
/// A pinched pair whose pads are farther apart than this after the warm start is restarted from
/// where it meets, metres.
const PINCH_OPEN_M: f64 = 0.005;
/// Most iterations of a first solve.
const FRESH_ITERATIONS: u32 = 200;
/// Most iterations of a restarted descent: enough to show a better branch, which the next
/// frames' warm starts then follow.
const RESTART_ITERATIONS: u32 = 6;
/// Joint vectors sampled per thumb pair for its pinch restart.
const PINCH_SEED_SAMPLES: usize = 4000;
/// A step that lowers the objective by less than this share of it ends the descent
/// (dex-retargeting stops nlopt at an absolute change of 1e-6).
const COST_TOLERANCE: f64 = 1e-4;
/// A step that moves no joint by more than this (radians) ends the solve.
const STEP_TOLERANCE_RAD: f64 = 1e-7;

/// What the last solve did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SolveReport {
    /// Gauss-Newton iterations (tried steps).
    pub iterations: u32,
    /// The objective's vector part (the weighted Huber sum, without the smoothness term), as
    /// dex-retargeting's optimizer reports it.
    pub objective: f64,
    /// Per fingertip after the thumb (index, middle, ...): the pinch switch is on.
    pub pinched: [bool; MAX_TIPS - 1],
}

/// One vector: from `origin` (a fingertip slot, or the wrist) to `task` (a fingertip slot).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct VectorDef {
    origin: Option<usize>,
    task: usize,
}

/// The fingertip solver of one hand profile (see the module docs).
#[derive(Debug, Clone)]
pub struct Solver {
    chains: Chains,
    params: FingertipConfig,
    scaling: f64,
    pinch: bool,
    /// Per fingertip slot: the chain (profile finger) and the operator finger (`FINGERS`
    /// index: thumb 0 .. little 4).
    tip_chain: [usize; MAX_TIPS],
    tip_operator: [usize; MAX_TIPS],
    /// Pad radius per slot, metres.
    tip_radius: [f64; MAX_TIPS],
    tips: usize,
    /// Thumb-finger pairs (the first vectors) when slot 0 is a thumb, else 0.
    thumb_pairs: usize,
    /// All pairs.
    pairs: usize,
    vectors: [VectorDef; MAX_VECTORS],
    n_vectors: usize,
    /// Solved joints.
    vars: [usize; MAX_JOINTS],
    n_vars: usize,
    /// Per joint: the variable it moves with and by how much (1 for the variable itself, the
    /// coupling ratio for a follower); `None` for a joint the solver leaves alone.
    moves_with: [Option<(usize, f64)>; MAX_JOINTS],
    lower: [f64; MAX_JOINTS],
    upper: [f64; MAX_JOINTS],
    joints: usize,
    /// Per variable: the middle of its range, where the posture term pulls.
    rest: [f64; MAX_JOINTS],
    /// Per variable: its profile finger.
    var_finger: [usize; MAX_JOINTS],
    /// Per fingertip slot: the variables that move its pad.
    slot_vars: [[usize; MAX_JOINTS]; MAX_TIPS],
    slot_var_count: [usize; MAX_TIPS],
    /// The current solution (radians, every joint; unsolved joints at their `open` angle).
    q: [f64; MAX_JOINTS],
    /// The pinch switch per vector.
    projected: [bool; MAX_VECTORS],
    /// No solve since construction or [`Solver::reset`].
    fresh: bool,
    /// Where the first solve starts: every joint at its `open` angle.
    initial: [f64; MAX_JOINTS],
    report: SolveReport,
    /// The last solve's targets.
    last_targets: Targets,
    /// Per thumb pair: variables where the two pads come closest (a restart for a pinch), and
    /// which variables belong to the pair's two fingers.
    pinch_seed: [[f64; MAX_JOINTS]; MAX_TIPS - 1],
    pinch_seed_moves: [[bool; MAX_JOINTS]; MAX_TIPS - 1],
}

/// Per-solve data: the vectors' targets and weights.
#[derive(Debug, Clone)]
struct Targets {
    reference: [DVec3; MAX_VECTORS],
    weight: [f64; MAX_VECTORS],
}

impl Solver {
    /// The solver for `profile`, over its joints' limits, narrowed where `narrowed` (radians,
    /// per joint; missing entries: none) says: `pinch` turns the pinch switch on (mode
    /// `pinch`). `None` when no finger of the profile follows an operator finger.
    pub fn new(
        profile: &HandProfile,
        params: FingertipConfig,
        pinch: bool,
        narrowed: &[Option<(f32, f32)>],
    ) -> Option<Self> {
        let chains = Chains::new(profile);
        // Fingertip slots in the operator's order (thumb first).
        let mut slots: Vec<(usize, usize)> = profile
            .fingers
            .iter()
            .enumerate()
            .filter_map(|(f, finger)| {
                let operator = finger.operator.and_then(finger_of_glove_finger)?;
                Some((operator, f))
            })
            .take(MAX_TIPS)
            .collect();
        slots.sort_unstable();
        if slots.is_empty() {
            return None;
        }
        let mut tip_chain = [0; MAX_TIPS];
        let mut tip_operator = [0; MAX_TIPS];
        let mut tip_radius = [0.0; MAX_TIPS];
        for (s, &(operator, f)) in slots.iter().enumerate() {
            tip_chain[s] = f;
            tip_operator[s] = operator;
            tip_radius[s] = chains.chains()[f].pad_radius;
        }
        let tips = slots.len();
        // DexPilot's order (generate_link_indices): pairs (later -> earlier), then the wrist.
        let mut vectors = [VectorDef::default(); MAX_VECTORS];
        let mut n = 0;
        for task in 0..tips.saturating_sub(1) {
            for origin in task + 1..tips {
                vectors[n] = VectorDef {
                    origin: Some(origin),
                    task,
                };
                n += 1;
            }
        }
        let pairs = n;
        for task in 0..tips {
            vectors[n] = VectorDef { origin: None, task };
            n += 1;
        }
        let thumb_pairs = if tip_operator[0] == 0 { tips - 1 } else { 0 };

        let count = profile.joints.len().min(MAX_JOINTS);
        let mut lower = [0.0; MAX_JOINTS];
        let mut upper = [0.0; MAX_JOINTS];
        let mut q = [0.0; MAX_JOINTS];
        for (j, joint) in profile.joints.iter().take(count).enumerate() {
            let (lo, hi) = narrowed
                .get(j)
                .copied()
                .flatten()
                .unwrap_or((joint.lower, joint.upper));
            lower[j] = f64::from(lo.max(joint.lower));
            upper[j] = f64::from(hi.min(joint.upper)).max(lower[j]);
            q[j] = f64::from(joint.open).clamp(lower[j], upper[j]);
        }
        let retargeted = |f: usize| slots.iter().any(|&(_, g)| g == f);
        let mut vars = [0; MAX_JOINTS];
        let mut n_vars = 0;
        let mut moves_with = [None; MAX_JOINTS];
        for (j, joint) in profile.joints.iter().take(count).enumerate() {
            if joint.coupling.is_none() && joint.role != Role::Wrist && retargeted(joint.finger) {
                moves_with[j] = Some((n_vars, 1.0));
                vars[n_vars] = j;
                n_vars += 1;
            }
        }
        for (j, joint) in profile.joints.iter().take(count).enumerate() {
            if let Some(c) = joint.coupling {
                if let Some(Some((v, _))) = moves_with.get(c.to) {
                    moves_with[j] = Some((*v, f64::from(c.ratio)));
                }
            }
        }
        let scaling = f64::from(params.scaling.unwrap_or(profile.retarget.scaling));
        let mut rest = [0.0; MAX_JOINTS];
        let mut var_finger = [0; MAX_JOINTS];
        for v in 0..n_vars {
            rest[v] = 0.5 * (lower[vars[v]] + upper[vars[v]]);
            var_finger[v] = profile.joints[vars[v]].finger;
        }
        // The variables that move each slot's pad: those of the joints on its chain.
        let mut slot_vars = [[0; MAX_JOINTS]; MAX_TIPS];
        let mut slot_var_count = [0; MAX_TIPS];
        for s in 0..tips {
            for link in &profile.fingers[tip_chain[s]].links {
                let Some((v, _)) = link
                    .joint
                    .and_then(|j| moves_with.get(j).copied().flatten())
                else {
                    continue;
                };
                if !slot_vars[s][..slot_var_count[s]].contains(&v) {
                    slot_vars[s][slot_var_count[s]] = v;
                    slot_var_count[s] += 1;
                }
            }
        }
        let mut solver = Self {
            chains,
            params,
            scaling,
            pinch,
            tip_chain,
            tip_operator,
            tip_radius,
            tips,
            thumb_pairs,
            pairs,
            vectors,
            n_vectors: n,
            vars,
            n_vars,
            moves_with,
            lower,
            upper,
            joints: count,
            rest,
            var_finger,
            slot_vars,
            slot_var_count,
            q,
            projected: [false; MAX_VECTORS],
            fresh: true,
            initial: q,
            report: SolveReport::default(),
            last_targets: Targets {
                reference: [DVec3::ZERO; MAX_VECTORS],
                weight: [0.0; MAX_VECTORS],
            },
            pinch_seed: [[0.0; MAX_JOINTS]; MAX_TIPS - 1],
            pinch_seed_moves: [[false; MAX_JOINTS]; MAX_TIPS - 1],
        };
        solver.find_pinch_seeds(profile);
        Some(solver)
    }

    /// For each thumb pair, the sampled joint vector (of that pair's two fingers, within the
    /// solver's limits, [`PINCH_SEED_SAMPLES`] from a fixed seed) whose pads come closest.
    fn find_pinch_seeds(&mut self, profile: &HandProfile) {
        for k in 0..self.thumb_pairs {
            let (thumb, other) = (self.tip_chain[0], self.tip_chain[k + 1]);
            // Measured as the pinch target measures it (see `pair_gap`).
            let radii = if self.params.pad_contact {
                self.tip_radius[0] + self.tip_radius[k + 1]
            } else {
                0.0
            };
            let mut moves = [false; MAX_JOINTS];
            for v in 0..self.n_vars {
                let finger = profile.joints[self.vars[v]].finger;
                moves[v] = finger == thumb || finger == other;
            }
            let mut uniform = Uniform::new(0x9E37_79B9_7F4A_7C15 ^ k as u64);
            let mut x = [0.0; MAX_JOINTS];
            let mut q = self.q;
            let mut best = (f64::INFINITY, x);
            for _ in 0..PINCH_SEED_SAMPLES {
                for v in 0..self.n_vars {
                    let j = self.vars[v];
                    x[v] = self.lower[j] + uniform.next() * (self.upper[j] - self.lower[j]);
                }
                self.expand(&x, &mut q);
                let q = &q[..self.joints];
                let gap = self
                    .chains
                    .pad(thumb, q)
                    .distance(self.chains.pad(other, q))
                    - radii;
                if gap.abs() < best.0 {
                    best = (gap.abs(), x);
                }
            }
            self.pinch_seed[k] = best.1;
            self.pinch_seed_moves[k] = moves;
        }
    }

    /// Whether joint `j` is the solver's (solved, or following a solved joint).
    pub fn drives(&self, j: usize) -> bool {
        self.moves_with.get(j).is_some_and(Option::is_some)
    }

    /// The current solution, radians, in the profile's joint order.
    pub fn solution(&self) -> &[f64] {
        &self.q[..self.joints]
    }

    /// What the last solve did.
    pub fn report(&self) -> SolveReport {
        self.report
    }

    /// Forgets the pinch switch and the solution: the next solve, like the first, starts from
    /// the open hand and converges without the smoothness term (so what follows a reset depends
    /// on the input alone).
    pub fn reset(&mut self) {
        self.projected = [false; MAX_VECTORS];
        self.q = self.initial;
        self.fresh = true;
    }

    /// The retargeted fingers (profile finger indices), thumb first: the order of the vectors'
    /// fingertips.
    pub fn fingertips(&self) -> &[usize] {
        &self.tip_chain[..self.tips]
    }

    /// The joints the solver moves (leaders; their followers move with them), profile order.
    pub fn variables(&self) -> &[usize] {
        &self.vars[..self.n_vars]
    }

    /// The operator's vectors for `pads`, in the solver's (DexPilot's) order: the fingertip
    /// pairs, then the wrist to each fingertip (unscaled, metres); returns how many.
    pub fn operator_vectors(&self, pads: &[Vec3; 5], out: &mut [DVec3; MAX_VECTORS]) -> usize {
        for (k, v) in self.vectors[..self.n_vectors].iter().enumerate() {
            let origin = v.origin.map_or(DVec3::ZERO, |o| self.operator_pad(pads, o));
            out[k] = self.operator_pad(pads, v.task) - origin;
        }
        self.n_vectors
    }

    /// The objective's vector part at joint angles `q` (radians, every joint) against the last
    /// solve's targets: how another solver's answer to the same frame scores.
    pub fn objective_at(&self, q: &[f64]) -> f64 {
        let mut full = self.q;
        for (slot, v) in full.iter_mut().zip(q) {
            *slot = *v;
        }
        let x = [0.0; MAX_JOINTS];
        self.objective(&self.last_targets, &full, &x, &x, 0.0).0
    }

    /// The operator's pad for slot `s` (from `pads`, in the operator's finger order).
    fn operator_pad(&self, pads: &[Vec3; 5], s: usize) -> DVec3 {
        pads[self.tip_operator[s]].as_dvec3()
    }

    /// Sets the pinch switch from the operator's pads and builds this solve's targets.
    fn targets(&mut self, pads: &[Vec3; 5]) -> Targets {
        let p = &self.params;
        let mut human = [DVec3::ZERO; MAX_VECTORS];
        self.operator_vectors(pads, &mut human);
        if self.pinch && self.thumb_pairs > 0 {
            for k in 0..self.thumb_pairs {
                let d = human[k].length();
                if d < f64::from(p.pinch_engage) {
                    self.projected[k] = true;
                } else if d > f64::from(p.pinch_release) {
                    self.projected[k] = false;
                }
            }
            for k in self.thumb_pairs..self.pairs {
                // A pair of two non-thumb fingers: both pinched with the thumb (the thumb
                // pair of slot s is vector s - 1) and close together.
                let v = self.vectors[k];
                let both =
                    v.origin.is_some_and(|o| self.projected[o - 1]) && self.projected[v.task - 1];
                self.projected[k] = both && human[k].length() <= FINGER_GAP_BELOW_M;
            }
        }
        let mut t = Targets {
            reference: [DVec3::ZERO; MAX_VECTORS],
            weight: [0.0; MAX_VECTORS],
        };
        let wrist_weight = (self.pairs + self.tips) as f64;
        for k in 0..self.n_vectors {
            let v = self.vectors[k];
            let direction = human[k] / (human[k].length() + 1e-6);
            let (reference, weight) = match (k < self.pairs, self.projected[k]) {
                (false, _) => (human[k] * self.scaling, wrist_weight),
                (true, false) => (human[k] * self.scaling, 1.0),
                (true, true) if k < self.thumb_pairs => {
                    let radii = if p.pad_contact {
                        self.tip_radius[v.task] + v.origin.map_or(0.0, |o| self.tip_radius[o])
                    } else {
                        0.0
                    };
                    (
                        direction * (f64::from(p.pinch_gap) + radii),
                        f64::from(p.pinch_weight),
                    )
                }
                (true, true) => (
                    direction * f64::from(p.finger_gap),
                    f64::from(p.finger_gap_weight),
                ),
            };
            t.reference[k] = reference;
            t.weight[k] = weight;
        }
        t
    }

    /// The gap of thumb pair `k` at `q` as the pinch target measures it (between the pad
    /// surfaces, or their centres without `pad_contact`), metres.
    fn pair_gap(&self, k: usize, q: &[f64; MAX_JOINTS]) -> f64 {
        let q = &q[..self.joints];
        let thumb = self.chains.pad(self.tip_chain[0], q);
        let other = self.chains.pad(self.tip_chain[k + 1], q);
        let radii = if self.params.pad_contact {
            self.tip_radius[0] + self.tip_radius[k + 1]
        } else {
            0.0
        };
        thumb.distance(other) - radii
    }

    /// The fingertip slot whose wrist vector is farthest from its target at `q`.
    fn worst_fingertip(&self, targets: &Targets, q: &[f64; MAX_JOINTS]) -> usize {
        let mut worst = (0, f64::MIN);
        for s in 0..self.tips {
            let pad = self.chains.pad(self.tip_chain[s], &q[..self.joints]);
            let error = pad.distance(targets.reference[self.pairs + s]);
            if error > worst.1 {
                worst = (s, error);
            }
        }
        worst.0
    }

    /// Huber loss of an error length.
    fn huber(&self, e: f64) -> f64 {
        let delta = f64::from(self.params.huber_delta);
        if e < delta {
            0.5 * e * e / delta
        } else {
            e - 0.5 * delta
        }
    }

    /// Every joint's angle from the variables `x` (followers from their leaders, clamped).
    fn expand(&self, x: &[f64; MAX_JOINTS], q: &mut [f64; MAX_JOINTS]) {
        *q = self.q;
        for j in 0..self.joints {
            if let Some((v, ratio)) = self.moves_with[j] {
                let leader = self.vars[v];
                q[j] = if leader == j {
                    x[v]
                } else {
                    (ratio * x[v]).clamp(self.lower[j], self.upper[j])
                };
            }
        }
    }

    /// The vector part of the objective at `q`, and the smoothness (against `previous`) and
    /// posture parts.
    fn objective(
        &self,
        targets: &Targets,
        q: &[f64; MAX_JOINTS],
        x: &[f64; MAX_JOINTS],
        previous: &[f64; MAX_JOINTS],
        smoothness: f64,
    ) -> (f64, f64) {
        let mut pads = [DVec3::ZERO; MAX_TIPS];
        for (s, pad) in pads.iter_mut().enumerate().take(self.tips) {
            *pad = self.chains.pad(self.tip_chain[s], &q[..self.joints]);
        }
        let mut sum = 0.0;
        for k in 0..self.n_vectors {
            let v = self.vectors[k];
            let robot = pads[v.task] - v.origin.map_or(DVec3::ZERO, |o| pads[o]);
            sum += targets.weight[k] * self.huber((robot - targets.reference[k]).length());
        }
        let vector_part = sum / self.n_vectors as f64;
        let (mut smooth, mut posture) = (0.0, 0.0);
        for v in 0..self.n_vars {
            smooth += (x[v] - previous[v]).powi(2);
            posture += (x[v] - self.rest[v]).powi(2);
        }
        (
            vector_part,
            smoothness * smooth + f64::from(self.params.posture) * posture,
        )
    }

    /// Solves for the operator's pad centres `pads` (operator model, hand frame, thumb ..
    /// little) and returns the solution (radians, every joint of the profile).
    ///
    /// From the previous solution first. When that ends with the vector part above
    /// `restart_above`, again for a few iterations with the fingertip farthest from its target
    /// restarted from the middle of its joints' ranges; and while a pinch is on but its pads
    /// are more than 5 mm apart, with the pinching pair where it meets. A restart's result is
    /// kept when its vector part is at least a fifth lower (a jump the downstream slew limit
    /// paces). Restarts are what get a redundant finger out of a branch that ran into its
    /// limits.
    pub fn solve(&mut self, pads: &[Vec3; 5]) -> &[f64] {
        if pads.iter().any(|p| !p.is_finite()) {
            // Nothing to follow: keep the previous solution.
            self.report.iterations = 0;
            return self.solution();
        }
        let targets = self.targets(pads);
        self.last_targets = targets.clone();
        let mut previous = [0.0; MAX_JOINTS];
        for v in 0..self.n_vars {
            previous[v] = self.q[self.vars[v]];
        }

        // The first solve (and the first after a reset) has no previous solution to stay near:
        // it converges on the fit alone. Where the operator holds still, that is where every
        // later solve stays, however many samples came before.
        let (smoothness, iterations, tolerance) = if self.fresh {
            (0.0, FRESH_ITERATIONS, 0.0)
        } else {
            let smoothness = f64::from(self.params.smoothness);
            (smoothness, self.params.max_iterations, COST_TOLERANCE)
        };
        self.fresh = false;
        let mut best = self.descend(
            &targets, &previous, &previous, iterations, smoothness, tolerance,
        );
        let mut iterations = best.iterations;
        // A first solve runs its restarts to convergence too, so that it has already taken
        // whatever a later frame's restart would find.
        let restart_iterations = if tolerance == 0.0 {
            FRESH_ITERATIONS
        } else {
            RESTART_ITERATIONS
        };
        let mut restart = |best: &mut Descent, start: &[f64; MAX_JOINTS]| {
            let other = self.descend(
                &targets,
                start,
                &previous,
                restart_iterations,
                smoothness,
                tolerance,
            );
            iterations += other.iterations;
            if other.vector_part < 0.8 * best.vector_part {
                *best = other;
            }
        };
        // A poor fit (a finger whose warm start followed a branch into its limits): the finger
        // farthest from its target from the middle of its joints' ranges, the others where they
        // are, a few iterations only (a hand whose shape cannot match the operator's leaves a
        // steady residual, tried every frame).
        if best.vector_part > f64::from(self.params.restart_above) {
            let worst = self.worst_fingertip(&targets, &best.q);
            let mut fresh = previous;
            for v in 0..self.n_vars {
                if self.var_finger[v] == self.tip_chain[worst] {
                    fresh[v] = self.rest[v];
                }
            }
            restart(&mut best, &fresh);
        }
        // A pinch the warm start leaves open: from where that pair meets, the other fingers
        // where they are.
        if let Some(k) = (0..self.thumb_pairs).find(|&k| self.projected[k]) {
            if self.pair_gap(k, &best.q) > PINCH_OPEN_M {
                let mut seeded = previous;
                for v in 0..self.n_vars {
                    if self.pinch_seed_moves[k][v] {
                        seeded[v] = self.pinch_seed[k][v];
                    }
                }
                restart(&mut best, &seeded);
            }
        }
        if best.q.iter().all(|v| v.is_finite()) {
            self.q = best.q;
        }
        let mut pinched = [false; MAX_TIPS - 1];
        pinched[..self.thumb_pairs].copy_from_slice(&self.projected[..self.thumb_pairs]);
        self.report = SolveReport {
            iterations,
            objective: best.vector_part,
            pinched,
        };
        self.solution()
    }

    /// Projected, damped Gauss-Newton from the variables `start`, the smoothness term measured
    /// from `previous`.
    fn descend(
        &self,
        targets: &Targets,
        start: &[f64; MAX_JOINTS],
        previous: &[f64; MAX_JOINTS],
        max_iterations: u32,
        smoothness: f64,
        cost_tolerance: f64,
    ) -> Descent {
        let n = self.n_vars;
        let mut x = *start;
        let mut q = self.q;
        self.expand(&x, &mut q);
        let (mut vector_part, smooth) = self.objective(targets, &q, &x, previous, smoothness);
        let mut cost = vector_part + smooth;
        let mut damping = 1e-3;
        let mut iterations = 0;
        let posture = f64::from(self.params.posture);
        let delta = f64::from(self.params.huber_delta);
        let mut full = [DVec3::ZERO; MAX_JOINTS];
        while iterations < max_iterations {
            // Pads and their Jacobians by variable.
            let mut pads = [DVec3::ZERO; MAX_TIPS];
            let mut jac = [[DVec3::ZERO; MAX_JOINTS]; MAX_TIPS];
            for s in 0..self.tips {
                pads[s] = self
                    .chains
                    .pad_jacobian(self.tip_chain[s], &q[..self.joints], &mut full);
                for (j, column) in full.iter().enumerate().take(self.joints) {
                    if let Some((v, ratio)) = self.moves_with[j] {
                        // A follower held at its own limit does not move with its leader.
                        let follows = self.vars[v] == j
                            || (self.lower[j]..=self.upper[j]).contains(&(ratio * x[v]));
                        if follows {
                            jac[s][v] += ratio * *column;
                        }
                    }
                }
            }
            // Normal equations of the reweighted, linearised objective.
            let mut h = [[0.0; MAX_JOINTS]; MAX_JOINTS];
            let mut g = [0.0; MAX_JOINTS];
            for k in 0..self.n_vectors {
                let vd = self.vectors[k];
                let robot = pads[vd.task] - vd.origin.map_or(DVec3::ZERO, |o| pads[o]);
                let e = robot - targets.reference[k];
                let length = e.length();
                let curvature = if length < delta {
                    1.0 / delta
                } else {
                    1.0 / length
                };
                let a = targets.weight[k] * curvature / self.n_vectors as f64;
                // Only the two fingers' variables move this vector.
                let mut index = [0; MAX_JOINTS];
                let mut column = [DVec3::ZERO; MAX_JOINTS];
                let mut m = 0;
                for slot in [Some(vd.task), vd.origin].into_iter().flatten() {
                    for &v in &self.slot_vars[slot][..self.slot_var_count[slot]] {
                        if index[..m].contains(&v) {
                            continue;
                        }
                        index[m] = v;
                        column[m] = jac[vd.task][v] - vd.origin.map_or(DVec3::ZERO, |o| jac[o][v]);
                        m += 1;
                    }
                }
                for i in 0..m {
                    let r = index[i];
                    g[r] += a * column[i].dot(e);
                    for k2 in 0..m {
                        let c = index[k2];
                        if c <= r {
                            h[r][c] += a * column[i].dot(column[k2]);
                        }
                    }
                }
            }
            for v in 0..n {
                g[v] +=
                    2.0 * smoothness * (x[v] - previous[v]) + 2.0 * posture * (x[v] - self.rest[v]);
                h[v][v] += 2.0 * (smoothness + posture);
            }
            // Joints at a limit they push against stay there this iteration.
            let mut free = [true; MAX_JOINTS];
            for v in 0..n {
                let j = self.vars[v];
                let at_lower = x[v] <= self.lower[j] + 1e-12 && g[v] > 0.0;
                let at_upper = x[v] >= self.upper[j] - 1e-12 && g[v] < 0.0;
                free[v] = !(at_lower || at_upper);
            }
            // Damped steps until one lowers the objective.
            let mut accepted = false;
            while iterations < max_iterations {
                iterations += 1;
                let Some(step) = damped_step(&h, &g, &free, n, damping) else {
                    damping *= 10.0;
                    continue;
                };
                let mut trial = x;
                let mut largest: f64 = 0.0;
                for v in 0..n {
                    let j = self.vars[v];
                    trial[v] = (x[v] + step[v]).clamp(self.lower[j], self.upper[j]);
                    largest = largest.max((trial[v] - x[v]).abs());
                }
                let mut trial_q = q;
                self.expand(&trial, &mut trial_q);
                let (trial_vectors, trial_smooth) =
                    self.objective(targets, &trial_q, &trial, previous, smoothness);
                let trial_cost = trial_vectors + trial_smooth;
                if trial_cost.is_finite() && trial_cost <= cost {
                    let gain = cost - trial_cost;
                    x = trial;
                    q = trial_q;
                    cost = trial_cost;
                    vector_part = trial_vectors;
                    damping = (damping / 3.0).max(1e-9);
                    accepted = largest > STEP_TOLERANCE_RAD && gain > cost_tolerance * cost;
                    break;
                }
                damping *= 4.0;
                if largest <= STEP_TOLERANCE_RAD || damping > 1e9 {
                    break;
                }
            }
            if !accepted {
                break;
            }
        }
        Descent {
            q,
            vector_part,
            iterations,
        }
    }
}

/// Uniform numbers in [0, 1) from a fixed seed (xorshift64*): reproducible sampling without a
/// dependency.
#[derive(Debug, Clone)]
pub(crate) struct Uniform(u64);

impl Uniform {
    /// A sequence from `seed` (0 is replaced: xorshift needs a non-zero state).
    pub(crate) fn new(seed: u64) -> Self {
        Self(seed.max(1))
    }

    /// The next number.
    pub(crate) fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Where one descent ended.
struct Descent {
    q: [f64; MAX_JOINTS],
    vector_part: f64,
    iterations: u32,
}

/// Solves `(H + damping × diag(H)) Δ = −g` over the free variables (a fixed variable's step is
/// 0) by Cholesky; `None` when the matrix is not positive definite. `h` holds the lower
/// triangle.
fn damped_step(
    h: &[[f64; MAX_JOINTS]; MAX_JOINTS],
    g: &[f64; MAX_JOINTS],
    free: &[bool; MAX_JOINTS],
    n: usize,
    damping: f64,
) -> Option<[f64; MAX_JOINTS]> {
    let mut l = [[0.0; MAX_JOINTS]; MAX_JOINTS];
    let mut b = [0.0; MAX_JOINTS];
    for r in 0..n {
        for c in 0..=r {
            l[r][c] = if free[r] && free[c] { h[r][c] } else { 0.0 };
        }
        if free[r] {
            // Marquardt's scaling, with a floor for a joint that moves nothing at the moment (a
            // straight finger's side joint), which would leave the matrix singular.
            l[r][r] += damping * (h[r][r] + 1e-6);
            b[r] = -g[r];
        } else {
            l[r][r] = 1.0;
        }
    }
    // In-place Cholesky: l = L Lᵀ.
    for c in 0..n {
        let mut d = l[c][c];
        for k in 0..c {
            d -= l[c][k] * l[c][k];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let d = d.sqrt();
        l[c][c] = d;
        for r in c + 1..n {
            let mut s = l[r][c];
            for k in 0..c {
                s -= l[r][k] * l[c][k];
            }
            l[r][c] = s / d;
        }
    }
    // Forward then back substitution.
    let mut y = [0.0; MAX_JOINTS];
    for r in 0..n {
        let mut s = b[r];
        for k in 0..r {
            s -= l[r][k] * y[k];
        }
        y[r] = s / l[r][r];
    }
    let mut x = [0.0; MAX_JOINTS];
    for r in (0..n).rev() {
        let mut s = y[r];
        for k in r + 1..n {
            s -= l[k][r] * x[k];
        }
        x[r] = s / l[r][r];
    }
    for (v, step) in x.iter_mut().enumerate().take(n) {
        if !free[v] {
            *step = 0.0;
        }
    }
    Some(x)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use teleop_kinematics::{OperatorHand, OperatorPose};

    fn solver(hand: &str, pinch: bool) -> (HandProfile, Solver) {
        solver_with(hand, pinch, FingertipConfig::default())
    }

    fn solver_with(hand: &str, pinch: bool, params: FingertipConfig) -> (HandProfile, Solver) {
        let profile = HandProfile::builtin(hand).unwrap();
        let s = Solver::new(&profile, params, pinch, &[]).unwrap();
        (profile, s)
    }

    /// The operator pads that make `q`'s robot pads the exact targets: the robot's pads over
    /// the scaling.
    fn pads_for(s: &Solver, q: &[f64]) -> [Vec3; 5] {
        let mut pads = [Vec3::ZERO; 5];
        for slot in 0..s.tips {
            let pad = s.chains.pad(s.tip_chain[slot], q) / s.scaling;
            pads[s.tip_operator[slot]] = pad.as_vec3();
        }
        pads
    }

    /// Solved joints at `u` (0 = lower limit .. 1 = upper) of their range, followers where
    /// their leaders put them, the rest where the solver keeps them. A side-spreading
    /// joint stays in the middle half of its range: a hand's pose, not the LEAP's fingers
    /// splayed 48 degrees apart, where a straight finger's two branches meet.
    fn pose_at(profile: &HandProfile, s: &Solver, u: &[f64]) -> Vec<f64> {
        let mut q: Vec<f64> = (0..profile.joints.len())
            .map(|j| match s.moves_with[j] {
                Some((v, _)) if s.vars[v] == j => {
                    let u = match profile.joints[j].role {
                        Role::Abduct => 0.25 + 0.5 * u[j % u.len()],
                        _ => u[j % u.len()],
                    };
                    s.lower[j] + u * (s.upper[j] - s.lower[j])
                }
                _ => s.q[j],
            })
            .collect();
        for j in 0..q.len() {
            if let (Some(c), true) = (profile.joints[j].coupling, s.drives(j)) {
                q[j] = (f64::from(c.ratio) * q[c.to]).clamp(s.lower[j], s.upper[j]);
            }
        }
        q
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// A pose the hand can reach is reached: pose -> pads -> solve -> pads within 1 mm,
        /// tracking the pads there from the open hand as a glove would move them. Without the
        /// smoothness term, which trails on purpose (see the next test), and with the posture
        /// term, which pulls on purpose, only a thousandth as strong: enough to keep a
        /// redundant finger's free joint from drifting into a limit. Poses within the middle half
        /// of every joint's range: nearer the limits (a LEAP finger curled hard) a tracked solve
        /// can end on another branch 2 to 6 mm off.
        #[test]
        fn reachable_fingertips_are_reached(
            hand in prop::sample::select(vec!["revo2", "allegro", "shadow", "leap"]),
            u in prop::collection::vec(0.25f64..0.75, 24),
        ) {
            let no_smoothing = FingertipConfig {
                smoothness: 0.0,
                posture: 1e-6,
                ..FingertipConfig::default()
            };
            let (profile, mut s) = solver_with(hand, false, no_smoothing);
            // Tracked as a glove would move: from the start pose to the target in 50 steps
            // (170 ms at the glove's 290 Hz: a fast move across every joint's range).
            let start = s.solution().to_vec();
            let q = pose_at(&profile, &s, &u);
            for k in 1..=50 {
                let t = f64::from(k) / 50.0;
                let between: Vec<f64> =
                    start.iter().zip(&q).map(|(a, b)| a + t * (b - a)).collect();
                s.solve(&pads_for(&s, &between));
            }
            let pads = pads_for(&s, &q);
            for _ in 0..10 {
                s.solve(&pads);
            }
            let got = s.solution().to_vec();
            for slot in 0..s.tips {
                let f = s.tip_chain[slot];
                let error = s.chains.pad(f, &got).distance(s.chains.pad(f, &q));
                prop_assert!(error < 1e-3, "{hand} finger {f}: {} mm off", error * 1e3);
            }
        }

        /// Limits and couplings hold for any operator input, finite or not.
        #[test]
        fn limits_and_couplings_hold_for_any_input(
            hand in prop::sample::select(vec!["revo2", "allegro", "shadow", "leap"]),
            raw in prop::collection::vec(prop::num::f32::ANY, 15),
        ) {
            let (profile, mut s) = solver(hand, true);
            let pads: [Vec3; 5] = core::array::from_fn(|i| Vec3::new(raw[3 * i], raw[3 * i + 1], raw[3 * i + 2]));
            for _ in 0..3 {
                let q = s.solve(&pads).to_vec();
                for (j, joint) in profile.joints.iter().enumerate() {
                    prop_assert!(q[j].is_finite());
                    prop_assert!(q[j] >= s.lower[j] - 1e-12 && q[j] <= s.upper[j] + 1e-12, "{}", joint.name);
                    if let Some(c) = joint.coupling {
                        let expect = (f64::from(c.ratio) * q[c.to]).clamp(s.lower[j], s.upper[j]);
                        prop_assert!((q[j] - expect).abs() < 1e-12, "{}", joint.name);
                    }
                }
            }
        }
    }

    #[test]
    fn a_still_operator_is_a_fixed_point_however_many_samples_came_before() {
        // A recording that starts a few samples after the node did reprocesses to the same
        // solutions: the first solve converges, and later solves of the same pads stay there.
        let operator = OperatorHand::default();
        let pose = OperatorPose {
            flexion: [0.3, 0.5, 0.4, 0.2, 0.1],
            thumb_opposition: 0.6,
        };
        let pads = operator.pads(&pose);
        for hand in ["revo2", "allegro", "shadow", "leap"] {
            let (_, mut live) = solver(hand, true);
            let (_, mut replay) = solver(hand, true);
            for _ in 0..3 {
                live.solve(&pads);
            }
            // Within the tolerance `teleop reprocess` compares commands with.
            let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
            let first = replay.solve(&pads).to_vec();
            assert!(close(live.solution(), &first), "{hand}");
            for _ in 0..5 {
                let a = live.solve(&pads).to_vec();
                assert!(close(&a, replay.solve(&pads)), "{hand}");
            }
        }
    }

    #[test]
    fn the_pinch_switch_engages_below_3_cm_and_releases_above_5_cm() {
        let (_, mut s) = solver("allegro", true);
        let operator = OperatorHand::default();
        let open = operator.pads(&OperatorPose::default());
        let at = |d: f32| {
            // The index pad `d` from the thumb's, the rest of the hand open.
            let mut pads = open;
            pads[1] = pads[0] + Vec3::new(0.0, d, 0.0);
            pads
        };
        let mut pinched = |d: f32| {
            s.solve(&at(d));
            s.report().pinched[0]
        };
        assert!(!pinched(0.04));
        assert!(pinched(0.029));
        assert!(
            pinched(0.04),
            "hysteresis: still pinched between 3 and 5 cm"
        );
        assert!(pinched(0.049));
        assert!(!pinched(0.051));
        assert!(!pinched(0.04));
    }

    #[test]
    fn the_same_inputs_give_the_same_solution_bit_for_bit() {
        let operator = OperatorHand::default();
        let run = || {
            let (_, mut s) = solver("shadow", true);
            let mut out = Vec::new();
            for k in 0..50 {
                let pose = OperatorPose {
                    flexion: [k as f32 / 50.0; 5],
                    thumb_opposition: 0.6,
                };
                out.extend_from_slice(s.solve(&operator.pads(&pose)));
            }
            out
        };
        assert_eq!(run(), run());
    }
}
