//! The retargeting process's logic without its plumbing: its configuration file and the
//! [`RetargetEngine`] that turns glove samples (and input timeouts) into hand commands. The
//! `teleop-retarget` executable feeds it from the live topics; `teleop reprocess` feeds it from a
//! recording, so both run exactly the same code.

use std::path::{Path, PathBuf};

use teleop_msgs::{command_flags, control_mode, hand_model, units, GloveState, HandCommand};
use teleop_retarget::{Calibration, GloveInput, JointTargets, RetargetConfig, Retargeter};

/// The node's configuration file.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NodeConfig {
    /// Calibration profile, relative to the configuration file.
    pub calibration: Option<PathBuf>,
    /// A glove silent for this long is stale.
    pub glove_timeout_ms: u64,
    /// Health report period.
    pub health_period_ms: u64,
    /// The retargeting parameters.
    pub retarget: RetargetConfig,
}

impl Default for NodeConfig {
    fn default() -> Self {
        Self {
            calibration: None,
            glove_timeout_ms: 100,
            health_period_ms: 500,
            retarget: RetargetConfig::default(),
        }
    }
}

/// Loads the configuration (defaults without a file) and the calibration profile (from
/// `calibration`, else the one the file names, else the full range). Errors name the file.
pub fn load(
    config: Option<&Path>,
    calibration: Option<&Path>,
) -> anyhow::Result<(NodeConfig, Calibration, Option<PathBuf>)> {
    let (cfg, base) = match config {
        Some(path) => (
            teleop_runtime::load_toml::<NodeConfig>(path)?,
            path.parent().map(PathBuf::from).unwrap_or_default(),
        ),
        None => (NodeConfig::default(), PathBuf::new()),
    };
    let origin = config.map_or("defaults".to_string(), |p| p.display().to_string());
    cfg.retarget
        .validate()
        .map_err(|e| e.with_origin(&origin))?;
    let path = calibration
        .map(PathBuf::from)
        .or_else(|| cfg.calibration.as_ref().map(|p| base.join(p)));
    let cal = match &path {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| anyhow::anyhow!("{}: cannot read calibration: {e}", p.display()))?;
            Calibration::from_toml_str(&text, &p.display().to_string())?
        }
        None => Calibration::default(),
    };
    Ok((cfg, cal, path))
}

/// What one input did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Output {
    /// The command to publish, if any.
    pub command: Option<HandCommand>,
    /// The input just went stale (log it, count a timeout).
    pub became_stale: bool,
    /// The input is fresh again after being stale.
    pub became_fresh: bool,
    /// Joints clamped to their limits.
    pub clamped: u8,
}

/// Glove samples in, hand commands out, holding on stale input.
pub struct RetargetEngine {
    retargeter: Retargeter,
    stale: bool,
    last_origin: u64,
}

impl RetargetEngine {
    /// An engine with this configuration and calibration.
    pub fn new(config: &NodeConfig, calibration: Calibration) -> anyhow::Result<Self> {
        Ok(Self {
            retargeter: Retargeter::new(config.retarget.clone(), calibration)?,
            stale: true,
            last_origin: 0,
        })
    }

    /// A glove sample arrived. A glove that reports its link down counts as stale input.
    pub fn on_glove(&mut self, sample: &GloveState) -> Output {
        if sample.link_up == 0 {
            return self.on_timeout();
        }
        let targets = self.retargeter.step(&GloveInput {
            t_ns: sample.header.origin_ns,
            raw: sample.raw_position,
        });
        self.last_origin = sample.header.origin_ns;
        let became_fresh = self.stale;
        self.stale = false;
        Output {
            command: Some(hand_command(&targets, self.last_origin)),
            became_stale: false,
            became_fresh,
            clamped: targets.clamped,
        }
    }

    /// No glove sample within the timeout: repeat the last command flagged as held (nothing
    /// before the first sample).
    pub fn on_timeout(&mut self) -> Output {
        let became_stale = !self.stale;
        self.stale = true;
        Output {
            command: self
                .retargeter
                .hold()
                .map(|t| hand_command(&t, self.last_origin)),
            became_stale,
            became_fresh: false,
            clamped: 0,
        }
    }
}

/// The hand command for `targets`, descending from the glove sample stamped `origin_ns`.
pub fn hand_command(targets: &JointTargets, origin_ns: u64) -> HandCommand {
    let mut cmd = HandCommand {
        hand_model: hand_model::REVO2,
        joint_count: targets.position.len() as u8,
        control_mode: control_mode::POSITION,
        units: units::NORMALISED,
        ..Default::default()
    };
    cmd.header.origin_ns = origin_ns;
    for (joint, &target) in cmd.joints.iter_mut().zip(&targets.position) {
        joint.target = target;
        joint.speed_limit = targets.max_speed;
    }
    if targets.held {
        cmd.flags |= command_flags::HELD;
    }
    if targets.clamped > 0 {
        cmd.flags |= command_flags::CLAMPED;
    }
    if targets.slew_limited > 0 {
        cmd.flags |= command_flags::SLEW_LIMITED;
    }
    cmd
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_command_carries_targets_in_revo2_order_with_flags() {
        let targets = JointTargets {
            position: [0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
            max_speed: 3.0,
            held: true,
            clamped: 1,
            slew_limited: 0,
        };
        let cmd = hand_command(&targets, 77);
        assert_eq!(cmd.header.origin_ns, 77);
        assert_eq!(cmd.joint_count, 6);
        assert_eq!(cmd.hand_model, hand_model::REVO2);
        let t: Vec<f32> = cmd.active_joints().iter().map(|j| j.target).collect();
        assert_eq!(t, vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
        assert!(cmd.active_joints().iter().all(|j| j.speed_limit == 3.0));
        assert_eq!(cmd.flags, command_flags::HELD | command_flags::CLAMPED);
    }

    #[test]
    fn engine_holds_on_timeout_and_link_down_and_reports_transitions() {
        let mut e = RetargetEngine::new(&NodeConfig::default(), Calibration::default()).unwrap();
        assert_eq!(
            e.on_timeout().command,
            None,
            "nothing to hold before the first sample"
        );
        let mut s = GloveState {
            link_up: 1,
            raw_position: [500; 6],
            ..Default::default()
        };
        s.header.origin_ns = 1_000_000;
        let out = e.on_glove(&s);
        assert!(out.became_fresh && out.command.is_some());
        let live = out.command.unwrap();
        let held = e.on_timeout();
        assert!(held.became_stale);
        let cmd = held.command.unwrap();
        assert_ne!(cmd.flags & command_flags::HELD, 0);
        assert_eq!(cmd.joints[2].target, live.joints[2].target);
        assert!(!e.on_timeout().became_stale, "reported once");
        s.link_up = 0;
        assert_ne!(
            e.on_glove(&s).command.unwrap().flags & command_flags::HELD,
            0
        );
    }

    #[test]
    fn config_file_errors_name_the_field() {
        let err = teleop_runtime::parse_toml::<NodeConfig>("glove_timeout = 5\n", "r.toml")
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("r.toml: ") && err.contains("glove_timeout"),
            "{err}"
        );
        let cfg: NodeConfig =
            teleop_runtime::parse_toml("[retarget]\nmax_speed = 2.0\n", "r.toml").unwrap();
        assert_eq!(cfg.retarget.max_speed, 2.0);
        assert_eq!(cfg.glove_timeout_ms, 100);
    }
}
