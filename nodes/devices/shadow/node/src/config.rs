//! The Shadow node's configuration file (`config/shadow.toml`).

use std::collections::BTreeMap;

pub use teleop_ecat_master::Transport;
use teleop_shadow_protocol::data::EdcNumbering;
use teleop_shadow_protocol::mapping::{Mapping, SENSOR_NAMES};

use crate::joints::JOINTS;
use crate::schedule::DemandMode;

/// One joint sensor's calibration: `(raw ADC, angle in rad)` points in raw order, interpolated
/// linearly between them and extrapolated from the end segments (as Shadow's per-hand tables).
pub type Table = Vec<[f64; 2]>;

/// Per-joint position control gains and limit (demand units: PWM or torque, by `demand`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gains {
    /// Demand per radian of position error.
    pub kp: f64,
    /// Demand per radian per second of joint speed (damping).
    pub kd: f64,
    /// Largest demand magnitude sent (the controllers' max_force; shipped default 1023 in PWM).
    pub max_effort: f64,
}

/// The node's configuration file.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShadowConfig {
    /// `interface:NAME` (hardware; needs CAP_NET_RAW), `ethercrab:NAME` or `sim:SOCKET` (the
    /// emulator). See [`Transport`].
    pub transport: String,
    /// Cycle rate in Hz (the palm runs at 1 kHz).
    pub cycle_hz: f64,
    /// A hand command older than this is stale: the hand holds its last target.
    pub stale_command_ms: u64,
    /// Without a valid exchange for this long, the link counts as lost and the bus is brought up
    /// again.
    pub link_timeout_ms: u64,
    /// A motor that has not answered for this long is reported (and counted) as silent.
    pub motor_timeout_ms: u64,
    /// Health report period.
    pub health_period_ms: u64,
    /// After a hold (a stale command, the e-stop, a refused command), joint targets move from
    /// the held ones back to the operator's at most this fast, rad/s, then track the commands.
    pub resume_speed: f64,
    /// Joint -> motor mapping of this hand: `E_v3`, `E_v4` or `E_v5` (sr_hand_config's
    /// `general_info.yaml` names it).
    pub mapping: String,
    /// `pwm` (the shipped default) or `torque` demands.
    pub demand: String,
    /// EDC command numbering: `shipped` (every palm firmware in the field) or `document`.
    pub numbering: String,
    /// Joint effort per raw strain-gauge torque unit, N m (reported in `hand/state`).
    pub effort_nm_per_unit: f64,
    /// Position control gains for every joint ...
    pub gains: Gains,
    /// ... and per joint (by name: FFJ0, FFJ3, ..., WRJ2) where they differ.
    pub joint_gains: BTreeMap<String, Gains>,
    /// Calibration of every joint sensor (by the joint names of `hand/state`: FFJ1 ... WRJ2;
    /// THJ5 and WRJ1 read the mean of their two sensors): the default table ...
    pub calibration: Table,
    /// ... and per joint where this hand's differs (from its sr_hand_config calibration).
    pub joint_calibration: BTreeMap<String, Table>,
    /// The ADC and channel each sensor word should come from (by sensor name: FFJ1 ... THJ5A,
    /// THJ5B, WRJ1A, WRJ1B, WRJ2, ACCX ... AN3), as `[adc, channel]`; `teleop shadow channels`
    /// checks the palm against it.
    pub channels: BTreeMap<String, [u8; 2]>,
}

impl Default for ShadowConfig {
    fn default() -> Self {
        Self {
            transport: "sim:/tmp/teleop-shadow.sock".into(),
            cycle_hz: 1000.0,
            stale_command_ms: 100,
            link_timeout_ms: 100,
            motor_timeout_ms: 100,
            health_period_ms: 500,
            resume_speed: 1.0,
            mapping: "E_v3".into(),
            demand: "pwm".into(),
            numbering: "shipped".into(),
            effort_nm_per_unit: 1.0 / 32767.0,
            gains: Gains {
                kp: 600.0,
                kd: 20.0,
                max_effort: 1023.0,
            },
            joint_gains: BTreeMap::new(),
            // The emulated hand's sensors: 2048 counts at 0 rad, 1200 counts per radian.
            calibration: vec![[848.0, -1.0], [3248.0, 1.0]],
            joint_calibration: BTreeMap::new(),
            channels: BTreeMap::new(),
        }
    }
}

/// The configuration, checked and parsed.
#[derive(Debug, Clone)]
pub struct Checked {
    /// Where the bus is.
    pub transport: Transport,
    /// The mapping.
    pub mapping: Mapping,
    /// The demand mode.
    pub demand: DemandMode,
    /// The numbering.
    pub numbering: EdcNumbering,
}

fn check_table(name: &str, t: &Table) -> Result<(), String> {
    if t.len() < 2 {
        return Err(format!(
            "{name}: a calibration needs at least two [raw, rad] points"
        ));
    }
    if t.windows(2).any(|w| w[1][0] <= w[0][0]) {
        return Err(format!(
            "{name}: calibration points must be in increasing raw order"
        ));
    }
    if t.iter().flatten().any(|v| !v.is_finite()) {
        return Err(format!("{name}: calibration values must be finite"));
    }
    Ok(())
}

fn check_gains(name: &str, g: &Gains, demand: DemandMode) -> Result<(), String> {
    let limit = match demand {
        DemandMode::Pwm => 1023.0,
        DemandMode::Torque => 32767.0,
    };
    if !(g.kp >= 0.0 && g.kd >= 0.0 && g.kp.is_finite() && g.kd.is_finite()) {
        return Err(format!("{name}: kp and kd must be finite and >= 0"));
    }
    if !(g.max_effort > 0.0 && g.max_effort <= limit) {
        return Err(format!(
            "{name}.max_effort = {}: must be in (0, {limit}] for {demand:?} demands",
            g.max_effort
        ));
    }
    Ok(())
}

/// The fastest `resume_speed`, rad/s.
pub const MAX_RESUME_SPEED: f64 = 20.0;

impl ShadowConfig {
    /// Every value checked; messages name the field.
    pub fn validate(&self) -> Result<Checked, String> {
        let transport = Transport::parse(&self.transport)?;
        if !(self.cycle_hz >= 10.0 && self.cycle_hz <= 4000.0) {
            return Err(format!("cycle_hz = {}: must be 10..=4000", self.cycle_hz));
        }
        for (name, v) in [
            ("link_timeout_ms", self.link_timeout_ms),
            ("motor_timeout_ms", self.motor_timeout_ms),
            ("stale_command_ms", self.stale_command_ms),
            ("health_period_ms", self.health_period_ms),
        ] {
            teleop_runtime::check_ms(name, v)?;
        }
        if !(self.resume_speed > 0.0 && self.resume_speed <= MAX_RESUME_SPEED) {
            return Err(format!(
                "resume_speed = {}: must be in (0, {MAX_RESUME_SPEED}] rad/s",
                self.resume_speed
            ));
        }
        let mapping = match self.mapping.as_str() {
            "E_v3" => Mapping::EV3,
            "E_v4" => Mapping::EV4,
            "E_v5" => Mapping::EV5,
            other => return Err(format!("mapping = {other:?}: use E_v3, E_v4 or E_v5")),
        };
        let demand = match self.demand.as_str() {
            "pwm" => DemandMode::Pwm,
            "torque" => DemandMode::Torque,
            other => return Err(format!("demand = {other:?}: use pwm or torque")),
        };
        let numbering = match self.numbering.as_str() {
            "shipped" => EdcNumbering::Shipped,
            "document" => EdcNumbering::Document,
            other => return Err(format!("numbering = {other:?}: use shipped or document")),
        };
        if !(self.effort_nm_per_unit.is_finite() && self.effort_nm_per_unit > 0.0) {
            return Err("effort_nm_per_unit must be > 0".into());
        }
        check_gains("gains", &self.gains, demand)?;
        for (joint, g) in &self.joint_gains {
            if mapping.motor_of_joint(joint).is_none() {
                return Err(format!(
                    "joint_gains.{joint}: not a motor-driven joint (FFJ0, FFJ3, FFJ4, ..., WRJ2)"
                ));
            }
            check_gains(&format!("joint_gains.{joint}"), g, demand)?;
        }
        check_table("calibration", &self.calibration)?;
        for (joint, t) in &self.joint_calibration {
            if !JOINTS.contains(&joint.as_str()) {
                return Err(format!("joint_calibration.{joint}: no such joint sensor"));
            }
            check_table(&format!("joint_calibration.{joint}"), t)?;
        }
        for name in self.channels.keys() {
            if !SENSOR_NAMES.contains(&name.as_str()) {
                return Err(format!(
                    "channels.{name}: no such sensor (FFJ1 ... THJ5A, THJ5B, WRJ1A, WRJ1B, WRJ2, \
                     ACCX ... AN3)"
                ));
            }
        }
        Ok(Checked {
            transport,
            mapping,
            demand,
            numbering,
        })
    }

    /// The calibration table of `joint`.
    pub fn table(&self, joint: &str) -> &Table {
        self.joint_calibration
            .get(joint)
            .unwrap_or(&self.calibration)
    }

    /// The gains of motor-driven joint `joint`.
    pub fn gains_of(&self, joint: &str) -> Gains {
        self.joint_gains.get(joint).copied().unwrap_or(self.gains)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn the_shipped_configuration_loads() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../../config/shadow.toml"
        );
        let cfg: ShadowConfig = teleop_runtime::load_toml(std::path::Path::new(path)).unwrap();
        cfg.validate().unwrap();
        assert_eq!(cfg.channels["LFJ5"], [5, 6], "the document's example");
        assert_eq!(cfg.channels.len(), 26);
    }

    #[test]
    fn validation_names_the_field() {
        assert!(ShadowConfig::default().validate().is_ok());
        let cfg: ShadowConfig = teleop_runtime::parse_toml(
            "mapping = \"E_v4\"\ndemand = \"torque\"\n[joint_gains.FFJ3]\nkp = 1.0\nkd = 0.0\nmax_effort = 2000.0\n",
            "s.toml",
        )
        .unwrap();
        let checked = cfg.validate().unwrap();
        assert_eq!(checked.mapping, Mapping::EV4);
        assert_eq!(cfg.gains_of("FFJ3").max_effort, 2000.0);
        let pwm_too_big = ShadowConfig {
            demand: "pwm".into(),
            ..cfg.clone()
        };
        assert!(pwm_too_big
            .validate()
            .unwrap_err()
            .contains("joint_gains.FFJ3.max_effort"));
        let bad_joint: ShadowConfig = teleop_runtime::parse_toml(
            "[joint_gains.FFJ1]\nkp = 1.0\nkd = 0.0\nmax_effort = 9.0\n",
            "s.toml",
        )
        .unwrap();
        assert!(bad_joint
            .validate()
            .unwrap_err()
            .contains("joint_gains.FFJ1"));
        let bad_table: ShadowConfig =
            teleop_runtime::parse_toml("calibration = [[10.0, 0.0], [5.0, 1.0]]\n", "s.toml")
                .unwrap();
        assert!(bad_table
            .validate()
            .unwrap_err()
            .contains("increasing raw order"));
        for (text, field) in [
            ("stale_command_ms = 0\n", "stale_command_ms = 0"),
            ("stale_command_ms = 60001\n", "stale_command_ms = 60001"),
            (
                "link_timeout_ms = 18446744073709551615\n",
                "link_timeout_ms",
            ),
            ("motor_timeout_ms = 0\n", "motor_timeout_ms"),
            ("health_period_ms = 0\n", "health_period_ms"),
            ("resume_speed = -1.0\n", "resume_speed"),
            ("resume_speed = nan\n", "resume_speed"),
        ] {
            let cfg: ShadowConfig = teleop_runtime::parse_toml(text, "s.toml").unwrap();
            let err = cfg.validate().unwrap_err();
            assert!(err.starts_with(field), "{text}: {err}");
        }
        let err = teleop_runtime::parse_toml::<ShadowConfig>("gain = 1\n", "s.toml").unwrap_err();
        assert!(err.to_string().contains("unknown field `gain`"), "{err}");
    }
}
