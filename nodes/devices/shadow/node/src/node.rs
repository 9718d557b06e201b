//! The Shadow node: the master's cycle (`teleop-ecat-master`) with the [`Shadow`] driver, and
//! the hand-node core's ports (`teleop-hand-node`: admission by the Shadow Hand's profile,
//! position modes only; e-stop, stale -> hold, the ramp back, health and device info, also
//! while the hand is away) as its host;
//! `hand/state` (24 joints, efforts from the strain gauges, each joint's motor flags as its
//! status) and `hand/tactile` (PST pressure) out for every valid exchange, the link state while
//! the hand is away, health and device info periodically (also while the hand is away).

use std::time::Duration;

use teleop_ecat_master::{Bus, Connect, Counters, Event, Exchange, Host, Settings};
use teleop_hand_node::{Admission, HandPorts, Modes, Timing};
use teleop_hand_profile::HandProfile;
use teleop_msgs::{
    bus_state, device_model, fingertip_sensor, fixed_text, link_kind, units, DeviceInfo,
    HandCommand, HandState, Tactile,
};
use teleop_runtime::NodeRuntime;

use crate::config::{Checked, ShadowConfig};
use crate::driver::{Inputs, Shadow};

/// The node's ports, the master's host.
struct Ports(HandPorts);

/// Runs until SIGINT/SIGTERM.
pub fn run(
    runtime: &NodeRuntime,
    config: &ShadowConfig,
    checked: Checked,
    connect: Connect,
) -> anyhow::Result<()> {
    teleop_runtime::install_stop_handlers();
    let mut ports = Ports(HandPorts::new(
        runtime,
        admission()?,
        Timing {
            stale_after: Duration::from_millis(config.stale_command_ms),
            health_period: Duration::from_millis(config.health_period_ms),
            resume_speed: config.resume_speed,
        },
    )?);
    let settings = Settings {
        period: Duration::from_secs_f64(1.0 / config.cycle_hz),
        link_timeout: Duration::from_millis(config.link_timeout_ms),
    };
    let bus = Bus::open(connect)?;
    let mut driver = Shadow::new(config.clone(), checked);
    teleop_ecat_master::run(&bus, &mut driver, &mut ports, &settings)
}

/// The Shadow Hand's admission rule: its shipped hand profile (`config/hands/shadow.toml`:
/// radians, 24 joints and their limits) and position targets (with or without a motion time;
/// the host's position control takes both as positions).
pub fn admission() -> anyhow::Result<Admission> {
    let profile = HandProfile::builtin("shadow")
        .ok_or_else(|| anyhow::anyhow!("the shipped Shadow Hand profile does not load"))?;
    Ok(Admission::new(
        &profile,
        Modes {
            position_time: true,
            ..Modes::POSITION
        },
    ))
}

/// `hand/state` of one exchange.
pub fn hand_state(inputs: &Inputs) -> HandState {
    let mut state = HandState {
        hand_model: device_model::SHADOW,
        joint_count: 24,
        units: units::PHYSICAL,
        link_up: 1,
        link_kind: link_kind::ETHERCAT,
        bus_state: bus_state::AL_OP,
        ..Default::default()
    };
    for (j, out) in state.joints.iter_mut().enumerate() {
        out.position = inputs.angles[j] as f32;
        out.speed = inputs.speeds[j] as f32;
        out.effort = inputs.efforts[j] as f32;
        out.current_ma = inputs.currents_ma[j] as f32;
        out.status = u32::from(inputs.flags[j]);
    }
    state
}

/// `hand/tactile` of one exchange, when the palm sent PST data.
pub fn tactile(inputs: &Inputs) -> Option<Tactile> {
    let pst = inputs.pst?;
    let mut t = Tactile {
        hand_model: device_model::SHADOW,
        fingertip_count: pst.len() as u8,
        ..Default::default()
    };
    for (out, (pressure, temperature)) in t.fingertips.iter_mut().zip(pst) {
        out.sensor_kind = fingertip_sensor::PST_PRESSURE;
        out.normal_n = f32::NAN;
        out.tangential_n = f32::NAN;
        out.direction_deg = f32::NAN;
        out.pressure = i32::from(pressure);
        out.temperature = i32::from(temperature);
    }
    Some(t)
}

impl Host<Shadow> for Ports {
    fn stop_requested(&self) -> bool {
        teleop_runtime::stop_signal().is_some()
    }

    fn command(&mut self) -> Option<HandCommand> {
        self.0.command()
    }

    fn connected(&mut self, driver: &Shadow) {
        let palm = driver.palm();
        let connected = self.0.connected(DeviceInfo {
            device_model: device_model::SHADOW,
            link_kind: link_kind::ETHERCAT,
            identity_serial: palm.serial,
            model_name: fixed_text("Shadow Hand E (SR06 palm, 0220)"),
            hardware_revision: fixed_text(&palm.revision.to_string()),
            serial_number: fixed_text(&palm.serial.to_string()),
            ..Default::default()
        });
        if let Err(e) = connected {
            self.0.health().count_error();
            tracing::warn!("device/info: {e}");
        }
    }

    fn exchanged(
        &mut self,
        _driver: &Shadow,
        inputs: &Inputs,
        exchange: &Exchange,
    ) -> anyhow::Result<()> {
        let mut state = hand_state(inputs);
        state.holding = u8::from(exchange.holding);
        state.link_errors = exchange.counters.wkc_errors;
        state.lost_frames = exchange.counters.lost_frames;
        state.header.origin_ns = exchange.origin_ns;
        let tactile = tactile(inputs).map(|mut t| {
            t.header.origin_ns = exchange.origin_ns;
            t
        });
        self.0.publish(&state, tactile.as_ref())?;
        Ok(())
    }

    fn event(&mut self, event: Event) {
        match event {
            Event::Refused => {
                self.0.health().count_error();
                self.0.refused();
            }
            Event::Recovered | Event::Lost => self.0.health().count_error(),
        }
    }

    fn link_down(&mut self, counters: &Counters) -> anyhow::Result<()> {
        self.0.publish_down(&HandState {
            link_kind: link_kind::ETHERCAT,
            link_errors: counters.wkc_errors,
            lost_frames: counters.lost_frames,
            ..Default::default()
        })?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use teleop_shadow_protocol::mapping::{HAND_JOINTS, HAND_LIMITS};

    /// The shipped profile names the Hand E's 24 joints in the order the node reports them, and
    /// its limits, the only ones commands are held to, lie within the hand's published joint
    /// ranges (`HAND_LIMITS`, which the simulator also moves within).
    #[test]
    fn the_profile_limits_lie_within_the_hands_joint_ranges() {
        let profile = HandProfile::builtin("shadow").unwrap();
        let names: Vec<&str> = profile.joint_names().collect();
        assert_eq!(names, HAND_JOINTS);
        let admission = admission().unwrap();
        assert_eq!(admission.limits().len(), 24);
        for ((name, &(lo, hi)), (dlo, dhi)) in
            HAND_JOINTS.iter().zip(admission.limits()).zip(HAND_LIMITS)
        {
            assert!(
                f64::from(lo) >= dlo - 1e-6 && f64::from(hi) <= dhi + 1e-6,
                "{name}: profile {lo}..{hi} rad, hand {dlo}..{dhi} rad"
            );
        }
    }
}
