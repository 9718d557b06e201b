//! The Allegro node's configuration file (`config/allegro.toml`) and its checked form.
//!
//! Defaults follow `docs/devices/allegro.md`: gains, per-joint PWM limits and the velocity
//! filter of R4 (allegro_hand_ros_v4), the 3 ms period of the device document.

use std::path::PathBuf;
use std::time::Duration;

use teleop_allegro_protocol::{Generation, JointCalibration, JOINTS};
use teleop_can_link::LinkSpec;

/// Which protocol generation the hand speaks (`protocol`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ProtocolSetting {
    /// Detect it: from the streamed ids, and when the hand is silent, by trying each
    /// generation's start (the v4 info query, then the document's start sequence).
    #[default]
    Auto,
    /// This generation.
    Fixed(Generation),
}

impl std::str::FromStr for ProtocolSetting {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(Self::Auto);
        }
        s.parse::<Generation>()
            .map(Self::Fixed)
            .map_err(|_| format!("{s:?}: use \"auto\", \"v1\", \"v2\", \"v3\" or \"v4\""))
    }
}

impl std::fmt::Display for ProtocolSetting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Auto => f.write_str("auto"),
            Self::Fixed(g) => write!(f, "{g}"),
        }
    }
}

impl<'de> serde::Deserialize<'de> for ProtocolSetting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        text.parse().map_err(serde::de::Error::custom)
    }
}

/// How joint velocities are estimated from the positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VelocityFilterKind {
    /// R4's filter: `q_f = 0.6 q_f + 0.198 (q_prev + q)`, differentiated, and the same filter on
    /// the velocity.
    #[default]
    R4,
    /// W2's first-order low-pass at `velocity_cutoff_hz` on the differentiated position.
    LowPass,
}

/// Per-joint calibration of a document-protocol hand (v1-v3; a v4 hand reports calibrated
/// positions, so these are not used for it).
#[derive(Debug, Clone, PartialEq, Eq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationConfig {
    /// Encoder offset per joint, counts (R1's zero.yaml: `offset`).
    pub offset: [i32; JOINTS],
    /// Encoder direction per joint, +1 or -1.
    pub encoder_dir: [i8; JOINTS],
    /// Motor direction per joint, +1 or -1.
    pub motor_dir: [i8; JOINTS],
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        Self {
            offset: [0; JOINTS],
            encoder_dir: [1; JOINTS],
            motor_dir: [1; JOINTS],
        }
    }
}

/// The node's configuration file.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AllegroConfig {
    /// Where the CAN bus is: `slcan:PATH[@SERIAL_BAUD]`, `socketcan:IFACE` or `local:SOCKET`.
    pub link: String,
    /// `auto`, `v1`, `v2`, `v3` or `v4`.
    pub protocol: ProtocolSetting,
    /// The v4 hand's device id (0..=3, kept in the hand's memory; 0 unless changed).
    pub device_id: u8,
    /// The hand's position stream period, ms (the document's 3 ms: 333 Hz).
    pub period_ms: u8,
    /// v4: the temperature stream period, ms (0: none).
    pub temperature_period_ms: u16,
    /// PWM counts per N m; unset: from the v4 hand's info (hardware version 4: 1200, else 800),
    /// else the generation's (v1, v2: 800 as the document says; v3: 1200).
    pub pwm_per_nm: Option<f64>,
    /// PWM limit per joint (R4/W2: fingers 375 675 450 285, thumb 525 405 270 270), each also
    /// capped at `pwm_per_nm` (the global limit in docs/devices/allegro.md).
    pub pwm_limit: [i16; JOINTS],
    /// Absolute torque limit per joint, N m.
    pub max_torque_nm: f64,
    /// Proportional gain per joint, PWM counts per rad (R4 defaults).
    pub kp: [f64; JOINTS],
    /// Derivative gain per joint, PWM counts per rad/s (R4 defaults).
    pub kd: [f64; JOINTS],
    /// Velocity estimate: `r4` or `low-pass`.
    pub velocity_filter: VelocityFilterKind,
    /// Cut-off of the `low-pass` velocity filter, Hz (W2: 30).
    pub velocity_cutoff_hz: f64,
    /// Encoder offsets and directions, motor directions (v1-v3 hands).
    pub calibration: CalibrationConfig,
    /// A hand command older than this (judged by its stamp) is stale: the hand holds its last
    /// target.
    pub stale_command_ms: u64,
    /// No finger frame for this long counts one missing cycle.
    pub frame_timeout_ms: u64,
    /// On a link that stamps frames with their bus time (an slcan adapter taking `Z1`), a wait
    /// without finger frames is only suspected missing for up to this long: the next frame's
    /// stamp tells whether the hand was silent or its frames only came late (a loaded host).
    /// Past it, or without stamps, each `frame_timeout_ms` counts (0: never suspect).
    pub late_frame_limit_ms: u64,
    /// A run of this many cycles with a missing finger frame or a bus error stops torque, sends
    /// SYSTEM_OFF and brings the hand up again (R1: more than 3 in a row).
    pub missing_frame_limit: u32,
    /// Bring-up: how long to wait for the hand's first answer and all four finger frames.
    pub bringup_timeout_ms: u64,
    /// Waits between attempts to open the link and bring the hand up: first, then doubling up to
    /// the second.
    pub reconnect_backoff_ms: [u64; 2],
    /// v4: how often the hand's info (temperature, status) is queried while running (0: never).
    pub info_period_ms: u64,
    /// Health and device info report period.
    pub health_period_ms: u64,
    /// After a hold (a stale or refused command, the e-stop) and at the first command, joint
    /// targets move from the held ones back to the operator's at most this fast, rad/s, then
    /// track the commands.
    pub resume_speed: f64,
    /// The hand profile (joint names and limits), relative to this file's folder.
    pub hand_profile: Option<PathBuf>,
}

impl Default for AllegroConfig {
    fn default() -> Self {
        // docs/devices/allegro.md, "Joints, limits, gains": R4's defaults, index middle ring thumb.
        let finger = |f: [f64; 4], t: [f64; 4]| -> [f64; JOINTS] {
            let mut out = [0.0; JOINTS];
            for (i, v) in out.iter_mut().enumerate() {
                *v = if i < 12 { f[i % 4] } else { t[i % 4] };
            }
            out
        };
        let mut pwm_limit = [0i16; JOINTS];
        for (i, v) in pwm_limit.iter_mut().enumerate() {
            // docs/devices/allegro.md: per-joint PWM limits of R4 and W2.
            *v = if i < 12 {
                [375, 675, 450, 285][i % 4]
            } else {
                [525, 405, 270, 270][i % 4]
            };
        }
        Self {
            link: "slcan:/tmp/teleop-allegro".into(),
            protocol: ProtocolSetting::Auto,
            device_id: 0,
            period_ms: 3,
            temperature_period_ms: 500,
            pwm_per_nm: None,
            pwm_limit,
            max_torque_nm: 1.0,
            kp: finger(
                [600.0, 600.0, 600.0, 1000.0],
                [1000.0, 1000.0, 1000.0, 600.0],
            ),
            kd: finger([15.0, 20.0, 15.0, 15.0], [30.0, 20.0, 20.0, 15.0]),
            velocity_filter: VelocityFilterKind::R4,
            velocity_cutoff_hz: 30.0,
            calibration: CalibrationConfig::default(),
            stale_command_ms: 100,
            frame_timeout_ms: 10,
            late_frame_limit_ms: 500,
            missing_frame_limit: 4,
            bringup_timeout_ms: 500,
            reconnect_backoff_ms: [100, 2000],
            info_period_ms: 1000,
            health_period_ms: 500,
            resume_speed: 1.0,
            hand_profile: None,
        }
    }
}

/// The configuration checked, in the forms the loop uses.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The link.
    pub link: LinkSpec,
    /// The protocol setting.
    pub protocol: ProtocolSetting,
    /// v4 device id.
    pub device_id: u8,
    /// Stream period.
    pub period: Duration,
    /// Stream period, ms.
    pub period_ms: u8,
    /// v4 temperature stream period, ms.
    pub temperature_period_ms: u16,
    /// Configured PWM per N m (None: from the hand).
    pub pwm_per_nm: Option<f64>,
    /// Per-joint PWM limits.
    pub pwm_limit: [i16; JOINTS],
    /// Torque limit, N m.
    pub max_torque_nm: f64,
    /// Gains.
    pub kp: [f64; JOINTS],
    /// Gains.
    pub kd: [f64; JOINTS],
    /// Velocity filter.
    pub velocity_filter: VelocityFilterKind,
    /// Its cut-off.
    pub velocity_cutoff_hz: f64,
    /// Per-joint calibration (document protocol).
    pub calibration: [JointCalibration; JOINTS],
    /// Stale command age.
    pub stale_command: Duration,
    /// Missing-cycle timeout.
    pub frame_timeout: Duration,
    /// How long a stamped link's silence may be thought late.
    pub late_frame_limit: Duration,
    /// Run length that brings the hand up again.
    pub missing_frame_limit: u32,
    /// Bring-up timeout.
    pub bringup_timeout: Duration,
    /// Reconnect backoff: first, most.
    pub backoff: [Duration; 2],
    /// Info query period (None: never).
    pub info_period: Option<Duration>,
    /// Health period.
    pub health_period: Duration,
    /// Most joint target motion after a hold, rad/s.
    pub resume_speed: f64,
}

/// The fastest `resume_speed`, rad/s.
pub const MAX_RESUME_SPEED: f64 = 20.0;

impl AllegroConfig {
    /// Checks every value; the message names the field.
    pub fn validate(&self) -> Result<Settings, String> {
        let link: LinkSpec = self
            .link
            .parse()
            .map_err(|e| format!("link = {:?}: {e}", self.link))?;
        if self.device_id > 3 {
            return Err(format!("device_id = {}: must be 0..=3", self.device_id));
        }
        if self.period_ms == 0 {
            return Err("period_ms must be 1..=255".into());
        }
        if let Some(k) = self.pwm_per_nm {
            if !(k.is_finite() && k > 0.0 && k <= 32767.0) {
                return Err(format!("pwm_per_nm = {k}: must be in (0, 32767]"));
            }
        }
        for (j, &l) in self.pwm_limit.iter().enumerate() {
            if l <= 0 {
                return Err(format!("pwm_limit[{j}] = {l}: must be > 0"));
            }
        }
        if !(self.max_torque_nm.is_finite() && self.max_torque_nm >= 0.0) {
            return Err(format!(
                "max_torque_nm = {}: must be a number >= 0",
                self.max_torque_nm
            ));
        }
        for (name, gains) in [("kp", &self.kp), ("kd", &self.kd)] {
            if let Some((j, g)) = gains
                .iter()
                .enumerate()
                .find(|(_, g)| !(g.is_finite() && **g >= 0.0))
            {
                return Err(format!("{name}[{j}] = {g}: must be a number >= 0"));
            }
        }
        if !(self.velocity_cutoff_hz.is_finite() && self.velocity_cutoff_hz > 0.0) {
            return Err(format!(
                "velocity_cutoff_hz = {}: must be > 0",
                self.velocity_cutoff_hz
            ));
        }
        let c = &self.calibration;
        for (name, dirs) in [
            ("calibration.encoder_dir", &c.encoder_dir),
            ("calibration.motor_dir", &c.motor_dir),
        ] {
            if let Some((j, d)) = dirs.iter().enumerate().find(|(_, d)| d.abs() != 1) {
                return Err(format!("{name}[{j}] = {d}: must be 1 or -1"));
            }
        }
        for (name, v) in [
            ("stale_command_ms", self.stale_command_ms),
            ("frame_timeout_ms", self.frame_timeout_ms),
            ("bringup_timeout_ms", self.bringup_timeout_ms),
            ("health_period_ms", self.health_period_ms),
            ("reconnect_backoff_ms[0]", self.reconnect_backoff_ms[0]),
            ("reconnect_backoff_ms[1]", self.reconnect_backoff_ms[1]),
        ] {
            teleop_runtime::check_ms(name, v)?;
        }
        if self.info_period_ms > 0 {
            teleop_runtime::check_ms("info_period_ms", self.info_period_ms)?;
        }
        if self.late_frame_limit_ms > 0 {
            teleop_runtime::check_ms("late_frame_limit_ms", self.late_frame_limit_ms)?;
        }
        if !(self.resume_speed > 0.0 && self.resume_speed <= MAX_RESUME_SPEED) {
            return Err(format!(
                "resume_speed = {}: must be in (0, {MAX_RESUME_SPEED}] rad/s",
                self.resume_speed
            ));
        }
        if self.reconnect_backoff_ms[1] < self.reconnect_backoff_ms[0] {
            return Err(format!(
                "reconnect_backoff_ms = {:?}: the second (most) must not be below the first",
                self.reconnect_backoff_ms
            ));
        }
        if self.missing_frame_limit == 0 {
            return Err("missing_frame_limit must be > 0".into());
        }
        let mut calibration = [JointCalibration {
            offset: 0,
            encoder_dir: 1,
            motor_dir: 1,
        }; JOINTS];
        for (j, cal) in calibration.iter_mut().enumerate() {
            *cal = JointCalibration {
                offset: c.offset[j],
                encoder_dir: c.encoder_dir[j],
                motor_dir: c.motor_dir[j],
            };
        }
        Ok(Settings {
            link,
            protocol: self.protocol,
            device_id: self.device_id,
            period: Duration::from_millis(u64::from(self.period_ms)),
            period_ms: self.period_ms,
            temperature_period_ms: self.temperature_period_ms,
            pwm_per_nm: self.pwm_per_nm,
            pwm_limit: self.pwm_limit,
            max_torque_nm: self.max_torque_nm,
            kp: self.kp,
            kd: self.kd,
            velocity_filter: self.velocity_filter,
            velocity_cutoff_hz: self.velocity_cutoff_hz,
            calibration,
            stale_command: Duration::from_millis(self.stale_command_ms),
            frame_timeout: Duration::from_millis(self.frame_timeout_ms),
            late_frame_limit: Duration::from_millis(self.late_frame_limit_ms),
            missing_frame_limit: self.missing_frame_limit,
            bringup_timeout: Duration::from_millis(self.bringup_timeout_ms),
            backoff: [
                Duration::from_millis(self.reconnect_backoff_ms[0]),
                Duration::from_millis(self.reconnect_backoff_ms[1]),
            ],
            info_period: (self.info_period_ms > 0)
                .then(|| Duration::from_millis(self.info_period_ms)),
            health_period: Duration::from_millis(self.health_period_ms),
            resume_speed: self.resume_speed,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn defaults_are_valid_and_follow_the_device_page() {
        let s = AllegroConfig::default().validate().unwrap();
        assert_eq!(s.period, Duration::from_millis(3));
        assert_eq!(&s.pwm_limit[..4], &[375, 675, 450, 285]);
        assert_eq!(&s.pwm_limit[12..], &[525, 405, 270, 270]);
        assert_eq!(&s.kp[..4], &[600.0, 600.0, 600.0, 1000.0]);
        assert_eq!(&s.kp[12..], &[1000.0, 1000.0, 1000.0, 600.0]);
        assert_eq!(&s.kd[4..8], &[15.0, 20.0, 15.0, 15.0]);
        assert_eq!(&s.kd[12..], &[30.0, 20.0, 20.0, 15.0]);
        assert_eq!(s.protocol, ProtocolSetting::Auto);
    }

    #[test]
    fn errors_name_the_field() {
        let parse = |text: &str| teleop_runtime::parse_toml::<AllegroConfig>(text, "a.toml");
        let cfg = parse("protocol = \"v3\"\nlink = \"local:/tmp/x.sock\"\n").unwrap();
        assert_eq!(cfg.protocol, ProtocolSetting::Fixed(Generation::V3));
        let err = parse("protocol = \"v5\"\n").unwrap_err().to_string();
        assert!(err.contains("use \"auto\""), "{err}");
        let err = parse("gain = 1\n").unwrap_err().to_string();
        assert!(err.contains("unknown field `gain`"), "{err}");
        let err = parse("[calibration]\noffst = [0]\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("unknown field `offst`"), "{err}");
        for (cfg, field) in [
            (
                AllegroConfig {
                    device_id: 4,
                    ..Default::default()
                },
                "device_id",
            ),
            (
                AllegroConfig {
                    link: "carrier-pigeon:1".into(),
                    ..Default::default()
                },
                "link",
            ),
            (
                AllegroConfig {
                    max_torque_nm: f64::NAN,
                    ..Default::default()
                },
                "max_torque_nm",
            ),
            (
                AllegroConfig {
                    missing_frame_limit: 0,
                    ..Default::default()
                },
                "missing_frame_limit",
            ),
        ] {
            let err = cfg.validate().unwrap_err();
            assert!(err.contains(field), "{field}: {err}");
        }
        let mut cfg = AllegroConfig::default();
        cfg.kd[5] = -1.0;
        assert!(cfg.validate().unwrap_err().contains("kd[5]"));
        cfg = AllegroConfig::default();
        cfg.calibration.motor_dir[13] = 0;
        assert!(cfg
            .validate()
            .unwrap_err()
            .contains("calibration.motor_dir[13]"));
        cfg = AllegroConfig::default();
        cfg.pwm_limit[2] = 0;
        assert!(cfg.validate().unwrap_err().contains("pwm_limit[2]"));
        for (text, field) in [
            ("stale_command_ms = 0\n", "stale_command_ms = 0"),
            ("stale_command_ms = 60001\n", "stale_command_ms = 60001"),
            (
                "frame_timeout_ms = 18446744073709551615\n",
                "frame_timeout_ms = 18446744073709551615",
            ),
            ("bringup_timeout_ms = 0\n", "bringup_timeout_ms"),
            ("health_period_ms = 120000\n", "health_period_ms"),
            (
                "reconnect_backoff_ms = [100, 3600000]\n",
                "reconnect_backoff_ms[1]",
            ),
            ("info_period_ms = 86400000\n", "info_period_ms"),
            ("resume_speed = 0.0\n", "resume_speed"),
            ("resume_speed = inf\n", "resume_speed"),
        ] {
            let err = parse(text).unwrap().validate().unwrap_err();
            assert!(err.starts_with(field), "{text}: {err}");
        }
        let s = parse("info_period_ms = 0\nresume_speed = 0.5\n")
            .unwrap()
            .validate()
            .unwrap();
        assert_eq!((s.info_period, s.resume_speed), (None, 0.5));
    }
}
