//! The retargeting process's logic without its plumbing: its configuration file and the
//! [`RetargetEngine`] that turns glove samples (and its glove watchdog, a
//! [`Schedule`](teleop_runtime::schedule::Schedule)) into hand commands. The `teleop-retarget`
//! executable feeds it from the live topics and the clock; `teleop reprocess` feeds it from a
//! recording and its log times, so both run exactly the same code, schedule included.

use std::path::{Path, PathBuf};

use teleop_hand_profile::{CommandUnits, HandProfile};
use teleop_msgs::{command_flags, control_mode, units, GloveState, HandCommand, MAX_JOINTS};
use teleop_retargeting::{Calibration, GloveInput, JointTargets, RetargetConfig, Retargeter};
use teleop_runtime::schedule::Schedule;

// The retargeter sizes its joint arrays with the profile crate's bound; the contract must carry
// as many.
const _: () = assert!(teleop_hand_profile::MAX_JOINTS == MAX_JOINTS);

/// The node's configuration file.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NodeConfig {
    /// The hand profile (`config/hands/<hand>.toml`), relative to the configuration file.
    pub hand_profile: Option<PathBuf>,
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
            hand_profile: None,
            calibration: None,
            glove_timeout_ms: 100,
            health_period_ms: 500,
            retarget: RetargetConfig::default(),
        }
    }
}

/// Everything the node runs with.
#[derive(Debug, Clone)]
pub struct Loaded {
    /// The configuration.
    pub config: NodeConfig,
    /// The operator's calibration.
    pub calibration: Calibration,
    /// Where the calibration came from (`None`: the full range).
    pub calibration_path: Option<PathBuf>,
    /// The hand.
    pub profile: HandProfile,
}

/// Loads the configuration (defaults without a file), the hand profile (`profile` when given,
/// else the file the configuration names) and the calibration profile (from `calibration`, else
/// the one the file names, else the full range). Errors name the file, and for the retargeting
/// table's joints the line.
pub fn load(
    config: Option<&Path>,
    calibration: Option<&Path>,
    profile: Option<HandProfile>,
) -> anyhow::Result<Loaded> {
    let (cfg, base, text) = match config {
        Some(path) => (
            teleop_runtime::load_toml::<NodeConfig>(path)?,
            path.parent().map(PathBuf::from).unwrap_or_default(),
            std::fs::read_to_string(path).unwrap_or_default(),
        ),
        None => (NodeConfig::default(), PathBuf::new(), String::new()),
    };
    let origin = config.map_or("defaults".to_string(), |p| p.display().to_string());
    cfg.retarget
        .validate()
        .map_err(|e| e.with_origin(&origin))?;
    let hand = match (profile, &cfg.hand_profile) {
        (Some(p), _) => p,
        (None, Some(path)) => HandProfile::load(&base.join(path))?,
        (None, None) => anyhow::bail!(
            "{origin}: no hand profile: set `hand_profile` (e.g. \"hands/revo2.toml\") or pass --profile"
        ),
    };
    if let Err(e) = cfg.retarget.check_joints(&hand) {
        let line = match &e {
            teleop_retargeting::ConfigError::Invalid { field, .. } => text
                .lines()
                .position(|l| l.contains(field.as_str()))
                .map_or(String::new(), |i| format!(":{}", i + 1)),
            teleop_retargeting::ConfigError::Parse { .. } => String::new(),
        };
        return Err(e.with_origin(&format!("{origin}{line}")).into());
    }
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
    Ok(Loaded {
        config: cfg,
        calibration: cal,
        calibration_path: path,
        profile: hand,
    })
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
    command: CommandShape,
    stale: bool,
    last_origin: u64,
    /// The glove's watchdog (`glove_timeout_ms`).
    schedule: Schedule,
}

/// The glove's input index in the engine's schedule.
const GLOVE: usize = 0;

impl RetargetEngine {
    /// An engine for the hand `profile` with this configuration and calibration.
    pub fn new(
        config: &NodeConfig,
        calibration: Calibration,
        profile: &HandProfile,
    ) -> anyhow::Result<Self> {
        Ok(Self {
            retargeter: Retargeter::new(config.retarget.clone(), calibration, profile)?,
            command: CommandShape::of(profile),
            stale: true,
            last_origin: 0,
            schedule: {
                let mut schedule = Schedule::new();
                let glove = schedule.watch(config.glove_timeout_ms);
                debug_assert_eq!(glove, GLOVE);
                schedule
            },
        })
    }

    /// A glove sample arrived at `received_ns` (CLOCK_MONOTONIC, or the log time when
    /// reprocessing). A glove that reports its link down counts as stale input, and so does a
    /// sample made longer than the glove timeout ago by its stamp (see
    /// [`Schedule::sample`]): one from the topic's history, made before a restart, moves nothing.
    pub fn on_glove(&mut self, sample: &GloveState, received_ns: u64) -> Output {
        let stale = self
            .schedule
            .sample(GLOVE, sample.header.stamp_ns, received_ns);
        if sample.link_up == 0 || stale {
            return self.hold();
        }
        let targets = self.retargeter.step(&GloveInput {
            t_ns: sample.header.origin_ns,
            raw: sample.raw_position,
        });
        self.last_origin = sample.header.origin_ns;
        let became_fresh = self.stale;
        self.stale = false;
        Output {
            command: Some(self.command.command(&targets, self.last_origin)),
            became_stale: false,
            became_fresh,
            clamped: targets.clamped,
        }
    }

    /// When the glove's watchdog fires next, if no sample comes before (`None`: no sample yet).
    pub fn next_due(&self) -> Option<u64> {
        self.schedule.next_due()
    }

    /// What the glove's watchdog did by `now_ns`: its deadline and the output there, the
    /// earliest first (call until `None`). It fires when the newest glove sample becomes older
    /// than `glove_timeout_ms` and every timeout after, each time repeating the last command
    /// flagged as held.
    pub fn poll(&mut self, now_ns: u64) -> Option<(u64, Output)> {
        let (at, _) = self.schedule.pop(now_ns)?;
        Some((at, self.hold()))
    }

    /// Stale input: repeat the last command flagged as held (nothing before the first sample).
    fn hold(&mut self) -> Output {
        let became_stale = !self.stale;
        self.stale = true;
        Output {
            command: self
                .retargeter
                .hold()
                .map(|t| self.command.command(&t, self.last_origin)),
            became_stale,
            became_fresh: false,
            clamped: 0,
        }
    }
}

/// What a hand command looks like for one profile: its model id, and per joint how a
/// normalised target becomes the command's unit (identity, or the joint's open..closed angles).
#[derive(Debug, Clone, Copy)]
pub struct CommandShape {
    model: u8,
    units: u8,
    /// Per joint `(angle at 0, angle at 1)`; `None` for normalised commands.
    spans: Option<[(f32, f32); MAX_JOINTS]>,
}

impl CommandShape {
    /// The shape of `profile`'s commands.
    pub fn of(profile: &HandProfile) -> Self {
        let spans = match profile.command_units {
            CommandUnits::Normalised => None,
            CommandUnits::Radians => {
                let mut spans = [(0.0, 0.0); MAX_JOINTS];
                for (s, j) in spans.iter_mut().zip(&profile.joints) {
                    *s = (j.open, j.closed);
                }
                Some(spans)
            }
        };
        Self {
            model: profile.model_id,
            units: match profile.command_units {
                CommandUnits::Normalised => units::NORMALISED,
                CommandUnits::Radians => units::PHYSICAL,
            },
            spans,
        }
    }

    /// The hand command for `targets`, descending from the glove sample stamped `origin_ns`.
    /// In radians, a target is `open + (closed - open) × normalised` and the speed limit
    /// `max_speed × |closed - open|`.
    pub fn command(&self, targets: &JointTargets, origin_ns: u64) -> HandCommand {
        let mut cmd = HandCommand {
            hand_model: self.model,
            joint_count: targets.positions().len() as u8,
            control_mode: control_mode::POSITION,
            units: self.units,
            ..Default::default()
        };
        cmd.header.origin_ns = origin_ns;
        for (j, (joint, &target)) in cmd.joints.iter_mut().zip(targets.positions()).enumerate() {
            match &self.spans {
                None => {
                    joint.target = target;
                    joint.speed_limit = targets.max_speed;
                }
                Some(spans) => {
                    let (open, closed) = spans[j];
                    joint.target = open + (closed - open) * target;
                    joint.speed_limit = targets.max_speed * (closed - open).abs();
                }
            }
        }
        cmd.flags = flags_of(targets);
        cmd
    }
}

fn flags_of(targets: &JointTargets) -> u8 {
    let mut flags = 0;
    if targets.held {
        flags |= command_flags::HELD;
    }
    if targets.clamped > 0 {
        flags |= command_flags::CLAMPED;
    }
    if targets.slew_limited > 0 {
        flags |= command_flags::SLEW_LIMITED;
    }
    flags
}

#[cfg(test)]
mod tests {
    use super::*;

    fn revo2() -> HandProfile {
        HandProfile::builtin("revo2").unwrap()
    }

    fn targets(values: &[f32]) -> JointTargets {
        let mut position = [0.0; MAX_JOINTS];
        position[..values.len()].copy_from_slice(values);
        JointTargets {
            position,
            count: values.len(),
            max_speed: 3.0,
            held: true,
            clamped: 1,
            slew_limited: 0,
        }
    }

    #[test]
    fn hand_command_carries_targets_in_the_profile_order_with_flags() {
        let targets = targets(&[0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
        let cmd = CommandShape::of(&revo2()).command(&targets, 77);
        assert_eq!(cmd.header.origin_ns, 77);
        assert_eq!(cmd.joint_count, 6);
        assert_eq!(cmd.hand_model, teleop_msgs::device_model::REVO2);
        assert_eq!(cmd.units, units::NORMALISED);
        let t: Vec<f32> = cmd.active_joints().iter().map(|j| j.target).collect();
        assert_eq!(t, vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
        assert!(cmd.active_joints().iter().all(|j| j.speed_limit == 3.0));
        assert_eq!(cmd.flags, command_flags::HELD | command_flags::CLAMPED);
    }

    #[test]
    fn radian_profiles_get_angles_and_angular_speed_limits() {
        let shadow = HandProfile::builtin("shadow").unwrap();
        let mut values = [0.0; 24];
        values[2] = 1.0; // FFJ3 closed: 90 degrees
        values[3] = 0.5; // FFJ4 half way from -20 to 20 degrees: 0
        let cmd = CommandShape::of(&shadow).command(&targets(&values), 1);
        assert_eq!(cmd.hand_model, teleop_msgs::device_model::SHADOW);
        assert_eq!(cmd.units, units::PHYSICAL);
        assert_eq!(cmd.joint_count, 24);
        assert!((cmd.joints[2].target - core::f32::consts::FRAC_PI_2).abs() < 1e-5);
        assert!(cmd.joints[3].target.abs() < 1e-5);
        assert!((cmd.joints[2].speed_limit - 3.0 * core::f32::consts::FRAC_PI_2).abs() < 1e-4);
        // Model ids in the profiles are the contract's.
        assert_eq!(
            HandProfile::builtin("allegro").unwrap().model_id,
            teleop_msgs::device_model::ALLEGRO
        );
    }

    #[test]
    fn engine_holds_on_timeout_and_link_down_and_reports_transitions() {
        let mut e =
            RetargetEngine::new(&NodeConfig::default(), Calibration::default(), &revo2()).unwrap();
        let ms = 1_000_000;
        assert_eq!(
            e.poll(u64::MAX),
            None,
            "no watchdog before the first sample"
        );
        let mut s = GloveState {
            link_up: 0,
            raw_position: [500; 6],
            ..Default::default()
        };
        assert_eq!(
            e.on_glove(&s, 0).command,
            None,
            "nothing to hold before the first sample"
        );
        s.link_up = 1;
        s.header.origin_ns = ms;
        s.header.stamp_ns = ms;
        let out = e.on_glove(&s, 2 * ms);
        assert!(out.became_fresh && out.command.is_some());
        let live = out.command.unwrap();
        // The watchdog runs from when the sample was made (1 ms), not from its arrival.
        assert_eq!(e.next_due(), Some(101 * ms + 1));
        assert_eq!(e.poll(101 * ms), None, "exactly the timeout old: fresh");
        let (at, held) = e.poll(250 * ms).unwrap();
        assert_eq!(at, 101 * ms + 1);
        assert!(held.became_stale);
        let cmd = held.command.unwrap();
        assert_ne!(cmd.flags & command_flags::HELD, 0);
        assert_eq!(cmd.joints[2].target, live.joints[2].target);
        let (at, again) = e.poll(250 * ms).unwrap();
        assert_eq!(at, 201 * ms + 1, "every timeout while the glove is silent");
        assert!(!again.became_stale, "reported once");
        assert_eq!(e.poll(250 * ms), None);
        s.link_up = 0;
        assert_ne!(
            e.on_glove(&s, 260 * ms).command.unwrap().flags & command_flags::HELD,
            0
        );
    }

    #[test]
    fn a_glove_sample_made_before_the_timeout_moves_nothing() {
        let mut e =
            RetargetEngine::new(&NodeConfig::default(), Calibration::default(), &revo2()).unwrap();
        let ms = 1_000_000;
        let mut s = GloveState {
            link_up: 1,
            raw_position: [500; 6],
            ..Default::default()
        };
        // Made 1 s before it arrives (a topic's history after a restart): no command.
        s.header.stamp_ns = 1000 * ms;
        let out = e.on_glove(&s, 2000 * ms);
        assert_eq!(out.command, None);
        // Made within the timeout (100 ms): followed.
        s.header.stamp_ns = 1950 * ms;
        let out = e.on_glove(&s, 2000 * ms);
        assert!(out.became_fresh && out.command.is_some());
        // Followed, then an old one: held, not followed.
        s.header.stamp_ns = 1500 * ms;
        s.raw_position = [0; 6];
        let out = e.on_glove(&s, 2001 * ms);
        assert!(out.became_stale);
        assert_ne!(out.command.unwrap().flags & command_flags::HELD, 0);
    }

    #[test]
    fn a_joint_the_profile_lacks_is_refused_with_file_line_and_field() {
        let dir = std::env::temp_dir().join(format!("retarget-load-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("hands")).unwrap();
        let profile = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../config/hands/allegro.toml"
        );
        std::fs::copy(profile, dir.join("hands/allegro.toml")).unwrap();
        let config = dir.join("retarget.toml");
        let text = "hand_profile = \"hands/allegro.toml\"\n\n[retarget]\nmax_speed = 2.0\n\n\
                    [retarget.joints.index_1]\nmax = 0.9\n\n[retarget.joints.pinky]\nmax = 0.5\n";
        std::fs::write(&config, text).unwrap();
        let err = load(Some(&config), None, None).unwrap_err().to_string();
        let want = format!(
            "{}:9: joints.pinky: hand profile `allegro` has no joint",
            config.display()
        );
        assert!(err.starts_with(&want), "{err}");
        // Without the bad table the same file loads, with the profile it names.
        std::fs::write(
            &config,
            text.replace("[retarget.joints.pinky]\nmax = 0.5\n", ""),
        )
        .unwrap();
        let loaded = load(Some(&config), None, None).unwrap();
        assert_eq!(loaded.profile.name, "allegro");
        // No profile at all is an error that says how to give one.
        std::fs::write(&config, "glove_timeout_ms = 50\n").unwrap();
        let err = load(Some(&config), None, None).unwrap_err().to_string();
        assert!(
            err.contains("no hand profile") && err.contains("--profile"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
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
