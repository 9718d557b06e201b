//! `teleop retarget eval`: runs retargeting modes over recorded glove trajectories and prints
//! their measures side by side (`teleop_retargeting::eval`).
//!
//! The glove samples of each recording (`glove/state`, or `NS/glove/state` with `--namespace`)
//! go through the retargeting library exactly as the node steps it (calibrated raw positions,
//! the sample's own stamp), once per mode, and each step is timed here.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use teleop_hand_profile::{HandProfile, RetargetMode};
use teleop_msgs::{GloveState, Message};
use teleop_recording::read_samples;
use teleop_retargeting::eval::{pinch_reach, Evaluation, Summary, OPERATOR_PINCH_M, ROBOT_PINCH_M};
use teleop_retargeting::{GloveInput, Retargeter};
use teleop_runtime::Namespace;

/// What to evaluate.
pub struct EvalOptions {
    /// The recordings.
    pub recordings: Vec<PathBuf>,
    /// A shipped hand by name, or a profile file.
    pub hand: String,
    /// The modes, in the order to print them.
    pub modes: Vec<RetargetMode>,
    /// The retarget node's configuration file (its `[retarget]` table; default: the defaults).
    pub config: Option<PathBuf>,
    /// The operator's calibration (default: the glove's full range and the default model).
    pub calibration: Option<PathBuf>,
    /// The side to read in a recording of several.
    pub namespace: Option<Namespace>,
}

/// Parses `joint,vector,pinch` (or `all`).
pub fn parse_modes(s: &str) -> Result<Vec<RetargetMode>, String> {
    if s == "all" {
        return Ok(RetargetMode::ALL.to_vec());
    }
    s.split(',')
        .map(|m| {
            RetargetMode::from_name(m.trim()).ok_or_else(|| {
                format!("`{m}` is not a retargeting mode (joint, vector, pinch, or all)")
            })
        })
        .collect()
}

/// The hand: a shipped name or a profile file.
fn hand_profile(hand: &str) -> anyhow::Result<HandProfile> {
    if let Some(p) = HandProfile::builtin(hand) {
        return Ok(p);
    }
    let path = Path::new(hand);
    if path.exists() {
        return Ok(HandProfile::load(path)?);
    }
    anyhow::bail!(
        "--hand {hand}: neither a shipped hand ({}) nor a profile file",
        HandProfile::builtin_names().collect::<Vec<_>>().join(", ")
    )
}

/// The glove samples of one recording, in log order.
fn glove_samples(path: &Path, namespace: Option<&Namespace>) -> anyhow::Result<Vec<GloveState>> {
    let read = read_samples::<GloveState>(path, namespace)?;
    if read.undecodable > 0 {
        eprintln!(
            "{}: {} glove samples could not be decoded and were skipped",
            path.display(),
            read.undecodable
        );
    }
    anyhow::ensure!(
        !read.samples.is_empty(),
        "{}: no `{}` samples{}",
        path.display(),
        GloveState::TOPIC,
        namespace.map_or(String::new(), |ns| format!(" in namespace `{ns}`"))
    );
    Ok(read.samples)
}

/// Runs one mode over the samples.
fn evaluate(
    profile: &HandProfile,
    loaded: &teleop_retarget::Loaded,
    mode: RetargetMode,
    trajectories: &[Vec<GloveState>],
) -> anyhow::Result<Summary> {
    let mut config = loaded.config.retarget.clone();
    config.mode = Some(mode);
    let scaling = config.fingertip.scaling.unwrap_or(profile.retarget.scaling);
    let mut retargeter = Retargeter::new(config, loaded.calibration, profile)?;
    let mut evaluation = Evaluation::new(profile, &retargeter, scaling);
    for samples in trajectories {
        retargeter.reset();
        evaluation.new_trajectory();
        for s in samples {
            let input = GloveInput {
                t_ns: s.header.origin_ns,
                raw: s.raw_position,
            };
            let start = Instant::now();
            let targets = retargeter.step(&input);
            let took = start.elapsed().as_nanos() as u64;
            let closure = retargeter.calibration().closure(&input.raw);
            let iterations = retargeter.solve_report().map_or(0, |r| r.iterations);
            evaluation.record(input.t_ns, &closure, &targets, took, iterations);
        }
    }
    Ok(evaluation.summary())
}

/// Formats one row: a label and one cell per mode.
fn row(label: &str, cells: impl IntoIterator<Item = String>) -> String {
    let mut line = format!("  {label:<32}");
    for c in cells {
        line.push_str(&format!("{c:>22}"));
    }
    line
}

/// Prints the table of one group of recordings.
fn print_table(modes: &[RetargetMode], summaries: &[Summary]) {
    println!("{}", row("", modes.iter().map(|m| m.name().to_string())));
    let each = |f: &dyn Fn(&Summary) -> String| summaries.iter().map(f).collect::<Vec<_>>();
    println!("{}", row("frames", each(&|s| s.frames.to_string())));
    println!(
        "{}",
        row(
            "fingertip error p50/p95 (mm)",
            each(&|s| format!(
                "{:.1} / {:.1}",
                s.fingertip_error_mm.p50, s.fingertip_error_mm.p95
            ))
        )
    );
    println!(
        "{}",
        row(
            "operator pinch frames",
            each(&|s| s.pinch_gap_mm.count.to_string())
        )
    );
    println!(
        "{}",
        row(
            "robot pinch gap p50/p95 (mm)",
            each(&|s| if s.pinch_gap_mm.count == 0 {
                "-".to_string()
            } else {
                format!("{:.1} / {:.1}", s.pinch_gap_mm.p50, s.pinch_gap_mm.p95)
            })
        )
    );
    println!(
        "{}",
        row(
            &format!("pinch frames under {:.0} mm", ROBOT_PINCH_M * 1e3),
            each(&|s| s
                .pinch_made
                .map_or("-".to_string(), |m| format!("{:.1} %", m * 100.0)))
        )
    );
    for (i, finger) in ["index", "middle", "ring", "little"].iter().enumerate() {
        if summaries.iter().all(|s| s.pinches_by_finger[i].0 == 0) {
            continue;
        }
        println!(
            "{}",
            row(
                &format!("  thumb-{finger} made / frames"),
                each(&|s| format!(
                    "{} / {}",
                    s.pinches_by_finger[i].1, s.pinches_by_finger[i].0
                ))
            )
        );
    }
    println!(
        "{}",
        row(
            "joints at a limit",
            each(&|s| format!("{:.1} %", s.saturation * 100.0))
        )
    );
    println!(
        "{}",
        row(
            "jerk RMS (rad/s^3)",
            each(&|s| format!("{:.0}", s.jerk_rms))
        )
    );
    println!(
        "{}",
        row(
            "fingertip jerk RMS, p95 (m/s^3)",
            each(&|s| format!("{:.0}, {:.0}", s.fingertip_jerk_rms, s.fingertip_jerk.p95))
        )
    );
    println!(
        "{}",
        row(
            "solver iterations p50/p99/max",
            each(&|s| format!(
                "{:.0}/{:.0}/{:.0}",
                s.iterations.p50, s.iterations.p99, s.iterations.max
            ))
        )
    );
    println!(
        "{}",
        row(
            "step time p50/p99/max (us)",
            each(&|s| format!(
                "{:.1}/{:.1}/{:.0}",
                s.solve_us.p50, s.solve_us.p99, s.solve_us.max
            ))
        )
    );
}

/// `teleop retarget eval`.
pub fn eval_cmd(opts: &EvalOptions) -> anyhow::Result<ExitCode> {
    let profile = hand_profile(&opts.hand)?;
    let loaded = teleop_retarget::load(
        opts.config.as_deref(),
        opts.calibration.as_deref(),
        Some(profile.clone()),
    )?;
    let mut trajectories = Vec::new();
    for path in &opts.recordings {
        trajectories.push(glove_samples(path, opts.namespace.as_ref())?);
    }
    println!(
        "hand `{}` ({}), scaling {}; operator pinch: thumb-finger pads under {:.0} mm in the \
         operator model; gaps are between pad surfaces",
        profile.name,
        profile.model,
        loaded
            .config
            .retarget
            .fingertip
            .scaling
            .unwrap_or(profile.retarget.scaling),
        OPERATOR_PINCH_M * 1e3
    );
    let groups: Vec<(String, Vec<Vec<GloveState>>)> = if trajectories.len() > 1 {
        opts.recordings
            .iter()
            .zip(&trajectories)
            .map(|(p, t)| (p.display().to_string(), vec![t.clone()]))
            .chain(std::iter::once((
                "all recordings".to_string(),
                trajectories.clone(),
            )))
            .collect()
    } else {
        vec![(opts.recordings[0].display().to_string(), trajectories)]
    };
    for (name, group) in &groups {
        println!("\n{name}");
        let summaries = opts
            .modes
            .iter()
            .map(|&m| evaluate(&profile, &loaded, m, group))
            .collect::<anyhow::Result<Vec<_>>>()?;
        print_table(&opts.modes, &summaries);
    }
    println!("\nreach (20000 random joint vectors within the limits):");
    for (i, finger) in ["index", "middle", "ring", "little"].iter().enumerate() {
        if let Some((closest, share)) = pinch_reach(&profile, i + 1, 20_000) {
            println!(
                "  thumb-{finger}: closest pad gap {:.1} mm; {:.2} % of the joint space within {:.0} mm",
                closest * 1e3,
                share * 100.0,
                ROBOT_PINCH_M * 1e3
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
