//! The node: the torque loop ([`crate::driver`]) with the hand-node core's ports as its host
//! (`teleop-hand-node`: admission by the hand profile, position targets in radians only; e-stop,
//! stale -> hold, the ramp back, health and device info, also while the hand is down); hand
//! state out every cycle, the link state while the hand is down, the loop's counters in health.

use teleop_allegro_protocol::{v4, Generation, JOINTS};
use teleop_can_link::{Bitrate, BusState};
use teleop_hand_node::{Admission, HandKind, HandPorts, Modes, Timing};
use teleop_hand_profile::HandProfile;
use teleop_msgs::{bus_state, device_model, fixed_text, link_kind, units, DeviceInfo, HandState};
use teleop_runtime::NodeRuntime;

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

/// The node's ports, the loop's host: the core's ports, and what the loop's counters add to
/// health.
struct Ports {
    hand: HandPorts,
    device_id: u8,
    /// Loop errors (unknown and bad frames, bus errors, missing cycles) counted in health so far.
    errors_counted: u64,
}

impl Ports {
    /// The loop's counters into health: its errors, and its frame counters as named details.
    fn count(&mut self, counters: &Counters) {
        let errors = counters.unknown_frames
            + counters.bad_frames
            + counters.bus_errors
            + counters.missing_cycles;
        let health = self.hand.health();
        health.count_errors(errors.saturating_sub(self.errors_counted));
        self.errors_counted = errors;
        health.set_detail("unknown_frames", counters.unknown_frames as f64);
        health.set_detail("bad_frames", counters.bad_frames as f64);
        health.set_detail("reconnects", counters.reconnects as f64);
        // Waits the frames' stamps showed were a loaded host's, not the hand's.
        health.set_detail("late_periods", counters.late_periods as f64);
    }
}

impl Host for Ports {
    fn stop_requested(&self) -> bool {
        teleop_runtime::stop_signal().is_some()
    }

    fn target(&mut self) -> Target {
        self.hand.target()
    }

    fn connected(&mut self, hand: &Connected<'_>) -> anyhow::Result<()> {
        self.hand.connected(device_info(hand, self.device_id))?;
        let generation = match hand.generation {
            Generation::V1 => 1.0,
            Generation::V2 => 2.0,
            Generation::V3 => 3.0,
            Generation::V4 => 4.0,
        };
        self.hand
            .health()
            .set_detail("protocol_generation", generation);
        tracing::info!(
            generation = %hand.generation,
            firmware = %firmware_text(hand.identity),
            serial = %hand.identity.serial.as_ref().map(v4::serial_text).unwrap_or_default(),
            "Allegro Hand connected"
        );
        Ok(())
    }

    fn cycle(&mut self, cycle: &Cycle) -> anyhow::Result<()> {
        let hottest = cycle.temperatures.iter().filter_map(|t| *t).max();
        let health = self.hand.health();
        health.set_detail("bus_state", f64::from(bus_state_code(cycle.bus_state)));
        health.set_detail("max_temperature_c", f64::from(hottest.unwrap_or(0)));
        self.count(&cycle.counters);
        self.hand.publish(&hand_state(cycle), None)?;
        Ok(())
    }

    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        self.count(down.counters);
        self.hand.publish_down(&link_down_state(down.counters))?;
        Ok(())
    }
}

/// The Allegro's admission rule: its hand profile (radians, 16 joints and their limits) and
/// position targets only (the host's PD controller follows positions).
pub fn admission(profile: &HandProfile) -> Admission {
    Admission::new(profile, Modes::POSITION)
}

/// The Allegro Hand, as a profile must describe it.
const ALLEGRO: HandKind = HandKind {
    hand: "Allegro Hand",
    model: device_model::ALLEGRO,
    joints: JOINTS,
    layout: "index 0-3, middle 4-7, ring 8-11, thumb 12-15",
};

/// Runs until SIGINT/SIGTERM, on this thread (which takes the launch file's real-time
/// scheduling).
pub fn run(
    runtime: &NodeRuntime,
    settings: &Settings,
    profile: &HandProfile,
) -> anyhow::Result<()> {
    ALLEGRO.check(profile)?;
    teleop_runtime::install_stop_handlers();
    let mut ports = Ports {
        hand: HandPorts::new(
            runtime,
            admission(profile),
            Timing {
                stale_after: settings.stale_command,
                health_period: settings.health_period,
                resume_speed: settings.resume_speed,
            },
        )?,
        device_id: settings.device_id,
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

    /// The profile's joint count and limits are the hand's: 16 joints in the loop's order, and
    /// a command outside the limits is clamped into them by the one admission rule.
    #[test]
    fn the_profile_is_the_hands() {
        let profile = HandProfile::builtin("allegro").unwrap();
        let admission = admission(&profile);
        assert_eq!(admission.joints(), JOINTS);
        assert_eq!(admission.model(), device_model::ALLEGRO);
        assert_eq!(admission.units(), units::PHYSICAL);
        for (l, j) in admission.limits().iter().zip(&profile.joints) {
            assert_eq!(*l, (j.lower, j.upper), "{}", j.name);
        }
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
