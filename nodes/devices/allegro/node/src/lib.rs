//! The Allegro Hand node: bring-up, the 333 Hz torque loop with a host PD controller, hand state
//! out.
//!
//! - [`config`]: `config/allegro.toml` and its checked form (defaults from docs/devices/allegro.md:
//!   R4's gains, per-joint PWM limits and velocity filter);
//! - [`control`]: the pure PD controller, its limits and the velocity filter;
//! - [`gather`]: the pure gathering of one period's four finger frames;
//! - [`pace`]: telling a late period from a missing one by the link's bus-time stamps (pure);
//! - [`wire`]: one protocol generation on the wire (start, torque, stop, queries; what received
//!   frames mean), over `teleop-allegro-protocol`;
//! - [`bringup`]: bringing the hand up on a link, detecting its generation, naming a hand of the
//!   other generation or a silent bus;
//! - [`driver`]: the loop clocked by the hand's stream (hold, missing frames, bus errors, zero
//!   torque and SYSTEM_OFF at the end of each session) as a transport under the hand-node core's
//!   session loop (reconnect, back-off, stop), behind a [`driver::Host`];
//! - [`node`]: the node's ports as that host (`hand/command` in; `hand/state`, health,
//!   `device/info` out).
//!
//! `teleop allegro` (the CLI's `info`, `home`, `move`) uses the same bring-up and loop. The
//! protocols live in `teleop-allegro-protocol`, the links in `teleop-can-link`. Must not depend
//! on the simulator (outside tests).

pub mod bringup;
pub mod config;
pub mod control;
pub mod driver;
pub mod gather;
pub mod node;
pub mod pace;
pub mod service;
pub mod wire;

pub use config::{AllegroConfig, ProtocolSetting, Settings};
pub use node::run;
/// The protocol library, for users of this crate (`teleop allegro`).
pub use teleop_allegro_protocol as protocol;
/// The CAN link library, for users of this crate.
pub use teleop_can_link as can_link;

use std::path::Path;

use teleop_hand_profile::HandProfile;

/// Reads the configuration at `path` (None: the defaults) and its hand profile (`hand_profile`
/// relative to the file's folder; without one the shipped Allegro profile). Errors name the file
/// and the field.
pub fn load(path: Option<&Path>) -> anyhow::Result<(AllegroConfig, HandProfile)> {
    let (config, origin) = match path {
        Some(p) => (
            teleop_runtime::load_toml::<AllegroConfig>(p)?,
            p.display().to_string(),
        ),
        None => (AllegroConfig::default(), "defaults".to_string()),
    };
    let profile = match &config.hand_profile {
        Some(rel) => {
            let base = path.and_then(Path::parent).unwrap_or(Path::new(""));
            HandProfile::load(&base.join(rel))
                .map_err(|e| anyhow::anyhow!("{origin}: hand_profile: {e}"))?
        }
        None => HandProfile::builtin("allegro")
            .ok_or_else(|| anyhow::anyhow!("the shipped Allegro hand profile does not load"))?,
    };
    Ok((config, profile))
}
