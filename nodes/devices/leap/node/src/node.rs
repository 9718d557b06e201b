//! The node: the polled bus loop ([`crate::driver`]) with the hand-node core's ports as its host
//! (`teleop-hand-node`: admission by the hand profile, position targets in radians; e-stop,
//! stale -> hold, the ramp back, health and device info, also while the hand is down); hand
//! state out every cycle, the link state while the hand is down, the loop's counters in health.
//!
//! Health details: `crc_errors` (replies with a bad CRC), `garbage_bytes` (bytes that were no
//! packet, came after their request gave up, or packets nobody asked for), `reply_timeouts` (replies
//! not there in time), `silent_servos` and `hw_error_servos` (servos silent, or in a hardware
//! error, now), `reconnects`, `exchange_us_p99` (goal write to state read, 99th percentile),
//! `overruns` (deadlines missed by more than a period).

use teleop_hand_node::{Admission, HandKind, HandPorts, Modes, Timing};
use teleop_hand_profile::HandProfile;
use teleop_msgs::{device_model, fixed_text, link_kind, units, DeviceInfo, HandState};
use teleop_runtime::NodeRuntime;

use crate::config::{Settings, SERVOS};
use crate::driver::{self, Connected, Counters, Cycle, Down, Host, Target};
use crate::servos;

fn saturate(v: u64) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}

/// The `hand/state` sample of one cycle: positions (rad, the profile's device map), speeds
/// (rad/s), currents (mA), no effort (NaN: the servos measure current, not torque), `status`
/// the joint's word (`crate::servos::status`: stale, silent, alert, hardware error bits). A
/// joint never read since the hand came up has NaN for all of them: nothing is held there.
/// `link_errors` counts cycles with a bad exchange, `lost_frames` cycles without any state.
pub fn hand_state(profile: &HandProfile, cycle: &Cycle<'_>) -> HandState {
    let mut state = HandState {
        hand_model: device_model::LEAP,
        joint_count: SERVOS as u8,
        units: units::PHYSICAL,
        holding: u8::from(cycle.holding),
        link_up: 1,
        link_kind: link_kind::SERIAL,
        link_errors: saturate(cycle.counters.bad_cycles),
        lost_frames: saturate(cycle.counters.failed_cycles),
        ..Default::default()
    };
    for (j, (out, joint)) in state.joints.iter_mut().zip(&profile.joints).enumerate() {
        let r = cycle.servos.reading(j);
        out.status = cycle.servos.status_word(j);
        out.effort = f32::NAN;
        if out.status & servos::status::UNKNOWN != 0 {
            out.position = f32::NAN;
            out.speed = f32::NAN;
            out.current_ma = f32::NAN;
            continue;
        }
        out.position = servos::position_rad(joint, r.position) as f32;
        out.speed = servos::speed_rad_s(joint, r.velocity) as f32;
        out.current_ma = f32::from(r.current_ma);
    }
    state.header.origin_ns = cycle.received_ns;
    state
}

/// The `hand/state` sample while the hand is down.
pub fn link_down_state(counters: &Counters) -> HandState {
    HandState {
        hand_model: device_model::LEAP,
        joint_count: SERVOS as u8,
        units: units::PHYSICAL,
        link_up: 0,
        link_kind: link_kind::SERIAL,
        link_errors: saturate(counters.bad_cycles),
        lost_frames: saturate(counters.failed_cycles),
        ..Default::default()
    }
}

/// IDs as text: `0-15`, or `0-3,5,7-9`.
pub fn ids_text(ids: &[u8]) -> String {
    let mut out = String::new();
    let mut i = 0;
    while i < ids.len() {
        let mut k = i;
        while k + 1 < ids.len() && ids[k + 1] == ids[k].wrapping_add(1) {
            k += 1;
        }
        if !out.is_empty() {
            out.push(',');
        }
        if k > i {
            out.push_str(&format!("{}-{}", ids[i], ids[k]));
        } else {
            out.push_str(&ids[i].to_string());
        }
        i = k + 1;
    }
    out
}

/// Firmware versions as text: `52`, or `46..52` when they differ (silent servos left out).
pub fn firmware_text(hand: &Connected<'_>) -> String {
    let versions = hand
        .identity
        .firmware
        .iter()
        .enumerate()
        .filter(|(j, _)| hand.identity.silent & servos::bit(*j) == 0)
        .map(|(_, v)| *v);
    let (lo, hi) = versions.fold((u8::MAX, 0), |(lo, hi), v| (lo.min(v), hi.max(v)));
    match (lo, hi) {
        (u8::MAX, 0) => String::new(),
        (lo, hi) if lo == hi => lo.to_string(),
        (lo, hi) => format!("{lo}..{hi}"),
    }
}

/// The identity of the hand, for the recorder and `teleop echo device/info`: model, link,
/// port, the servos' model name and firmware, the protocol and the IDs.
pub fn device_info(hand: &Connected<'_>) -> DeviceInfo {
    let model = hand
        .identity
        .models
        .iter()
        .find(|m| **m != 0)
        .copied()
        .unwrap_or(0);
    DeviceInfo {
        device_model: device_model::LEAP,
        link_kind: link_kind::SERIAL,
        model_name: fixed_text(&format!("LEAP Hand, {}", crate::bringup::model_text(model))),
        firmware_version: fixed_text(&firmware_text(hand)),
        protocol: fixed_text(&format!("Dynamixel 2.0 ids {}", ids_text(hand.ids))),
        link: fixed_text(hand.port),
        ..Default::default()
    }
}

/// The node's ports, the loop's host.
struct Ports<'p> {
    hand: HandPorts,
    profile: &'p HandProfile,
    /// Loop errors counted in health so far.
    errors_counted: u64,
}

impl Ports<'_> {
    /// The loop's counters into health: its errors, and named details.
    fn count(&mut self, c: &Counters, silent: u32, alerts: u32) {
        let b = &c.bus;
        let garbage = b.garbage_bytes + b.late_bytes + b.unexpected + b.malformed;
        let errors = b.crc_errors
            + b.malformed
            + b.unexpected
            + b.timeouts
            + c.silent_events
            + c.hardware_errors
            + b.garbage_runs;
        let health = self.hand.health();
        health.count_errors(errors.saturating_sub(self.errors_counted));
        self.errors_counted = self.errors_counted.max(errors);
        health.set_detail("crc_errors", b.crc_errors as f64);
        health.set_detail("garbage_bytes", garbage as f64);
        health.set_detail("reply_timeouts", b.timeouts as f64);
        health.set_detail("silent_servos", f64::from(silent));
        health.set_detail("hw_error_servos", f64::from(alerts));
        health.set_detail("reconnects", c.reconnects as f64);
        health.set_detail("exchange_us_p99", f64::from(c.exchange_us_p99));
        health.set_detail("overruns", c.overruns as f64);
    }
}

impl Host for Ports<'_> {
    fn stop_requested(&self) -> bool {
        teleop_runtime::stop_signal().is_some()
    }

    fn target(&mut self) -> Target {
        self.hand.target()
    }

    fn connected(&mut self, hand: &Connected<'_>) -> anyhow::Result<()> {
        let info = device_info(hand);
        tracing::info!(
            port = hand.port,
            model = %teleop_msgs::text_of(&info.model_name),
            firmware = %firmware_text(hand),
            ids = %ids_text(hand.ids),
            "LEAP Hand connected"
        );
        self.hand.connected(info)?;
        // Where the hand is, before the first command: the ramp to the commands starts here
        // (with nothing held, the first command would pass through: a jump).
        self.hand
            .publish(&hand_state(self.profile, hand.bring_up), None)?;
        Ok(())
    }

    fn cycle(&mut self, cycle: &Cycle<'_>) -> anyhow::Result<()> {
        self.count(
            cycle.counters,
            cycle.servos.silent().count_ones(),
            cycle.servos.alerts().count_ones(),
        );
        self.hand.publish(&hand_state(self.profile, cycle), None)?;
        Ok(())
    }

    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        self.count(down.counters, 0, 0);
        self.hand.publish_down(&link_down_state(down.counters))?;
        Ok(())
    }
}

/// The LEAP Hand's admission rule: its hand profile (radians, 16 joints and their limits) and
/// position targets only (the servos' current-based position control follows positions).
pub fn admission(profile: &HandProfile) -> Admission {
    Admission::new(profile, Modes::POSITION)
}

/// The LEAP Hand, as a profile must describe it.
const LEAP: HandKind = HandKind {
    hand: "LEAP Hand",
    model: device_model::LEAP,
    joints: SERVOS,
    layout: "index 0-3, middle 4-7, ring 8-11, thumb 12-15",
};

/// Checks that `profile` is a LEAP Hand's: 16 joints, the LEAP's model.
pub fn check_profile(profile: &HandProfile) -> anyhow::Result<()> {
    Ok(LEAP.check(profile)?)
}

/// Runs until SIGINT/SIGTERM, on this thread (which takes the launch file's real-time
/// scheduling).
pub fn run(
    runtime: &NodeRuntime,
    settings: &Settings,
    profile: &HandProfile,
) -> anyhow::Result<()> {
    check_profile(profile)?;
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
        profile,
        errors_counted: 0,
    };
    tracing::info!(
        port = %settings.port,
        baud = settings.baud,
        rate_hz = 1.0 / settings.period.as_secs_f64(),
        "LEAP node starting"
    );
    // This thread is the bus loop: it runs at the real-time priority the launch file names.
    teleop_runtime::realtime::enter_realtime();
    driver::run(settings, profile, &mut ports)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_written_as_ranges() {
        let all: Vec<u8> = (0..16).collect();
        assert_eq!(ids_text(&all), "0-15");
        assert_eq!(ids_text(&[0, 1, 2, 3, 5, 7, 8, 9]), "0-3,5,7-9");
        assert_eq!(ids_text(&[4]), "4");
        assert_eq!(ids_text(&[]), "");
    }

    #[test]
    fn a_joint_never_read_is_published_as_nan_not_as_a_position() {
        let profile = HandProfile::builtin("leap").expect("the shipped profile");
        let mut ids = [0u8; SERVOS];
        for (j, id) in ids.iter_mut().enumerate() {
            *id = j as u8;
        }
        let mut servos = servos::Servos::new(ids, servos::bit(3));
        for j in (0..SERVOS).filter(|j| *j != 3) {
            let state = teleop_leap_protocol::xc330::State {
                current_ma: 20,
                velocity: 0,
                position: 2048,
            };
            servos.take(j, state);
        }
        let counters = Counters::default();
        let cycle = Cycle {
            servos: &servos,
            goals: &[2048; SERVOS],
            holding: true,
            counters: &counters,
            received_ns: 1,
        };
        let s = hand_state(&profile, &cycle);
        let j3 = s.joints[3];
        assert!(j3.position.is_nan() && j3.speed.is_nan() && j3.current_ma.is_nan());
        assert_ne!(j3.status & servos::status::UNKNOWN, 0);
        assert!(s.joints[2].position.abs() < 1e-6, "2048 counts: 0 rad");
        assert_eq!(s.joints[2].current_ma, 20.0);
    }
}
