//! `teleop-feedback`: the force-feedback process. Subscribes to `hand/tactile`, `hand/state`,
//! `hand/command`, `glove/state` (the passivity observer's finger motion), `health` (the
//! bridge's link delay) and `estop`, runs the [`FeedbackEngine`] on every sample and on its schedule (a
//! tick every `tick_ms`, so stale inputs ramp the force to zero even when nothing arrives, and
//! each input's watchdog), and publishes
//! `glove/force_command`. An engaged e-stop zeroes every force at once until it is released; it
//! is latched outside the process (`teleop_runtime::EStopInput`), so a restart keeps it.
//!
//! Owns only the plumbing between the topics and the engine.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Parser;
use teleop_feedback::{load, Event, FeedbackEngine, NodeConfig, Output};
use teleop_hand_profile::HandProfile;
use teleop_msgs::{
    force_flags, EStop, GloveForceCommand, GloveState, HandCommand, HandState, NodeHealth, Tactile,
};
use teleop_runtime::{
    node_main, now_ns, EStopInput, EventLoop, Health, Input, NodeArgs, NodeRuntime, Publisher, Wake,
};

/// The health details of the force feedback: per glove finger (`GLOVE_FINGERS` order), where
/// its force came from (a `contact_source` value).
const SOURCE_DETAILS: [&str; 5] = [
    "source_little",
    "source_ring",
    "source_middle",
    "source_index",
    "source_thumb",
];

#[derive(Parser)]
#[command(version, about = "Tactile + hand state -> glove force command")]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
    /// Hand profile (config/hands/<hand>.toml); overrides `hand_profile` in the configuration.
    #[arg(long)]
    profile: Option<PathBuf>,
}

fn main() -> ExitCode {
    node_main("feedback", start)
}

/// Logs, counts and publishes what one event did.
fn emit(
    out: Output,
    forces: &mut Publisher<GloveForceCommand>,
    health: &mut Health,
) -> anyhow::Result<()> {
    match out.estop_changed {
        Some(true) => tracing::warn!("e-stop engaged: all glove forces zero"),
        Some(false) => tracing::info!("e-stop released"),
        None => {}
    }
    if out.became_stale {
        tracing::warn!("no fresh tactile/hand input: glove forces ramp to zero");
        health.count_timeout();
    }
    if out.became_fresh {
        tracing::info!("inputs fresh again");
    }
    health.count_clamps(u64::from(out.clamped));
    if let Some(cmd) = out.command {
        health.count_loop();
        forces.publish(&cmd)?;
        for (name, source) in SOURCE_DETAILS.iter().zip(cmd.source) {
            health.set_detail(name, f64::from(source));
        }
    }
    Ok(())
}

/// The engine's e-stop event for the latched state.
fn estop_sample(engaged: bool) -> EStop {
    EStop {
        engaged: u8::from(engaged),
        ..Default::default()
    }
}

/// Loads everything the arguments name, then runs.
fn start(args: Args) -> anyhow::Result<()> {
    let profile = args.profile.as_deref().map(HandProfile::load).transpose()?;
    let (config, profile) = load(args.node.config.as_deref(), profile)?;
    tracing::info!(hand = %profile.name, "hand profile loaded");
    let engine = FeedbackEngine::new(&config, &profile)?;
    run(&args.node.runtime()?, &config, engine)
}

fn run(
    runtime: &NodeRuntime,
    config: &NodeConfig,
    mut engine: FeedbackEngine,
) -> anyhow::Result<()> {
    let tactile = runtime.subscriber::<Tactile>()?;
    let state = runtime.subscriber::<HandState>()?;
    let command = runtime.subscriber::<HandCommand>()?;
    let glove = runtime.subscriber::<GloveState>()?;
    let reports = runtime.subscriber::<NodeHealth>()?;
    let mut forces = runtime.publisher::<GloveForceCommand>()?;
    // The latched e-stop: engaged before this node started (or while it restarted) is in the
    // latch file.
    let estop = EStopInput::new(runtime)?;
    let mut health = Health::new(runtime)?;
    let health_period = Duration::from_millis(config.health_period_ms.max(10));
    let mut last_health = Instant::now();
    if estop.engaged() {
        emit(
            engine.handle(&Event::EStop(estop_sample(true)), now_ns()),
            &mut forces,
            &mut health,
        )?;
    }
    tracing::info!("force feedback hand/tactile + hand/state -> glove/force_command");

    // The ticks fall every tick_ms from here (the loop's tick, attached just after, is the
    // wake-up for them; the inputs' deadlines for their watchdogs).
    engine.start(now_ns());
    let on_wake = |wake: Wake| -> anyhow::Result<()> {
        // The engine's ticks and watchdogs, whatever woke the loop: what fell due by now, in
        // time order, before any newer sample.
        while let Some((_, out)) = engine.poll(now_ns()) {
            emit(out, &mut forces, &mut health)?;
        }
        let mut events = Vec::new();
        // The e-stop on every wake: its doorbell, or its latch read every LATCH_POLL when the
        // doorbell could not be rung.
        if let Some(engaged) = estop.update()? {
            events.push(Event::EStop(estop_sample(engaged)));
        }
        let _taken = match wake {
            Wake::Input(0) => tactile.drain(|t| events.push(Event::Tactile(*t))),
            Wake::Input(1) => state.drain(|s| events.push(Event::State(*s))),
            Wake::Input(2) => command.drain(|c| events.push(Event::Command(*c))),
            Wake::Input(4) => glove.drain(|g| events.push(Event::Glove(*g))),
            Wake::Input(5) => reports.drain(|h| events.push(Event::Health(*h))),
            Wake::Input(_) | Wake::Timeout(_) | Wake::Tick => 0,
        };
        for event in &events {
            emit(engine.handle(event, now_ns()), &mut forces, &mut health)?;
        }
        if last_health.elapsed() >= health_period {
            last_health = Instant::now();
            health.set_dropped(tactile.dropped() + state.dropped() + glove.dropped());
            let allowance = engine.link_allowance_ns(now_ns());
            health.set_detail("link_delay_ms", allowance as f64 / 1e6);
            health.set_detail("passivity_acted", engine.passivity_acted() as f64);
            health.set_detail("passivity_energy", f64::from(engine.passivity_energy()));
            let now = Instant::now();
            health.publish(&[tactile.age(now), state.age(now)])?;
        }
        Ok(())
    };
    let stopped = EventLoop::new(Duration::from_millis(config.tick_ms.max(1))).try_run(
        &[
            Input::with_deadline(
                tactile.listener(),
                Duration::from_millis(config.tactile_timeout_ms.max(1)),
            ),
            Input::with_deadline(
                state.listener(),
                Duration::from_millis(config.hand_timeout_ms.max(1)),
            ),
            Input::new(command.listener()),
            Input::new(estop.listener()),
            Input::new(glove.listener()),
            Input::new(reports.listener()),
        ],
        on_wake,
    )?;
    // Leave the glove unloaded.
    forces.publish(&GloveForceCommand {
        flags: force_flags::STALE,
        ..Default::default()
    })?;
    match stopped {
        // An error in the loop is a failure: the process exits non-zero and its supervisor
        // restarts it.
        Err(e) => Err(e.context("force feedback loop failed; published zero force")),
        Ok(stop) => {
            tracing::info!(?stop, "stopped; published zero force");
            Ok(())
        }
    }
}
