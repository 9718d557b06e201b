//! The node: the torque loop ([`crate::driver`]) with the node's ports as its host: hand commands
//! in (stale `stale_command_ms` after their stamp, none followed while the latched e-stop is
//! engaged: the hand holds its last target), hand state out every cycle, the link state while
//! the hand is down, health and device info periodically.

use std::time::{Duration, Instant};

use teleop_allegro_protocol::{v4, Generation, JOINTS};
use teleop_can_link::{Bitrate, BusState};
use teleop_hand_profile::HandProfile;
use teleop_msgs::{
    bus_state, control_mode, device_model, fixed_text, link_kind, units, DeviceInfo, HandCommand,
    HandState,
};
use teleop_runtime::{EStopInput, Health, NodeRuntime, Publisher, Subscriber};

use crate::config::Settings;
use crate::driver::{self, Connected, Counters, Cycle, Down, Host, Target};

/// The Allegro's CAN bit rate (the device document).
pub const BITRATE: Bitrate = Bitrate(1_000_000);

/// The contract's bus state of a CAN controller state.
pub fn bus_state_code(s: BusState) -> u8 {
    match s {
        BusState::ErrorActive | BusState::ErrorWarning => bus_state::CAN_ERROR_ACTIVE,
        BusState::ErrorPassive => bus_state::CAN_ERROR_PASSIVE,
        BusState::BusOff => bus_state::CAN_BUS_OFF,
    }
}

fn saturate(v: u64) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}

/// The `hand/state` sample of one cycle: positions (rad), filtered velocities (rad/s), efforts
/// = the commanded torques (N m), no current (NaN), `status` = the joint's temperature in deg C
/// where the hand reports it (v4), else 0. `link_errors` counts cycles with a missing finger
/// frame or a bus error, `lost_frames` the finger frames missing.
pub fn hand_state(cycle: &Cycle) -> HandState {
    let mut state = HandState {
        hand_model: device_model::ALLEGRO,
        joint_count: JOINTS as u8,
        units: units::PHYSICAL,
        holding: u8::from(cycle.holding),
        link_up: 1,
        link_kind: link_kind::CAN,
        bus_state: bus_state_code(cycle.bus_state),
        link_errors: saturate(cycle.counters.link_errors()),
        lost_frames: saturate(cycle.counters.lost_frames),
        ..Default::default()
    };
    for (j, joint) in state.joints.iter_mut().take(JOINTS).enumerate() {
        joint.position = cycle.q[j] as f32;
        joint.speed = cycle.qdot[j] as f32;
        joint.effort = cycle.torque[j] as f32;
        joint.current_ma = f32::NAN;
        joint.status = cycle.temperatures[j].map_or(0, u32::from);
    }
    state.header.origin_ns = cycle.received_ns;
    state
}

/// The `hand/state` sample while the hand is down.
pub fn link_down_state(counters: &Counters) -> HandState {
    HandState {
        hand_model: device_model::ALLEGRO,
        joint_count: JOINTS as u8,
        units: units::PHYSICAL,
        link_up: 0,
        link_kind: link_kind::CAN,
        link_errors: saturate(counters.link_errors()),
        lost_frames: saturate(counters.lost_frames),
        ..Default::default()
    }
}

/// Firmware text of a hand: v4 hardware and firmware versions, or the document protocol's
/// QUERY_ID answer.
pub fn firmware_text(identity: &crate::bringup::Identity) -> String {
    if let Some(i) = &identity.info {
        format!("hw {:#06x} fw {:#06x}", i.hw_version, i.fw_version)
    } else if let Some((revision, firmware, hw_type)) = identity.doc_id {
        format!("rev {revision} fw {firmware} type {hw_type}")
    } else {
        String::new()
    }
}

/// The identity the hand reported, for the recorder and `teleop echo device/info`.
pub fn device_info(hand: &Connected<'_>, device_id: u8) -> DeviceInfo {
    let serial = hand.identity.serial.as_ref().map(v4::serial_text);
    DeviceInfo {
        device_model: device_model::ALLEGRO,
        link_kind: link_kind::CAN,
        bus_address: u32::from(device_id),
        model_name: fixed_text(&format!("Wonik Allegro Hand {}", hand.generation)),
        firmware_version: fixed_text(&firmware_text(hand.identity)),
        protocol: fixed_text(&hand.generation.to_string()),
        serial_number: fixed_text(serial.as_deref().unwrap_or("")),
        link: fixed_text(hand.link),
        ..Default::default()
    }
}

/// Why a fresh hand command is not followed (None: it is).
pub fn refusal(cmd: &HandCommand) -> Option<&'static str> {
    if cmd.hand_model != device_model::ALLEGRO && cmd.hand_model != device_model::UNKNOWN {
        return Some("hand/command is for another hand model");
    }
    if cmd.units != units::PHYSICAL {
        return Some("hand/command is not in radians (units = physical), which the Allegro takes");
    }
    if cmd.control_mode != control_mode::POSITION {
        return Some(
            "hand/command is not a position command, the only mode the Allegro node follows",
        );
    }
    if usize::from(cmd.joint_count) < JOINTS {
        return Some("hand/command has fewer than the Allegro's 16 joints");
    }
    if cmd.joints[..JOINTS].iter().any(|j| !j.target.is_finite()) {
        return Some("hand/command has a target that is not a number");
    }
    None
}

/// The targets of a command, clamped to the profile's joint limits; the count of clamped ones.
pub fn targets(cmd: &HandCommand, limits: &[(f32, f32); JOINTS]) -> ([f64; JOINTS], u64) {
    let mut out = [0.0; JOINTS];
    let mut clamped = 0;
    for (j, t) in out.iter_mut().enumerate() {
        let v = cmd.joints[j].target;
        let (lo, hi) = limits[j];
        let c = v.clamp(lo, hi);
        clamped += u64::from(c != v);
        *t = f64::from(c);
    }
    (out, clamped)
}

/// The node's ports, the loop's host.
struct Ports {
    device: Publisher<DeviceInfo>,
    connected: Option<DeviceInfo>,
    commands: Subscriber<HandCommand>,
    estop: EStopInput,
    state: Publisher<HandState>,
    health: Health,
    limits: [(f32, f32); JOINTS],
    device_id: u8,
    stale_after: Duration,
    health_period: Duration,
    last_health: Instant,
    following: bool,
    refused: Option<&'static str>,
    errors_counted: u64,
}

impl Ports {
    /// Publishes health (and device info) when due.
    fn health_due(&mut self, counters: &Counters) -> anyhow::Result<()> {
        if self.last_health.elapsed() < self.health_period {
            return Ok(());
        }
        self.last_health = Instant::now();
        let errors = counters.unknown_frames
            + counters.bad_frames
            + counters.bus_errors
            + counters.missing_cycles;
        self.health
            .count_errors(errors.saturating_sub(self.errors_counted));
        self.errors_counted = errors;
        self.health.set_dropped(self.commands.dropped());
        for (name, count) in [
            ("unknown_frames", counters.unknown_frames),
            ("bad_frames", counters.bad_frames),
            ("reconnects", counters.reconnects),
            // Waits the frames' stamps showed were a loaded host's, not the hand's.
            ("late_periods", counters.late_periods),
        ] {
            self.health.set_detail(name, count as f64);
        }
        self.health.publish(&[self.commands.age(Instant::now())])?;
        if let Some(d) = &self.connected {
            self.device.publish(d)?;
        }
        Ok(())
    }
}

impl Host for Ports {
    fn stop_requested(&self) -> bool {
        teleop_runtime::stop_signal().is_some()
    }

    fn target(&mut self) -> Target {
        match self.estop.update() {
            Ok(Some(true)) => tracing::warn!("e-stop engaged: the hand holds its last target"),
            Ok(Some(false)) => tracing::info!("e-stop released: following hand commands"),
            Ok(None) => {}
            Err(e) => {
                self.health.count_error();
                tracing::warn!("e-stop acknowledgement: {e}");
            }
        }
        // Freshness counts from the command's stamp: one from the topic's history, sent
        // before this node (re)started, is stale.
        let cmd = self.commands.poll_latest();
        let fresh = self.commands.is_fresh(Instant::now(), self.stale_after);
        let Some(cmd) = cmd.filter(|_| fresh && !self.estop.engaged()) else {
            if self.following {
                self.following = false;
                self.health.count_timeout();
                tracing::info!("no fresh hand command: holding the last target");
            }
            return Target::Hold;
        };
        if let Some(why) = refusal(&cmd) {
            if self.refused != Some(why) {
                tracing::warn!("{why}: holding the last target");
                self.refused = Some(why);
            }
            self.health.count_error();
            return Target::Hold;
        }
        self.refused = None;
        if !self.following {
            self.following = true;
            tracing::info!("hand commands fresh: following them");
        }
        let (t, clamped) = targets(&cmd, &self.limits);
        self.health.count_clamps(clamped);
        Target::Follow(t)
    }

    fn connected(&mut self, hand: &Connected<'_>) -> anyhow::Result<()> {
        let info = device_info(hand, self.device_id);
        self.device.publish(&info)?;
        self.connected = Some(info);
        let generation = match hand.generation {
            Generation::V1 => 1.0,
            Generation::V2 => 2.0,
            Generation::V3 => 3.0,
            Generation::V4 => 4.0,
        };
        self.health.set_detail("protocol_generation", generation);
        tracing::info!(
            generation = %hand.generation,
            firmware = %firmware_text(hand.identity),
            serial = %hand.identity.serial.as_ref().map(v4::serial_text).unwrap_or_default(),
            "Allegro Hand connected"
        );
        Ok(())
    }

    fn cycle(&mut self, cycle: &Cycle) -> anyhow::Result<()> {
        self.state.publish(&hand_state(cycle))?;
        self.health.count_loop();
        self.health
            .set_detail("bus_state", f64::from(bus_state_code(cycle.bus_state)));
        let hottest = cycle.temperatures.iter().filter_map(|t| *t).max();
        self.health
            .set_detail("max_temperature_c", f64::from(hottest.unwrap_or(0)));
        self.health_due(&cycle.counters)
    }

    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        self.connected = None;
        self.state.publish(&link_down_state(down.counters))?;
        self.health_due(down.counters)
    }
}

/// Runs until SIGINT/SIGTERM, on this thread (which takes the launch file's real-time
/// scheduling).
pub fn run(
    runtime: &NodeRuntime,
    settings: &Settings,
    profile: &HandProfile,
) -> anyhow::Result<()> {
    if profile.joints.len() != JOINTS {
        anyhow::bail!(
            "hand profile {:?} has {} joints; the Allegro has {JOINTS} (index 0-3, middle 4-7, \
             ring 8-11, thumb 12-15)",
            profile.name,
            profile.joints.len()
        );
    }
    let mut limits = [(0.0f32, 0.0f32); JOINTS];
    for (l, j) in limits.iter_mut().zip(&profile.joints) {
        *l = (j.lower, j.upper);
    }
    teleop_runtime::install_stop_handlers();
    let mut ports = Ports {
        device: runtime.publisher()?,
        connected: None,
        commands: runtime.subscriber()?,
        estop: EStopInput::new(runtime)?,
        state: runtime.publisher()?,
        health: Health::new(runtime)?,
        limits,
        device_id: settings.device_id,
        stale_after: settings.stale_command,
        health_period: settings.health_period,
        last_health: Instant::now(),
        following: false,
        refused: None,
        errors_counted: 0,
    };
    tracing::info!(link = %settings.link, protocol = %settings.protocol, "Allegro node starting");
    // This thread is the torque loop: it runs at the real-time priority launch.toml names.
    teleop_runtime::realtime::enter_realtime();
    let spec = settings.link.clone();
    let mut open = move || teleop_can_link::open(&spec, BITRATE);
    driver::run(settings, &mut ports, &mut open)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn command(targets: [f32; JOINTS]) -> HandCommand {
        let mut c = HandCommand {
            hand_model: device_model::ALLEGRO,
            joint_count: JOINTS as u8,
            control_mode: control_mode::POSITION,
            units: units::PHYSICAL,
            ..Default::default()
        };
        for (j, t) in targets.iter().enumerate() {
            c.joints[j].target = *t;
        }
        c
    }

    #[test]
    fn commands_are_checked_and_clamped() {
        let profile = HandProfile::builtin("allegro").unwrap();
        let mut limits = [(0.0, 0.0); JOINTS];
        for (l, j) in limits.iter_mut().zip(&profile.joints) {
            *l = (j.lower, j.upper);
        }
        let mut c = command([0.3; JOINTS]);
        assert_eq!(refusal(&c), None);
        c.joints[0].target = 2.0; // index_0 is +-0.47
        let (t, clamped) = targets(&c, &limits);
        assert_eq!(clamped, 1);
        assert!((t[0] - 0.47).abs() < 1e-6 && (t[1] - 0.3).abs() < 1e-6);
        c.units = units::NORMALISED;
        assert!(refusal(&c).unwrap().contains("radians"));
        let mut c = command([0.3; JOINTS]);
        c.joint_count = 6;
        assert!(refusal(&c).is_some());
        let mut c = command([0.3; JOINTS]);
        c.joints[15].target = f32::NAN;
        assert!(refusal(&c).is_some());
        let mut c = command([0.3; JOINTS]);
        c.hand_model = device_model::REVO2;
        assert!(refusal(&c).is_some());
    }

    #[test]
    fn state_carries_positions_efforts_and_counters() {
        let mut temperatures = [None; JOINTS];
        temperatures[5] = Some(41);
        let cycle = Cycle {
            q: [0.25; JOINTS],
            qdot: [0.5; JOINTS],
            torque: [-0.125; JOINTS],
            target: [0.0; JOINTS],
            holding: true,
            temperatures,
            info: None,
            bus_state: BusState::ErrorPassive,
            counters: Counters {
                missing_cycles: 3,
                bus_errors: 2,
                lost_frames: 7,
                ..Default::default()
            },
            received_ns: 42,
        };
        let s = hand_state(&cycle);
        assert_eq!(s.joint_count, 16);
        assert_eq!(s.units, units::PHYSICAL);
        assert_eq!(s.link_kind, link_kind::CAN);
        assert_eq!(s.bus_state, bus_state::CAN_ERROR_PASSIVE);
        assert_eq!((s.link_errors, s.lost_frames), (5, 7));
        assert_eq!(s.holding, 1);
        assert_eq!(s.joints[15].position, 0.25);
        assert_eq!(s.joints[0].effort, -0.125);
        assert!(s.joints[0].current_ma.is_nan());
        assert_eq!((s.joints[5].status, s.joints[4].status), (41, 0));
        assert_eq!(s.joints[16].position, 0.0);
        assert_eq!(s.header.origin_ns, 42);
        let d = link_down_state(&cycle.counters);
        assert_eq!((d.link_up, d.link_errors), (0, 5));
    }
}
