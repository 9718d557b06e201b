//! The LEAP Hand node: 16 Dynamixel XC330 servos polled on one serial bus (Protocol 2.0) under
//! the hand-node core.
//!
//! - [`config`]: `config/leap.toml` and its checked form (defaults from docs/devices/leap.md:
//!   the shipped API's gains and current, 4 Mbit/s; our 500 Hz and zero return delay);
//! - [`timing`]: reply timeouts from the byte time, the return delay and a slack (pure);
//! - [`bus`]: request and reply over the serial line, every byte through
//!   `teleop-leap-protocol`, with what else is on the line counted; the serial port in
//!   low-latency mode with the USB latency-timer warning (`teleop_runtime::serial_latency`);
//! - [`servos`]: the servos between cycles (which are read, silent, in a hardware error; their
//!   last state) and angle <-> count conversion (pure);
//! - [`bringup`]: finding the servos (model check) and bringing them up in the documented order;
//! - [`driver`]: the polled loop as a `teleop_hand_node::Transport` under the core's session
//!   loop (reconnect, back-off, torque off once per session), behind a [`driver::Host`];
//! - [`node`]: the node's ports as that host (`hand/command` in; `hand/state`, health,
//!   `device/info` out);
//! - [`service`]: the commands `teleop leap` dispatches to (`info`, `reboot`, `home`, `move`).
//!
//! The protocol lives in `teleop-leap-protocol`. Must not depend on the simulator (outside
//! tests).

pub mod bringup;
pub mod bus;
pub mod config;
pub mod driver;
pub mod node;
pub mod service;
pub mod servos;
pub mod timing;

pub use config::{LeapConfig, Settings};
pub use node::run;
/// The protocol library, for users of this crate.
pub use teleop_leap_protocol as protocol;

use std::path::Path;

use teleop_hand_profile::HandProfile;

/// Reads the configuration at `path` (None: the defaults) and its hand profile (`hand_profile`
/// relative to the file's folder; without one the shipped LEAP profile). Errors name the file
/// and the field.
pub fn load(path: Option<&Path>) -> anyhow::Result<(LeapConfig, HandProfile)> {
    let (config, origin) = match path {
        Some(p) => (
            teleop_runtime::load_toml::<LeapConfig>(p)?,
            p.display().to_string(),
        ),
        None => (LeapConfig::default(), "defaults".to_string()),
    };
    let profile = match &config.hand_profile {
        Some(rel) => {
            let base = path.and_then(Path::parent).unwrap_or(Path::new(""));
            HandProfile::load(&base.join(rel))
                .map_err(|e| anyhow::anyhow!("{origin}: hand_profile: {e}"))?
        }
        None => HandProfile::builtin("leap").ok_or_else(|| {
            anyhow::anyhow!("{origin}: no hand_profile, and no shipped LEAP hand profile")
        })?,
    };
    Ok((config, profile))
}
