//! Benchmark: our fingertip solver (`teleop_retargeting::Solver`, mode `pinch`) side by side with
//! dex-retargeting's `DexPilotOptimizer` (PyPI, run by `bench_retarget_dexpilot.py` next to this
//! file), per shipped hand: solve time, the objective each reaches and the thumb-finger pinch
//! distance, on the same operator fingertips.
//!
//! Method:
//! - Frames: every `glove/state` sample of `recordings/trajectories/{grasp, pinch-index,
//!   pinch-middle, pinch-ring}.mcap`, in that order, as one sequence (each solver warm-starts
//!   from its previous frame, across the joins too). The operator's pads: the raw positions
//!   through the default calibration's closures, `Retargeter::operator_pose` and the default
//!   `OperatorHand`.
//! - The same problem on both sides: the URDF `HandProfile::to_urdf` writes (root `wrist`,
//!   fingertips the `<finger>_pad` frames, thumb first), the target joints = the joints our
//!   solver moves (`Solver::variables`, by profile name; followers are URDF mimic joints; the
//!   Shadow's wrist is left out), the human vectors of `Solver::operator_vectors` (DexPilot's
//!   order, unscaled), the profile's scaling and DexPilot's defaults (`FingertipConfig`'s, with
//!   `pad_contact` off: both measure the pinch between pad centres; and without our posture
//!   term, which DexPilot does not have).
//! - Timing: ours, `Instant` around each `solve()` of one pass over the frames on a fresh
//!   solver (no warm-up pass: the first frames are cold); the peer, Python's `perf_counter_ns`
//!   around each `optimizer.retarget()` (the peer's own loop, without process start and
//!   imports).
//! - Objective: the vector part (weighted Huber, no smoothness term), both scored by our
//!   `Solver::objective_at` against the targets of our solve of the same frame (the peer's q
//!   completed with its mimic followers, as the profile couples them); nlopt's own value beside
//!   it as a cross-check.
//! - Pinch: in the frames where the operator model pinches a finger (thumb-finger pad gap under
//!   `OPERATOR_PINCH_M`), the robot's thumb-finger pad distance from each side's q by our
//!   forward kinematics: between centres, and between surfaces (centres less both radii).
//!
//! Without python3 or dex-retargeting (`pip install -r .ci/requirements.txt`) the peer is
//! skipped with the reason and only ours is printed; under `TELEOP_REQUIRE_CHECKS` that fails.
//!
//! Run: `cargo run --release -p teleop-e2e --example bench_retarget`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};
use teleop_e2e::bench::loadavg;
use teleop_e2e::netns::skip;
use teleop_hand_profile::HandProfile;
use teleop_kinematics::{Chains, OperatorHand};
use teleop_msgs::GloveState;
use teleop_recording::read_samples;
use teleop_retargeting::eval::{Spread, OPERATOR_PINCH_M, ROBOT_PINCH_M};
use teleop_retargeting::{Calibration, FingertipConfig, Retargeter, Solver, MAX_VECTORS};

/// The trajectories, in the order they are run.
const TRAJECTORIES: [&str; 4] = ["grasp", "pinch-index", "pinch-middle", "pinch-ring"];
/// The shipped hands.
const HANDS: [&str; 4] = ["revo2", "allegro", "shadow", "leap"];
/// Ours counts as reaching the peer's objective within this relative and absolute slack.
const OBJECTIVE_RTOL: f64 = 1e-3;
const OBJECTIVE_ATOL: f64 = 1e-9;
/// The peer script's exit status when a Python module is missing.
const PEER_MODULE_MISSING: i32 = 2;

/// One glove sample, as the operator model sees it.
struct Frame {
    /// Pad centres, hand frame, thumb .. little.
    pads: [Vec3; 5],
    /// Per operator finger (thumb .. little): its pad within `OPERATOR_PINCH_M` of the
    /// thumb's (the thumb's own entry unused).
    pinching: [bool; 5],
}

/// The peer's input (the header of `bench_retarget_dexpilot.py`).
#[derive(Serialize)]
struct PeerInput {
    urdf: PathBuf,
    wrist_link: &'static str,
    tip_links: Vec<String>,
    target_joint_names: Vec<String>,
    scaling: f64,
    huber_delta: f64,
    norm_delta: f64,
    project_dist: f64,
    escape_dist: f64,
    eta1: f64,
    eta2: f64,
    frames: Vec<Vec<[f64; 3]>>,
}

/// The peer's output.
#[derive(Deserialize)]
struct PeerOutput {
    versions: BTreeMap<String, String>,
    joint_names: Vec<String>,
    frames: Vec<PeerFrame>,
}

#[derive(Deserialize)]
struct PeerFrame {
    q: Vec<f64>,
    solve_us: f64,
    objective: f64,
    nlopt_result: i64,
    error: Option<String>,
}

/// One side's measures over the frames.
#[derive(Default)]
struct Side {
    solve_us: Vec<f64>,
    objective: Vec<f64>,
    /// The objective with DexPilot's smoothness term, each side against its own previous q.
    full: Vec<f64>,
    previous: Vec<f64>,
    /// Thumb-finger pad distances in the operator's pinch frames, mm.
    pinch_centres_mm: Vec<f64>,
    pinch_surfaces_mm: Vec<f64>,
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let frames = load_frames(&root);
    let pinch_frames = frames
        .iter()
        .filter(|f| f.pinching[1..].iter().any(|&p| p))
        .count();
    println!(
        "Fingertip retargeting: our Solver (pinch mode) vs dex-retargeting's DexPilotOptimizer"
    );
    println!(
        "  frames: every glove/state sample of recordings/trajectories/{{{}}}.mcap, {} in all, one sequence",
        TRAJECTORIES.join(", "),
        frames.len()
    );
    println!(
        "  operator pinch frames (a thumb-finger pad gap under {:.0} mm): {pinch_frames}",
        1e3 * OPERATOR_PINCH_M
    );
    println!("  same URDF (HandProfile::to_urdf), target joints, human vectors, scaling and DexPilot defaults (pad centres)");
    println!("  timed: ours, Instant around each solve() of one pass on a fresh solver (no warm-up); peer, perf_counter_ns around each retarget()");
    println!("  objective: the vector part (weighted Huber) of both q, scored by our objective_at against the frame's targets");
    println!("  machine: {}", machine());
    println!("  load average (1 min) before: {}", loadavg());
    for hand in HANDS {
        bench_hand(hand, &frames);
    }
    println!("  load average (1 min) after: {}", loadavg());
}

/// The frames of every trajectory, in order.
fn load_frames(root: &Path) -> Vec<Frame> {
    let calibration = Calibration::default();
    let operator = OperatorHand::default();
    let mut frames = Vec::new();
    for name in TRAJECTORIES {
        let path = root.join(format!("recordings/trajectories/{name}.mcap"));
        let read = read_samples::<GloveState>(&path, None)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        assert!(
            read.undecodable == 0 && !read.samples.is_empty(),
            "{}: {} glove samples, {} undecodable",
            path.display(),
            read.samples.len(),
            read.undecodable
        );
        for sample in &read.samples {
            let closure = calibration.closure(&sample.raw_position);
            let pose = Retargeter::operator_pose(&closure);
            frames.push(Frame {
                pads: operator.pads(&pose),
                pinching: core::array::from_fn(|f| {
                    f > 0 && operator.pad_gap(&pose, 0, f) < OPERATOR_PINCH_M
                }),
            });
        }
    }
    frames
}

/// The CPU model and how many CPUs.
fn machine() -> String {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = cpuinfo
        .lines()
        .find_map(|l| l.strip_prefix("model name"))
        .map_or("unknown CPU", |m| m.trim_start_matches([' ', '\t', ':']));
    let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!("{model}, {cpus} CPUs available, shared with other work")
}

/// Runs both solvers on one hand and prints its table.
fn bench_hand(hand: &str, frames: &[Frame]) {
    let profile = HandProfile::builtin(hand).unwrap_or_else(|| panic!("no shipped hand {hand}"));
    let config = FingertipConfig {
        pad_contact: false,
        posture: 0.0,
        ..FingertipConfig::default()
    };
    let mut solver = Solver::new(&profile, config, true, &[])
        .unwrap_or_else(|| panic!("{hand}: no finger follows an operator finger"));
    let chains = Chains::new(&profile);
    // Per fingertip slot after the thumb: the profile finger and the operator finger (thumb 0 ..
    // little 4; chains name it little 0 .. thumb 4, the glove's order).
    let tips = solver.fingertips().to_vec();
    let operator_finger = |f: usize| {
        chains.chains()[f]
            .operator
            .map(|g| 4 - g.min(4))
            .unwrap_or(0)
    };

    let mut vectors = Vec::with_capacity(frames.len());
    let mut buffer = [DVec3::ZERO; MAX_VECTORS];
    for frame in frames {
        let n = solver.operator_vectors(&frame.pads, &mut buffer);
        vectors.push(buffer[..n].iter().map(|v| v.to_array()).collect());
    }
    let scaling = f64::from(config.scaling.unwrap_or(profile.retarget.scaling));
    let input = PeerInput {
        urdf: PathBuf::new(),
        wrist_link: "wrist",
        tip_links: tips
            .iter()
            .map(|&f| format!("{}_pad", profile.fingers[f].name))
            .collect(),
        target_joint_names: solver
            .variables()
            .iter()
            .map(|&j| profile.joints[j].name.clone())
            .collect(),
        scaling,
        huber_delta: f64::from(config.huber_delta),
        norm_delta: f64::from(config.smoothness),
        project_dist: f64::from(config.pinch_engage),
        escape_dist: f64::from(config.pinch_release),
        eta1: f64::from(config.pinch_gap),
        eta2: f64::from(config.finger_gap),
        frames: vectors,
    };
    let peer = run_peer(&profile, input, frames.len());
    // Per profile joint: where the peer's q has it.
    let peer_index: Vec<Option<usize>> = match &peer {
        Some(p) => profile
            .joints
            .iter()
            .map(|j| p.joint_names.iter().position(|n| *n == j.name))
            .collect(),
        None => Vec::new(),
    };

    let (mut ours, mut theirs) = (Side::default(), Side::default());
    let smoothness = f64::from(config.smoothness);
    let variables = solver.variables().to_vec();
    // The objective the optimisers minimise: the vector part plus the smoothness term against
    // the side's own previous solution (nlopt reports the vector part only).
    let full = |side: &mut Side, vector_part: f64, q: &[f64]| {
        let change: f64 = if side.previous.is_empty() {
            0.0
        } else {
            variables
                .iter()
                .map(|&j| (q[j] - side.previous[j]).powi(2))
                .sum()
        };
        side.full.push(vector_part + smoothness * change);
        side.previous = q.to_vec();
    };
    let mut ours_full_no_worse = 0usize;
    let mut ours_no_worse = 0usize;
    let mut ratio = Vec::new();
    let mut nlopt_difference = Vec::new();
    let mut q_peer = vec![0.0; profile.joints.len()];
    for (i, frame) in frames.iter().enumerate() {
        let start = Instant::now();
        solver.solve(&frame.pads);
        let took = start.elapsed();
        ours.solve_us.push(took.as_secs_f64() * 1e6);
        let objective = solver.report().objective;
        ours.objective.push(objective);
        let q = solver.solution();
        ours.pinches(&chains, q, &tips, frame, operator_finger);
        full(&mut ours, objective, q);
        let Some(p) = &peer else { continue };
        let pf = &p.frames[i];
        // The peer's q on every joint: its target joints, their coupled followers, the rest as
        // ours (joints that move no retargeted pad).
        q_peer.copy_from_slice(q);
        for (j, slot) in peer_index.iter().enumerate() {
            if let Some(k) = slot {
                q_peer[j] = pf.q[*k];
            }
        }
        for (j, joint) in profile.joints.iter().enumerate() {
            if let Some(c) = joint.coupling {
                if peer_index[c.to].is_some() {
                    q_peer[j] = (f64::from(c.ratio) * q_peer[c.to])
                        .clamp(f64::from(joint.lower), f64::from(joint.upper));
                }
            }
        }
        let scored = solver.objective_at(&q_peer);
        theirs.solve_us.push(pf.solve_us);
        theirs.objective.push(scored);
        theirs.pinches(&chains, &q_peer, &tips, frame, operator_finger);
        full(&mut theirs, scored, &q_peer);
        let (a, b) = (ours.full[i], theirs.full[i]);
        ours_full_no_worse += usize::from(a <= b * (1.0 + OBJECTIVE_RTOL) + OBJECTIVE_ATOL);
        ours_no_worse += usize::from(objective <= scored * (1.0 + OBJECTIVE_RTOL) + OBJECTIVE_ATOL);
        ratio.push(objective / scored.max(OBJECTIVE_ATOL));
        nlopt_difference.push((pf.objective - scored).abs() / scored.max(1e-12));
    }

    println!(
        "{hand} ({} fingertips, {} target joints of {}, scaling {scaling:.2})",
        tips.len(),
        solver.variables().len(),
        profile.joints.len()
    );
    let Some(p) = peer else {
        print_table(&ours, None);
        return;
    };
    let versions: Vec<String> = p.versions.iter().map(|(k, v)| format!("{k} {v}")).collect();
    println!("  peer: {}", versions.join(", "));
    print_table(&ours, Some(&theirs));
    let speedup = |f: fn(&Spread) -> f64| {
        f(&Spread::of(&mut theirs.solve_us.clone())) / f(&Spread::of(&mut ours.solve_us.clone()))
    };
    println!(
        "  speedup (peer / ours): p50 {:.0}x, p99 {:.0}x",
        speedup(|s| s.p50),
        speedup(|s| s.p99)
    );
    println!(
        "  frames where ours <= peer x {} + {OBJECTIVE_ATOL:e}: {:.1} % (vector part), {:.1} % \
         (with the smoothness term)",
        1.0 + OBJECTIVE_RTOL,
        100.0 * ours_no_worse as f64 / frames.len() as f64,
        100.0 * ours_full_no_worse as f64 / frames.len() as f64
    );
    let ratio = Spread::of(&mut ratio);
    println!(
        "  objective ours / peer per frame: p50 {:.4}, p95 {:.3}, max {:.3}",
        ratio.p50, ratio.p95, ratio.max
    );
    let failed = p.frames.iter().filter(|f| f.error.is_some()).count();
    let mut results: BTreeMap<i64, usize> = BTreeMap::new();
    for f in &p.frames {
        *results.entry(f.nlopt_result).or_default() += 1;
    }
    let spread = Spread::of(&mut nlopt_difference);
    println!(
        "  peer: nlopt results {results:?}, raised {failed}; |nlopt value - our score of its q| / score p50 {:.1e}, p99 {:.1e}",
        spread.p50, spread.p99
    );
}

impl Side {
    /// Records the thumb-finger pad distances at `q` for the fingers the operator pinches in
    /// `frame`.
    fn pinches(
        &mut self,
        chains: &Chains,
        q: &[f64],
        tips: &[usize],
        frame: &Frame,
        operator_finger: impl Fn(usize) -> usize,
    ) {
        let Some((&thumb, others)) = tips.split_first() else {
            return;
        };
        if operator_finger(thumb) != 0 {
            return;
        }
        let thumb_pad = chains.pad(thumb, q);
        let thumb_radius = chains.chains()[thumb].pad_radius;
        for &f in others {
            if !frame.pinching[operator_finger(f)] {
                continue;
            }
            let centres = thumb_pad.distance(chains.pad(f, q));
            self.pinch_centres_mm.push(1e3 * centres);
            self.pinch_surfaces_mm
                .push(1e3 * (centres - thumb_radius - chains.chains()[f].pad_radius));
        }
    }
}

/// Prints ours and (when it ran) the peer's measures side by side.
fn print_table(ours: &Side, peer: Option<&Side>) {
    let sides: Vec<(&str, &Side)> = std::iter::once(("ours", ours))
        .chain(peer.map(|p| ("DexPilotOptimizer", p)))
        .collect();
    let line = |label: &str, cells: Vec<String>| {
        let mut line = format!("  {label:<36}");
        for c in cells {
            line.push_str(&format!("{c:>28}"));
        }
        println!("{line}");
    };
    line("", sides.iter().map(|(name, _)| name.to_string()).collect());
    let row = |label: &str, cell: &dyn Fn(&Side) -> String| {
        line(label, sides.iter().map(|(_, s)| cell(s)).collect());
    };
    let spread = |v: &[f64]| Spread::of(&mut v.to_vec());
    row("solve time p50 / p99 / max (us)", &|s| {
        let t = spread(&s.solve_us);
        format!("{:.1} / {:.1} / {:.1}", t.p50, t.p99, t.max)
    });
    row("objective mean / p50", &|s| {
        let mean = s.objective.iter().sum::<f64>() / s.objective.len().max(1) as f64;
        format!("{mean:.3e} / {:.3e}", spread(&s.objective).p50)
    });
    row("with the smoothness term mean / p50", &|s| {
        let mean = s.full.iter().sum::<f64>() / s.full.len().max(1) as f64;
        format!("{mean:.3e} / {:.3e}", spread(&s.full).p50)
    });
    row("pinch frames (finger pairs)", &|s| {
        s.pinch_surfaces_mm.len().to_string()
    });
    row("pinch pad centres p50 / p95 (mm)", &|s| {
        let d = spread(&s.pinch_centres_mm);
        format!("{:.1} / {:.1}", d.p50, d.p95)
    });
    row("pinch pad surfaces p50 / p95 (mm)", &|s| {
        let d = spread(&s.pinch_surfaces_mm);
        format!("{:.1} / {:.1}", d.p50, d.p95)
    });
    row(
        &format!("pinch surfaces under {:.0} mm", 1e3 * ROBOT_PINCH_M),
        &|s| {
            let under = s
                .pinch_surfaces_mm
                .iter()
                .filter(|&&d| d < 1e3 * ROBOT_PINCH_M)
                .count();
            format!(
                "{:.1} %",
                100.0 * under as f64 / s.pinch_surfaces_mm.len().max(1) as f64
            )
        },
    );
}

/// Runs the peer on `input` (the URDF written to a temporary file); its output, or `None` when
/// it is skipped (python3 or a module missing: reported by [`skip`], which fails under
/// `TELEOP_REQUIRE_CHECKS`). Any other failure ends the benchmark with the peer's message.
fn run_peer(profile: &HandProfile, mut input: PeerInput, frames: usize) -> Option<PeerOutput> {
    let dir = tempfile::tempdir().unwrap();
    input.urdf = dir.path().join(format!("{}.urdf", profile.name));
    std::fs::write(&input.urdf, profile.to_urdf()).unwrap();
    let input_path = dir.path().join("input.json");
    std::fs::write(&input_path, serde_json::to_vec(&input).unwrap()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/bench_retarget_dexpilot.py");
    // Not `run_for`: it reads the output only after the exit, and this output (megabytes)
    // would fill the pipe first.
    let run = match Command::new("python3")
        .arg(&script)
        .arg(&input_path)
        .output()
    {
        Ok(run) => run,
        Err(e) => {
            skip(&format!(
                "the DexPilotOptimizer peer: cannot run python3 ({e})"
            ));
            return None;
        }
    };
    let err = String::from_utf8_lossy(&run.stderr);
    match run.status.code() {
        Some(0) => {}
        Some(PEER_MODULE_MISSING) => {
            skip(&format!("the DexPilotOptimizer peer: {}", err.trim()));
            return None;
        }
        _ => panic!(
            "{} on {}: {}: {err}",
            script.display(),
            profile.name,
            run.status
        ),
    }
    let output: PeerOutput = serde_json::from_slice(&run.stdout)
        .unwrap_or_else(|e| panic!("{}: output not as expected: {e}", script.display()));
    assert_eq!(
        output.frames.len(),
        frames,
        "{}: frames answered",
        script.display()
    );
    for name in &input.target_joint_names {
        assert!(
            output.joint_names.contains(name),
            "{}: no joint {name} in its q ({:?})",
            script.display(),
            output.joint_names
        );
    }
    for (i, f) in output.frames.iter().enumerate() {
        assert!(
            f.q.len() == output.joint_names.len() && f.q.iter().all(|v| v.is_finite()),
            "{}: frame {i}: q {:?}",
            script.display(),
            f.q
        );
    }
    Some(output)
}
