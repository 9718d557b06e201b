//! `teleop-retarget`: the retargeting process. Subscribes to `glove/state`, runs the
//! [`RetargetEngine`] on every sample and publishes `hand/command` for the hand its profile
//! describes (position targets, normalised or in radians as the profile says, with the slew limit
//! as speed limit). A stale glove (its newest sample older than `glove_timeout_ms` by its stamp,
//! or the glove reports its link down) makes it repeat the last command flagged as held: the
//! hand holds, never drifts. When that happens is the engine's schedule; the loop only wakes.
//!
//! Owns only the plumbing between the topics and the engine.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Parser;
use teleop_hand_profile::HandProfile;
use teleop_msgs::{GloveState, HandCommand};
use teleop_retarget::{load, Loaded, NodeConfig, Output, RetargetEngine};
use teleop_runtime::{
    node_main, now_ns, EventLoop, Health, Input, NodeArgs, NodeRuntime, Publisher, Wake,
};

#[derive(Parser)]
#[command(
    version,
    about = "Glove state -> hand command, for the hand a profile describes"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
    /// Operator calibration profile (TOML); overrides the one named in the configuration.
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// Hand profile (config/hands/<hand>.toml); overrides `hand_profile` in the configuration.
    #[arg(long)]
    profile: Option<PathBuf>,
}

fn main() -> ExitCode {
    node_main("retarget", start)
}

/// Loads everything the arguments name, then runs.
fn start(args: Args) -> anyhow::Result<()> {
    let profile = args.profile.as_deref().map(HandProfile::load).transpose()?;
    let Loaded {
        config,
        calibration,
        calibration_path,
        profile,
    } = load(
        args.node.config.as_deref(),
        args.calibration.as_deref(),
        profile,
    )?;
    match &calibration_path {
        Some(p) => tracing::info!(path = %p.display(), "calibration profile loaded"),
        None => tracing::info!("no calibration profile: using the full 0..1000 range"),
    }
    let mode = config.retarget.mode.unwrap_or(profile.retarget.mode);
    tracing::info!(
        hand = %profile.name,
        joints = profile.joints.len(),
        mode = mode.name(),
        "hand profile loaded"
    );
    let engine = RetargetEngine::new(&config, calibration, &profile)?;
    run(&args.node.runtime()?, &config, engine)
}

fn run(
    runtime: &NodeRuntime,
    config: &NodeConfig,
    mut engine: RetargetEngine,
) -> anyhow::Result<()> {
    let glove = runtime.subscriber::<GloveState>()?;
    let mut commands = runtime.publisher::<HandCommand>()?;
    let mut health = Health::new(runtime)?;
    let timeout = Duration::from_millis(config.glove_timeout_ms.max(1));
    let health_period = Duration::from_millis(config.health_period_ms.max(10));
    let mut last_health = Instant::now();
    tracing::info!(
        timeout_ms = config.glove_timeout_ms,
        "retargeting glove/state -> hand/command"
    );

    let emit = |out: Output,
                commands: &mut Publisher<HandCommand>,
                health: &mut Health|
     -> anyhow::Result<()> {
        if out.became_fresh {
            tracing::info!("glove input fresh: following the operator");
        }
        if out.became_stale {
            tracing::warn!(
                timeout_ms = config.glove_timeout_ms,
                "glove input stale or link down: holding the hand"
            );
            health.count_timeout();
        }
        health.count_clamps(u64::from(out.clamped));
        if let Some(cmd) = out.command {
            commands.publish(&cmd)?;
        }
        Ok(())
    };
    let on_wake = |wake: Wake| -> anyhow::Result<()> {
        // The engine's glove watchdog, whatever woke the loop (the input's deadline is the
        // wake-up for it): what fell due by now, in time order, before any newer sample.
        while let Some((_, out)) = engine.poll(now_ns()) {
            emit(out, &mut commands, &mut health)?;
        }
        if let Wake::Input(_) = wake {
            let mut outs = Vec::new();
            glove.drain(|s| outs.push(engine.on_glove(s, now_ns())));
            for out in outs {
                health.count_loop();
                emit(out, &mut commands, &mut health)?;
            }
        }
        if last_health.elapsed() >= health_period {
            last_health = Instant::now();
            health.set_dropped(glove.dropped());
            health.publish(&[glove.age(Instant::now())])?;
        }
        Ok(())
    };
    let stop = EventLoop::new(health_period)
        .try_run(&[Input::with_deadline(glove.listener(), timeout)], on_wake)?
        // An error in the loop is a failure: the process exits non-zero and its supervisor
        // restarts it.
        .map_err(|e| e.context("retargeting loop failed"))?;
    tracing::info!(?stop, "stopped");
    Ok(())
}
