//! `teleop-retarget`: the retargeting process. Subscribes to `glove/state`, runs
//! [`teleop_retarget::Retargeter`] on every sample and publishes `hand/command` for the Revo2
//! (normalised position targets with the slew limit as speed limit). A stale glove (no sample
//! within `glove_timeout_ms`, or the glove reports its link down) makes it repeat the last
//! command flagged as held: the hand holds, never drifts.
//!
//! Owns only the plumbing between the topics and the retargeting library; the logic lives in
//! `teleop-retarget`, the IPC in `teleop-runtime`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use teleop_msgs::{command_flags, control_mode, hand_model, units, GloveState, HandCommand};
use teleop_retarget::{Calibration, GloveInput, JointTargets, RetargetConfig, Retargeter};
use teleop_runtime::{
    init_logging, load_toml, EventLoop, Flow, Health, Input, IpcSettings, NodeRuntime, Wake,
};

#[derive(Parser)]
#[command(version, about = "Glove state -> hand command (Revo2)")]
struct Args {
    /// Node configuration (TOML); defaults are used without it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Operator calibration profile (TOML); overrides the one named in the configuration.
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// iceoryx2 node name.
    #[arg(long, default_value = "retarget")]
    name: String,
}

/// The node's configuration file.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
struct NodeConfig {
    /// Calibration profile, relative to the configuration file.
    calibration: Option<PathBuf>,
    /// A glove silent for this long is stale.
    glove_timeout_ms: u64,
    /// Health report period.
    health_period_ms: u64,
    /// The retargeting parameters.
    retarget: RetargetConfig,
}

impl Default for NodeConfig {
    fn default() -> Self {
        Self {
            calibration: None,
            glove_timeout_ms: 100,
            health_period_ms: 500,
            retarget: RetargetConfig::default(),
        }
    }
}

fn main() -> ExitCode {
    init_logging();
    let args = Args::parse();
    match setup(&args).and_then(|(config, retargeter)| {
        let runtime = NodeRuntime::new(&args.name, &IpcSettings::from_env())?;
        run(&runtime, &config, retargeter)
    }) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("stopping: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn setup(args: &Args) -> anyhow::Result<(NodeConfig, Retargeter)> {
    let (config, base) = match &args.config {
        Some(path) => (
            load_toml::<NodeConfig>(path)?,
            path.parent().map(PathBuf::from).unwrap_or_default(),
        ),
        None => (NodeConfig::default(), PathBuf::new()),
    };
    let origin = args
        .config
        .as_ref()
        .map_or("defaults".to_string(), |p| p.display().to_string());
    config
        .retarget
        .validate()
        .map_err(|e| e.with_origin(&origin))?;
    let calibration_path = args
        .calibration
        .clone()
        .or_else(|| config.calibration.as_ref().map(|p| base.join(p)));
    let calibration = match &calibration_path {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("{}: cannot read calibration", path.display()))?;
            let cal = Calibration::from_toml_str(&text, &path.display().to_string())?;
            tracing::info!(path = %path.display(), "calibration profile loaded");
            cal
        }
        None => {
            tracing::info!("no calibration profile: using the full 0..1000 range");
            Calibration::default()
        }
    };
    let retargeter = Retargeter::new(config.retarget.clone(), calibration)?;
    Ok((config, retargeter))
}

/// The hand command for `targets`, descending from the glove sample stamped `origin_ns`.
fn hand_command(targets: &JointTargets, origin_ns: u64) -> HandCommand {
    let mut cmd = HandCommand {
        hand_model: hand_model::REVO2,
        joint_count: targets.position.len() as u8,
        control_mode: control_mode::POSITION,
        units: units::NORMALISED,
        ..Default::default()
    };
    cmd.header.origin_ns = origin_ns;
    for (joint, &target) in cmd.joints.iter_mut().zip(&targets.position) {
        joint.target = target;
        joint.speed_limit = targets.max_speed;
    }
    if targets.held {
        cmd.flags |= command_flags::HELD;
    }
    if targets.clamped > 0 {
        cmd.flags |= command_flags::CLAMPED;
    }
    if targets.slew_limited > 0 {
        cmd.flags |= command_flags::SLEW_LIMITED;
    }
    cmd
}

fn run(
    runtime: &NodeRuntime,
    config: &NodeConfig,
    mut retargeter: Retargeter,
) -> anyhow::Result<()> {
    let glove = runtime.subscriber::<GloveState>()?;
    let mut commands = runtime.publisher::<HandCommand>()?;
    let mut health = Health::new(runtime)?;
    let timeout = Duration::from_millis(config.glove_timeout_ms.max(1));
    let health_period = Duration::from_millis(config.health_period_ms.max(10));
    let mut stale = true;
    let mut last_origin = 0;
    let mut last_health = Instant::now();
    tracing::info!(
        timeout_ms = config.glove_timeout_ms,
        "retargeting glove/state -> hand/command"
    );

    let mut on_wake = |wake: Wake| -> anyhow::Result<()> {
        match wake {
            Wake::Input(_) => {
                let mut link_down = false;
                let mut outputs = Vec::new();
                glove.drain(|s| {
                    if s.link_up == 0 {
                        link_down = true;
                        return;
                    }
                    let input = GloveInput {
                        t_ns: s.header.origin_ns,
                        raw: s.raw_position,
                    };
                    outputs.push((retargeter.step(&input), s.header.origin_ns));
                });
                for (targets, origin) in outputs {
                    if stale {
                        tracing::info!("glove input fresh again: following the operator");
                        stale = false;
                    }
                    health.count_loop();
                    health.count_clamps(u64::from(targets.clamped));
                    last_origin = origin;
                    commands.publish(&hand_command(&targets, origin))?;
                }
                if link_down && !stale {
                    tracing::warn!("glove reports its link down: holding the hand");
                    stale = true;
                    health.count_timeout();
                }
                if link_down {
                    hold(&retargeter, &mut commands, last_origin)?;
                }
            }
            Wake::Timeout(_) => {
                if !stale {
                    tracing::warn!(
                        timeout_ms = config.glove_timeout_ms,
                        "glove input stale: holding the hand"
                    );
                    stale = true;
                    health.count_timeout();
                }
                hold(&retargeter, &mut commands, last_origin)?;
            }
            Wake::Tick => {}
        }
        if last_health.elapsed() >= health_period {
            last_health = Instant::now();
            health.set_dropped(glove.dropped());
            health.publish(&[glove.age(Instant::now())])?;
        }
        Ok(())
    };
    let stop = EventLoop::new(health_period).run(
        &[Input::with_deadline(glove.listener(), timeout)],
        |wake| match on_wake(wake) {
            Ok(()) => Flow::Continue(()),
            Err(e) => {
                tracing::error!("{e:#}");
                Flow::Break(())
            }
        },
    )?;
    tracing::info!(?stop, "stopped");
    Ok(())
}

/// Publishes the last command again, flagged as held (nothing before the first glove sample).
fn hold(
    retargeter: &Retargeter,
    commands: &mut teleop_runtime::Publisher<HandCommand>,
    origin: u64,
) -> anyhow::Result<()> {
    if let Some(targets) = retargeter.hold() {
        commands.publish(&hand_command(&targets, origin))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_command_carries_targets_in_revo2_order_with_flags() {
        let targets = JointTargets {
            position: [0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
            max_speed: 3.0,
            held: true,
            clamped: 1,
            slew_limited: 0,
        };
        let cmd = hand_command(&targets, 77);
        assert_eq!(cmd.header.origin_ns, 77);
        assert_eq!(cmd.joint_count, 6);
        assert_eq!(cmd.hand_model, hand_model::REVO2);
        let t: Vec<f32> = cmd.active_joints().iter().map(|j| j.target).collect();
        assert_eq!(t, vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
        assert!(cmd.active_joints().iter().all(|j| j.speed_limit == 3.0));
        assert_eq!(cmd.flags, command_flags::HELD | command_flags::CLAMPED);
    }

    #[test]
    fn config_file_errors_name_the_field() {
        let err = teleop_runtime::parse_toml::<NodeConfig>("glove_timeout = 5\n", "r.toml")
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("r.toml: ") && err.contains("glove_timeout"),
            "{err}"
        );
        let cfg: NodeConfig =
            teleop_runtime::parse_toml("[retarget]\nmax_speed = 2.0\n", "r.toml").unwrap();
        assert_eq!(cfg.retarget.max_speed, 2.0);
        assert_eq!(cfg.glove_timeout_ms, 100);
    }
}
