//! `teleop-feedback`: the force-feedback process. Subscribes to `hand/tactile`, `hand/state`,
//! `hand/command` and `estop`, runs [`teleop_feedback::ForceFeedback`] and publishes
//! `glove/force_command`.
//!
//! It steps on every tactile sample (on every hand state when the hand has no tactile data), and
//! at least every `tick_ms` so that stale inputs ramp the force to zero even when nothing
//! arrives. An engaged e-stop zeroes every force at once until it is released.
//!
//! Owns only the plumbing between the topics and the force-feedback library.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Parser;
use teleop_feedback::{FeedbackConfig, ForceFeedback, HandInput, Inputs, Tactile, TactileInput};
use teleop_msgs::{
    force_flags, units, EStop, GloveForceCommand, HandCommand, HandState, Tactile as TactileMsg,
};
use teleop_runtime::{
    init_logging, load_toml, now_ns, EventLoop, Flow, Health, Input, IpcSettings, NodeRuntime,
    Subscriber, Wake,
};

#[derive(Parser)]
#[command(version, about = "Tactile + hand state -> glove force command")]
struct Args {
    /// Node configuration (TOML); defaults are used without it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// iceoryx2 node name.
    #[arg(long, default_value = "feedback")]
    name: String,
}

/// The node's configuration file.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
struct NodeConfig {
    /// Tactile data older than this is stale (forces ramp to zero).
    tactile_timeout_ms: u64,
    /// Hand state older than this is stale.
    hand_timeout_ms: u64,
    /// Longest time between two published force commands.
    tick_ms: u64,
    /// Health report period.
    health_period_ms: u64,
    /// The force-feedback law.
    feedback: FeedbackConfig,
}

impl Default for NodeConfig {
    fn default() -> Self {
        Self {
            tactile_timeout_ms: 100,
            hand_timeout_ms: 100,
            tick_ms: 10,
            health_period_ms: 500,
            feedback: FeedbackConfig::default(),
        }
    }
}

fn main() -> ExitCode {
    init_logging();
    let args = Args::parse();
    let result = load(&args).and_then(|config| {
        let law = ForceFeedback::new(config.feedback.clone())?;
        let runtime = NodeRuntime::new(&args.name, &IpcSettings::from_env())?;
        run(&runtime, &config, law)
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("stopping: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn load(args: &Args) -> anyhow::Result<NodeConfig> {
    let Some(path) = &args.config else {
        return Ok(NodeConfig::default());
    };
    let config: NodeConfig = load_toml(path)?;
    config
        .feedback
        .validate()
        .map_err(|e| e.with_origin(&path.display().to_string()))?;
    Ok(config)
}

/// The node's view of its inputs at one instant, turned into the law's [`Inputs`].
fn inputs(
    now: Instant,
    config: &NodeConfig,
    tactile: &Subscriber<TactileMsg>,
    state: &Subscriber<HandState>,
    command: &Subscriber<HandCommand>,
    estop: bool,
) -> (Inputs, u64) {
    let tactile_timeout = Duration::from_millis(config.tactile_timeout_ms);
    let hand_timeout = Duration::from_millis(config.hand_timeout_ms);
    let mut origin = 0;
    let tactile_input = match tactile.latest() {
        None => Tactile::Absent,
        Some(_) if !tactile.is_fresh(now, tactile_timeout) => Tactile::Stale,
        Some(msg) => {
            origin = msg.header.origin_ns;
            Tactile::Fresh(tactile_from_msg(&msg))
        }
    };
    let hand = match state.latest() {
        Some(msg) if state.is_fresh(now, hand_timeout) && msg.link_up != 0 => {
            if origin == 0 {
                origin = msg.header.origin_ns;
            }
            Some(hand_from_msgs(&msg, command.latest().as_ref()))
        }
        _ => None,
    };
    let t_ns = now_ns();
    (
        Inputs {
            t_ns,
            tactile: tactile_input,
            hand,
            estop,
        },
        origin,
    )
}

fn tactile_from_msg(msg: &TactileMsg) -> TactileInput {
    let mut input = TactileInput::default();
    for (i, tip) in msg
        .active_fingertips()
        .iter()
        .enumerate()
        .take(input.valid.len())
    {
        input.normal_n[i] = tip.normal_n;
        input.valid[i] = tip.is_valid();
    }
    input
}

/// Joint state plus the commanded positions; without a usable command the measured positions
/// stand in (no position error).
fn hand_from_msgs(state: &HandState, command: Option<&HandCommand>) -> HandInput {
    let mut input = HandInput::default();
    let normalised = state.units == units::NORMALISED;
    for (i, joint) in state
        .active_joints()
        .iter()
        .enumerate()
        .take(input.measured.len())
    {
        input.measured[i] = if normalised { joint.position } else { 0.0 };
        input.commanded[i] = input.measured[i];
        input.current_ma[i] = joint.current_ma;
    }
    if let Some(cmd) = command.filter(|c| normalised && c.units == units::NORMALISED) {
        for (i, joint) in cmd
            .active_joints()
            .iter()
            .enumerate()
            .take(input.commanded.len())
        {
            input.commanded[i] = joint.target;
        }
    }
    input
}

fn run(runtime: &NodeRuntime, config: &NodeConfig, mut law: ForceFeedback) -> anyhow::Result<()> {
    let tactile = runtime.subscriber::<TactileMsg>()?;
    let state = runtime.subscriber::<HandState>()?;
    let command = runtime.subscriber::<HandCommand>()?;
    let estop = runtime.subscriber::<EStop>()?;
    let mut forces = runtime.publisher::<GloveForceCommand>()?;
    let mut health = Health::new(runtime)?;
    let health_period = Duration::from_millis(config.health_period_ms.max(10));
    let mut last_health = Instant::now();
    let mut estop_engaged = estop.poll_latest().is_some_and(|e| e.engaged != 0);
    let mut was_stale = false;
    if estop_engaged {
        tracing::warn!("e-stop engaged at start: glove forces held at zero");
    }
    tracing::info!("force feedback hand/tactile + hand/state -> glove/force_command");

    const TACTILE: usize = 0;
    const STATE: usize = 1;
    const COMMAND: usize = 2;
    const ESTOP: usize = 3;
    let mut on_wake = |wake: Wake| -> anyhow::Result<()> {
        let step = match wake {
            Wake::Input(TACTILE) => tactile.drain(|_| {}) > 0,
            Wake::Input(STATE) => state.drain(|_| {}) > 0 && tactile.latest().is_none(),
            Wake::Input(COMMAND) => {
                command.drain(|_| {});
                false
            }
            Wake::Input(ESTOP) => {
                estop.drain(|_| {});
                let engaged = estop.latest().is_some_and(|e| e.engaged != 0);
                if engaged != estop_engaged {
                    if engaged {
                        tracing::warn!("e-stop engaged: all glove forces zero");
                    } else {
                        tracing::info!("e-stop released");
                    }
                    estop_engaged = engaged;
                }
                true
            }
            Wake::Timeout(i) => {
                let which = if i == TACTILE {
                    "hand/tactile"
                } else {
                    "hand/state"
                };
                tracing::debug!(input = which, "input deadline missed");
                true
            }
            Wake::Input(_) | Wake::Tick => true,
        };
        if step {
            let now = Instant::now();
            let (inputs, origin) = inputs(now, config, &tactile, &state, &command, estop_engaged);
            let out = law.step(&inputs);
            if out.stale && !was_stale {
                tracing::warn!("no fresh tactile/hand input: glove forces ramp to zero");
                health.count_timeout();
            } else if !out.stale && was_stale {
                tracing::info!("inputs fresh again");
            }
            was_stale = out.stale;
            if out.clamped > 0 {
                tracing::debug!(fingers = out.clamped, "force saturated at max_force");
            }
            health.count_clamps(u64::from(out.clamped));
            health.count_loop();
            let mut msg = GloveForceCommand {
                force: out.force,
                ..Default::default()
            };
            msg.header.origin_ns = origin;
            for (slot, source) in msg.source.iter_mut().zip(out.source) {
                *slot = source as u8;
            }
            if out.stale {
                msg.flags |= force_flags::STALE;
            }
            if estop_engaged {
                msg.flags |= force_flags::ESTOP;
            }
            if out.clamped > 0 {
                msg.flags |= force_flags::CLAMPED;
            }
            forces.publish(&msg)?;
            let mut detail = [0u8; 7];
            detail[..5].copy_from_slice(&msg.source);
            health.set_detail(detail);
        }
        if last_health.elapsed() >= health_period {
            last_health = Instant::now();
            health.set_dropped(tactile.dropped() + state.dropped());
            let now = Instant::now();
            health.publish(&[tactile.age(now), state.age(now)])?;
        }
        Ok(())
    };
    let stop = EventLoop::new(Duration::from_millis(config.tick_ms.max(1))).run(
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
        ],
        |wake| match on_wake(wake) {
            Ok(()) => Flow::Continue(()),
            Err(e) => {
                tracing::error!("{e:#}");
                Flow::Break(())
            }
        },
    )?;
    // Leave the glove unloaded.
    forces.publish(&GloveForceCommand {
        flags: force_flags::STALE,
        ..Default::default()
    })?;
    tracing::info!(?stop, "stopped; published zero force");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use teleop_feedback::ContactSource;
    use teleop_msgs::contact_source;

    #[test]
    fn contact_source_codes_match_the_contract() {
        assert_eq!(ContactSource::None as u8, contact_source::NONE);
        assert_eq!(ContactSource::Tactile as u8, contact_source::TACTILE);
        assert_eq!(
            ContactSource::PositionError as u8,
            contact_source::POSITION_ERROR
        );
        assert_eq!(ContactSource::Current as u8, contact_source::CURRENT);
        assert_eq!(ContactSource::Ramping as u8, contact_source::RAMPING);
        assert_eq!(ContactSource::EStop as u8, contact_source::ESTOP);
    }

    #[test]
    fn tactile_validity_follows_status_bits_and_count() {
        let mut msg = TactileMsg {
            fingertip_count: 4,
            ..Default::default()
        };
        msg.fingertips[0].normal_n = 2.0;
        msg.fingertips[1].status = teleop_msgs::touch_status::INVALID;
        let t = tactile_from_msg(&msg);
        assert_eq!(t.valid, [true, false, true, true, false]);
        assert_eq!(t.normal_n[0], 2.0);
    }

    #[test]
    fn hand_input_uses_command_targets_when_units_match() {
        let mut state = HandState {
            joint_count: 6,
            units: units::NORMALISED,
            ..Default::default()
        };
        state.joints[2].position = 0.4;
        state.joints[2].current_ma = 350.0;
        let mut cmd = HandCommand {
            joint_count: 6,
            units: units::NORMALISED,
            ..Default::default()
        };
        cmd.joints[2].target = 0.9;
        let h = hand_from_msgs(&state, Some(&cmd));
        assert_eq!(
            (h.measured[2], h.commanded[2], h.current_ma[2]),
            (0.4, 0.9, 350.0)
        );
        let h = hand_from_msgs(&state, None);
        assert_eq!(h.commanded[2], 0.4, "no command: no position error");
    }
}
