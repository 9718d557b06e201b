//! The Revo2 node: the master's cycle (`teleop-ecat-master`) with the [`Revo2`] driver, and the
//! hand-node core's ports (`teleop-hand-node`: admission by the Revo2's hand profile, e-stop,
//! stale -> hold, the ramp back, health and device info, also while the hand is away) as its
//! host; hand state and tactile data out for every valid exchange, the link state while the
//! hand is away.

use std::time::Duration;

use teleop_ecat_master::{Bus, Connect, Counters, Event, Exchange, Host, Settings};
use teleop_hand_node::{Admission, HandPorts, Modes, Timing};
use teleop_hand_profile::HandProfile;
use teleop_msgs::{
    bus_state, device_model, fixed_text, link_kind, DeviceInfo, HandCommand, HandState,
};
use teleop_revo2_protocol::Inputs;
use teleop_runtime::NodeRuntime;

use crate::bus::DeviceInfo as FoundDevice;
use crate::config::Revo2Config;
use crate::convert::{hand_state, tactile};
use crate::driver::Revo2;

/// The node's ports, the master's host.
struct Ports(HandPorts);

/// Runs until SIGINT/SIGTERM.
pub fn run(runtime: &NodeRuntime, config: &Revo2Config, connect: Connect) -> anyhow::Result<()> {
    teleop_runtime::install_stop_handlers();
    let mut ports = Ports(HandPorts::new(
        runtime,
        admission(config)?,
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
    let mut driver = Revo2::new(config.clone());
    teleop_ecat_master::run(&bus, &mut driver, &mut ports, &settings)
}

/// The Revo2's admission rule: its shipped hand profile (`config/hands/revo2.toml`: normalised
/// commands, six joints and their limits) and every mode it has (velocity up to its full speed,
/// effort and duty up to the whole range).
pub fn admission(config: &Revo2Config) -> anyhow::Result<Admission> {
    let profile = HandProfile::builtin("revo2")
        .ok_or_else(|| anyhow::anyhow!("the shipped Revo2 hand profile does not load"))?;
    let modes = Modes {
        position: true,
        position_time: true,
        velocity: Some(config.full_speed_travel_per_s),
        effort: Some(1.0),
        duty: Some(1.0),
    };
    Ok(Admission::new(&profile, modes))
}

/// The identity the device reported, for the recorder and `teleop echo device/info`.
fn device_info(info: &FoundDevice) -> DeviceInfo {
    DeviceInfo {
        device_model: device_model::REVO2,
        link_kind: link_kind::ETHERCAT,
        identity_serial: info.serial,
        model_name: fixed_text(teleop_revo2_protocol::DEVICE_NAME),
        firmware_version: fixed_text(&info.control_fw),
        serial_number: fixed_text(&info.control_sn),
        second_board_firmware: fixed_text(&info.wrist_fw),
        second_board_serial: fixed_text(&info.wrist_sn),
        ..Default::default()
    }
}

impl Host<Revo2> for Ports {
    fn stop_requested(&self) -> bool {
        teleop_runtime::stop_signal().is_some()
    }

    fn command(&mut self) -> Option<HandCommand> {
        self.0.command()
    }

    fn connected(&mut self, driver: &Revo2) {
        tracing::info!(
            tactile_in_pdo = driver.info().tactile_in_pdo(),
            "Revo2 tactile source"
        );
        if let Err(e) = self.0.connected(device_info(driver.info())) {
            self.0.health().count_error();
            tracing::warn!("device/info: {e}");
        }
    }

    fn exchanged(
        &mut self,
        driver: &Revo2,
        inputs: &Inputs,
        exchange: &Exchange,
    ) -> anyhow::Result<()> {
        let config = driver.config();
        let mut state = hand_state(
            inputs,
            driver.info().units(),
            config.full_speed_travel_per_s,
        );
        state.link_up = 1;
        state.bus_state = bus_state::AL_OP;
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
