//! The LEAP node's configuration file (`config/leap.toml`) and its checked form.
//!
//! Defaults follow the shipped LEAP Hand API (docs/devices/leap.md, "The shipped API"): 4 Mbit/s,
//! current-based position control, gains P 600, I 0, D 200 (the side joints 0, 4 and 8 at
//! 0.75 of them), Goal Current 350 mA; and what the API leaves at the servos' 500 us default
//! and we set: Return Delay Time 0. The loop rate is ours: 500 full-state cycles per second.

use std::path::PathBuf;
use std::time::Duration;

/// Servos (joints) of the LEAP Hand.
pub const SERVOS: usize = 16;

/// The Dynamixel X330 models the node takes (`model`): the XC330-M288-T of the full hand and
/// the XL330-M077-T of the Lite hand (ROBOTIS e-manual, "Model Number" of each).
pub const ACCEPTED_MODELS: [u16; 2] = [1240, 1190];

/// Baud rates an X330 can be set to (ROBOTIS e-manual, Control Table "Baud Rate", values 0..6).
pub const BAUD_RATES: [u32; 7] = [
    9_600, 57_600, 115_200, 1_000_000, 2_000_000, 3_000_000, 4_000_000,
];

/// The side (MCP abduction) joints, whose gains the shipped API scales by 0.75.
pub const SIDE_JOINTS: [usize; 3] = [0, 4, 8];

/// The node's configuration file.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LeapConfig {
    /// The serial port of the U2D2 (or other USB adapter): `/dev/serial/by-id/usb-FTDI_...` on
    /// hardware, the simulator's pseudo-terminal link otherwise.
    pub port: String,
    /// Bits per second; the servos must already be set to it (the shipped API: 4 000 000).
    pub baud: u32,
    /// Full-state cycles per second (goal write, then current, velocity and position of every
    /// servo).
    pub rate_hz: u32,
    /// Return Delay Time written to every servo at bring-up, microseconds (0..=508, even: the
    /// register counts 2 us).
    pub return_delay_us: u32,
    /// What a reply may take beyond its bytes on the wire and the return delay, microseconds:
    /// the USB adapter's latency (its latency timer: 1 ms when set low) and scheduling.
    pub reply_slack_us: u32,
    /// Position P gain (register units) per joint, in joint (ID) order.
    pub position_p_gain: [u16; SERVOS],
    /// Position I gain per joint.
    pub position_i_gain: [u16; SERVOS],
    /// Position D gain per joint.
    pub position_d_gain: [u16; SERVOS],
    /// Goal Current written at bring-up, mA: the most current each servo's position loop may
    /// ask for (the shipped API: 350; up to 550 for full XC330 hands).
    pub current_limit_ma: u16,
    /// The servo IDs, in the profile's joint order.
    pub ids: [u8; SERVOS],
    /// The Model Number every servo must report (1240 XC330-M288-T; 1190 XL330-M077-T for a
    /// Lite hand).
    pub model: u16,
    /// A hand command older than this (by its stamp) is stale: the hand holds its last target.
    pub stale_command_ms: u64,
    /// After a hold and at the first command, targets ramp back at most this fast, rad/s.
    pub resume_speed: f64,
    /// Health and device info report period.
    pub health_period_ms: u64,
    /// A run of this many cycles without any servo's state (no reply, or only bad ones) loses
    /// the hand: torque off, the port closed and opened again.
    pub failed_cycle_limit: u32,
    /// How often a silent servo is looked for again.
    pub silent_retry_ms: u64,
    /// Waits between attempts to open the port and bring the hand up: first, then doubling up
    /// to the second.
    pub reconnect_backoff_ms: [u64; 2],
    /// The hand profile (joint names, limits, device map), relative to this file's folder;
    /// unset: the shipped LEAP profile.
    pub hand_profile: Option<PathBuf>,
}

impl Default for LeapConfig {
    fn default() -> Self {
        // docs/devices/leap.md, "The shipped API": P 600, I 0, D 200, the side joints x 0.75.
        let gain = |g: u16| -> [u16; SERVOS] {
            let mut out = [g; SERVOS];
            for j in SIDE_JOINTS {
                out[j] = g * 3 / 4;
            }
            out
        };
        let mut ids = [0u8; SERVOS];
        for (i, id) in ids.iter_mut().enumerate() {
            *id = i as u8;
        }
        Self {
            port: "/tmp/teleop-leap".into(),
            baud: 4_000_000,
            rate_hz: 500,
            return_delay_us: 0,
            reply_slack_us: 3000,
            position_p_gain: gain(600),
            position_i_gain: gain(0),
            position_d_gain: gain(200),
            current_limit_ma: 350,
            ids,
            model: 1240,
            stale_command_ms: 100,
            resume_speed: 1.0,
            health_period_ms: 500,
            failed_cycle_limit: 50,
            silent_retry_ms: 1000,
            reconnect_backoff_ms: [100, 2000],
            hand_profile: None,
        }
    }
}

/// The configuration checked, in the forms the loop uses.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The serial port.
    pub port: String,
    /// Bits per second.
    pub baud: u32,
    /// The cycle period.
    pub period: Duration,
    /// Return Delay Time register value (2 us units).
    pub return_delay: u8,
    /// Slack on every reply's timeout.
    pub reply_slack: Duration,
    /// Position gains per joint: P, I, D.
    pub gains: [[u16; 3]; SERVOS],
    /// Goal Current, mA.
    pub current_limit_ma: u16,
    /// Servo IDs in joint order.
    pub ids: [u8; SERVOS],
    /// Expected Model Number.
    pub model: u16,
    /// Stale command age.
    pub stale_command: Duration,
    /// Most target motion after a hold, rad/s.
    pub resume_speed: f64,
    /// Health period.
    pub health_period: Duration,
    /// Failed cycles in a row that lose the hand.
    pub failed_cycle_limit: u32,
    /// How often a silent servo is looked for.
    pub silent_retry: Duration,
    /// Reconnect back-off: first, most.
    pub backoff: [Duration; 2],
}

/// The fastest `resume_speed`, rad/s.
pub const MAX_RESUME_SPEED: f64 = 20.0;

/// The highest `rate_hz`.
pub const MAX_RATE_HZ: u32 = 2000;

/// Most Goal Current, mA (the XC330-M288's Current Limit range, ROBOTIS e-manual).
pub const MAX_CURRENT_MA: u16 = 2352;

impl LeapConfig {
    /// Checks every value; the message names the field.
    pub fn validate(&self) -> Result<Settings, String> {
        if self.port.is_empty() {
            return Err("port must name the serial port".into());
        }
        if !BAUD_RATES.contains(&self.baud) {
            return Err(format!(
                "baud = {}: an X330 runs at one of {BAUD_RATES:?}",
                self.baud
            ));
        }
        if !(1..=MAX_RATE_HZ).contains(&self.rate_hz) {
            return Err(format!(
                "rate_hz = {}: must be 1..={MAX_RATE_HZ}",
                self.rate_hz
            ));
        }
        if self.return_delay_us > 508 || !self.return_delay_us.is_multiple_of(2) {
            return Err(format!(
                "return_delay_us = {}: must be even and 0..=508 (the register counts 2 us up to \
                 254)",
                self.return_delay_us
            ));
        }
        if self.reply_slack_us > 100_000 {
            return Err(format!(
                "reply_slack_us = {}: must be 0..=100000",
                self.reply_slack_us
            ));
        }
        for (name, gains) in [
            ("position_p_gain", &self.position_p_gain),
            ("position_i_gain", &self.position_i_gain),
            ("position_d_gain", &self.position_d_gain),
        ] {
            if let Some((j, g)) = gains.iter().enumerate().find(|(_, g)| **g > 16383) {
                return Err(format!("{name}[{j}] = {g}: must be 0..=16383"));
            }
        }
        if !(1..=MAX_CURRENT_MA).contains(&self.current_limit_ma) {
            return Err(format!(
                "current_limit_ma = {}: must be 1..={MAX_CURRENT_MA}",
                self.current_limit_ma
            ));
        }
        for (j, &id) in self.ids.iter().enumerate() {
            if id > 252 {
                return Err(format!("ids[{j}] = {id}: must be 0..=252"));
            }
            if self.ids[..j].contains(&id) {
                return Err(format!("ids[{j}] = {id}: used twice"));
            }
        }
        if !ACCEPTED_MODELS.contains(&self.model) {
            return Err(format!(
                "model = {}: use 1240 (XC330-M288-T) or 1190 (XL330-M077-T, the Lite hand)",
                self.model
            ));
        }
        for (name, v) in [
            ("stale_command_ms", self.stale_command_ms),
            ("health_period_ms", self.health_period_ms),
            ("silent_retry_ms", self.silent_retry_ms),
            ("reconnect_backoff_ms[0]", self.reconnect_backoff_ms[0]),
            ("reconnect_backoff_ms[1]", self.reconnect_backoff_ms[1]),
        ] {
            teleop_runtime::check_ms(name, v)?;
        }
        if self.reconnect_backoff_ms[1] < self.reconnect_backoff_ms[0] {
            return Err(format!(
                "reconnect_backoff_ms = {:?}: the second (most) must not be below the first",
                self.reconnect_backoff_ms
            ));
        }
        if !(self.resume_speed > 0.0 && self.resume_speed <= MAX_RESUME_SPEED) {
            return Err(format!(
                "resume_speed = {}: must be in (0, {MAX_RESUME_SPEED}] rad/s",
                self.resume_speed
            ));
        }
        if self.failed_cycle_limit == 0 {
            return Err("failed_cycle_limit must be > 0".into());
        }
        let mut gains = [[0u16; 3]; SERVOS];
        for (j, g) in gains.iter_mut().enumerate() {
            *g = [
                self.position_p_gain[j],
                self.position_i_gain[j],
                self.position_d_gain[j],
            ];
        }
        Ok(Settings {
            port: self.port.clone(),
            baud: self.baud,
            period: Duration::from_nanos(1_000_000_000 / u64::from(self.rate_hz)),
            return_delay: (self.return_delay_us / 2) as u8,
            reply_slack: Duration::from_micros(u64::from(self.reply_slack_us)),
            gains,
            current_limit_ma: self.current_limit_ma,
            ids: self.ids,
            model: self.model,
            stale_command: Duration::from_millis(self.stale_command_ms),
            resume_speed: self.resume_speed,
            health_period: Duration::from_millis(self.health_period_ms),
            failed_cycle_limit: self.failed_cycle_limit,
            silent_retry: Duration::from_millis(self.silent_retry_ms),
            backoff: [
                Duration::from_millis(self.reconnect_backoff_ms[0]),
                Duration::from_millis(self.reconnect_backoff_ms[1]),
            ],
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn defaults_are_the_shipped_apis_at_our_rate() {
        let s = LeapConfig::default().validate().unwrap();
        assert_eq!(s.period, Duration::from_millis(2));
        assert_eq!(s.baud, 4_000_000);
        assert_eq!(s.return_delay, 0);
        assert_eq!(s.gains[0], [450, 0, 150]);
        assert_eq!(s.gains[1], [600, 0, 200]);
        assert_eq!(s.gains[4], [450, 0, 150]);
        assert_eq!(s.gains[8], [450, 0, 150]);
        assert_eq!(s.gains[12], [600, 0, 200]);
        assert_eq!(s.current_limit_ma, 350);
        assert_eq!(s.ids[15], 15);
        assert_eq!(s.model, 1240);
    }

    #[test]
    fn the_shipped_file_is_the_defaults() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../../config/leap.toml");
        let cfg: LeapConfig = teleop_runtime::load_toml(&path).unwrap();
        let (a, b) = (
            cfg.validate().unwrap(),
            LeapConfig::default().validate().unwrap(),
        );
        assert_eq!(
            (
                a.baud,
                a.period,
                a.gains,
                a.current_limit_ma,
                a.ids,
                a.model
            ),
            (
                b.baud,
                b.period,
                b.gains,
                b.current_limit_ma,
                b.ids,
                b.model
            )
        );
        assert_eq!(
            cfg.hand_profile.as_deref(),
            Some(std::path::Path::new("hands/leap.toml"))
        );
    }

    #[test]
    fn errors_name_the_field() {
        let parse = |text: &str| teleop_runtime::parse_toml::<LeapConfig>(text, "leap.toml");
        let err = parse("gain = 1\n").unwrap_err().to_string();
        assert!(err.contains("unknown field `gain`"), "{err}");
        for (text, field) in [
            ("baud = 1500000\n", "baud = 1500000"),
            ("rate_hz = 0\n", "rate_hz = 0"),
            ("return_delay_us = 3\n", "return_delay_us = 3"),
            ("return_delay_us = 510\n", "return_delay_us = 510"),
            ("reply_slack_us = 1000000\n", "reply_slack_us"),
            ("current_limit_ma = 0\n", "current_limit_ma = 0"),
            ("current_limit_ma = 3000\n", "current_limit_ma = 3000"),
            ("model = 1000\n", "model = 1000"),
            ("stale_command_ms = 0\n", "stale_command_ms = 0"),
            ("health_period_ms = 120000\n", "health_period_ms"),
            ("silent_retry_ms = 0\n", "silent_retry_ms"),
            (
                "reconnect_backoff_ms = [100, 3600000]\n",
                "reconnect_backoff_ms[1]",
            ),
            (
                "reconnect_backoff_ms = [500, 100]\n",
                "reconnect_backoff_ms",
            ),
            ("resume_speed = 0.0\n", "resume_speed"),
            ("resume_speed = nan\n", "resume_speed"),
            ("failed_cycle_limit = 0\n", "failed_cycle_limit"),
            ("port = \"\"\n", "port"),
        ] {
            let err = parse(text).unwrap().validate().unwrap_err();
            assert!(err.starts_with(field), "{text}: {err}");
        }
        let mut cfg = LeapConfig::default();
        cfg.position_d_gain[7] = 20000;
        assert!(cfg
            .validate()
            .unwrap_err()
            .starts_with("position_d_gain[7]"));
        let mut cfg = LeapConfig::default();
        cfg.ids[9] = 3;
        let err = cfg.validate().unwrap_err();
        assert!(err.starts_with("ids[9] = 3: used twice"), "{err}");
        cfg.ids[9] = 253;
        assert!(cfg.validate().unwrap_err().starts_with("ids[9] = 253"));
        let s = parse("model = 1190\nrate_hz = 1000\nreturn_delay_us = 500\n")
            .unwrap()
            .validate()
            .unwrap();
        assert_eq!(
            (s.model, s.period, s.return_delay),
            (1190, Duration::from_millis(1), 250)
        );
    }
}
