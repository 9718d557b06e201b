//! The Revo2 node's configuration file.

pub use teleop_ecat_master::Transport;

/// How tactile data is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TactileSource {
    /// In the process data (TxPDO 0x1A01 assigned to SM3); falls back to SDO polling if the
    /// device refuses that assignment.
    Pdo,
    /// Poll object 0x6010 by SDO at `tactile_poll_hz`.
    Sdo,
    /// No tactile data.
    Off,
}

/// Values written to 0x8000 in PRE-OP (and read back). Absent values are left as they are.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceSettings {
    /// 0 = left hand, 1 = right hand.
    pub hand_type: Option<u8>,
    /// Back-of-hand light.
    pub led_switch: Option<u8>,
    /// Buzzer.
    pub buzzer_switch: Option<u8>,
    /// Vibration motor.
    pub vibrator_switch: Option<u8>,
    /// 0 = percentage units, 1 = physical units.
    pub unit_mode: Option<u8>,
    /// Calibrate automatically at power-on.
    pub auto_calibration: Option<u8>,
    /// Turbo mode.
    pub turbo_mode: Option<u8>,
    /// Protection currents per joint (thumb flex, thumb abduct, index, middle, ring, pinky), mA.
    pub protection_current_ma: Option<[u16; 6]>,
    /// Thumb abduction locking current, mA.
    pub thumb_aux_lock_cur: Option<u16>,
}

/// The node's configuration file (`config/revo2.toml`).
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Revo2Config {
    /// `interface:NAME` (recommended for hardware: the node's frame pump on a raw socket,
    /// survives interface resets), `ethercrab:NAME` (ethercrab's own raw-socket task; the node
    /// opens a fresh bus after that task ends on a socket error) or `sim:SOCKET` (the emulator).
    /// See [`Transport`].
    pub transport: String,
    /// Cycle rate in Hz.
    pub cycle_hz: f64,
    /// A hand command older than this is stale: the hand holds its last target.
    pub stale_command_ms: u64,
    /// Without a valid exchange (answer with the right working counter, device in OP) for this
    /// long, the link counts as lost: `hand/state` says so and the bus is brought up again.
    pub link_timeout_ms: u64,
    /// Tactile data source.
    pub tactile: TactileSource,
    /// SDO polling rate of the tactile object when it is not in the process data.
    pub tactile_poll_hz: f64,
    /// Hand speed at 100 % speed, in joint travel per second (the document does not give it; used
    /// to turn normalised speed limits into the device's per-mille speed).
    pub full_speed_travel_per_s: f32,
    /// Speed used when holding after a stale command, per mille of full speed (converted to
    /// degrees per second in physical units).
    pub hold_speed_per_mille: u16,
    /// Health report period.
    pub health_period_ms: u64,
    /// After a hold (a stale command, the e-stop, a refused command), position targets move
    /// from the held ones back to the operator's at most this fast, in joint travel per second
    /// (the device's full speed is about `full_speed_travel_per_s`), then track the commands.
    pub resume_speed: f64,
    /// 0x8000 configuration applied in PRE-OP.
    pub device: DeviceSettings,
}

impl Default for Revo2Config {
    fn default() -> Self {
        Self {
            transport: "sim:/tmp/teleop-revo2.sock".into(),
            cycle_hz: 1000.0,
            stale_command_ms: 100,
            link_timeout_ms: 100,
            tactile: TactileSource::Pdo,
            tactile_poll_hz: 50.0,
            full_speed_travel_per_s: 2.0,
            hold_speed_per_mille: 300,
            health_period_ms: 500,
            resume_speed: 1.0,
            device: DeviceSettings::default(),
        }
    }
}

/// The fastest `resume_speed`, travel per second (the whole travel in a tenth of a second).
pub const MAX_RESUME_SPEED: f64 = 10.0;

impl Revo2Config {
    /// The parsed transport and every value checked; messages name the field.
    pub fn validate(&self) -> Result<Transport, String> {
        let transport = Transport::parse(&self.transport)?;
        if !(self.cycle_hz >= 10.0 && self.cycle_hz <= 4000.0) {
            return Err(format!("cycle_hz = {}: must be 10..=4000", self.cycle_hz));
        }
        if !(self.tactile_poll_hz > 0.0 && self.tactile_poll_hz <= 500.0) {
            return Err(format!(
                "tactile_poll_hz = {}: must be in (0, 500]",
                self.tactile_poll_hz
            ));
        }
        if !(self.full_speed_travel_per_s > 0.0 && self.full_speed_travel_per_s.is_finite()) {
            return Err("full_speed_travel_per_s must be > 0".into());
        }
        if self.hold_speed_per_mille == 0 || self.hold_speed_per_mille > 1000 {
            return Err("hold_speed_per_mille must be 1..=1000".into());
        }
        let d = &self.device;
        for (name, v, max) in [
            ("hand_type", d.hand_type, 1),
            ("unit_mode", d.unit_mode, 1),
            ("led_switch", d.led_switch, 255),
        ] {
            if v.is_some_and(|v| v > max) {
                return Err(format!(
                    "device.{name} = {}: must be 0..={max}",
                    v.unwrap_or(0)
                ));
            }
        }
        for (name, ms) in [
            ("stale_command_ms", self.stale_command_ms),
            ("link_timeout_ms", self.link_timeout_ms),
            ("health_period_ms", self.health_period_ms),
        ] {
            teleop_runtime::check_ms(name, ms)?;
        }
        if !(self.resume_speed > 0.0 && self.resume_speed <= MAX_RESUME_SPEED) {
            return Err(format!(
                "resume_speed = {}: must be in (0, {MAX_RESUME_SPEED}] travel per second",
                self.resume_speed
            ));
        }
        Ok(transport)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_the_field() {
        assert!(Revo2Config::default().validate().is_ok());
        // Joint limits are the hand profile's (config/hands/revo2.toml), never the node's.
        let err =
            teleop_runtime::parse_toml::<Revo2Config>("joint_max = [1.0]\n", "r.toml").unwrap_err();
        assert!(
            err.to_string().contains("unknown field `joint_max`"),
            "{err}"
        );
        for (text, field) in [
            ("stale_command_ms = 0\n", "stale_command_ms = 0"),
            ("stale_command_ms = 60001\n", "stale_command_ms = 60001"),
            (
                "stale_command_ms = 18446744073709551615\n",
                "stale_command_ms = 18446744073709551615",
            ),
            ("link_timeout_ms = 0\n", "link_timeout_ms"),
            ("health_period_ms = 100000\n", "health_period_ms"),
            ("resume_speed = 0.0\n", "resume_speed"),
            ("resume_speed = nan\n", "resume_speed"),
            ("resume_speed = inf\n", "resume_speed"),
        ] {
            let cfg: Revo2Config = teleop_runtime::parse_toml(text, "r.toml").unwrap();
            let err = cfg.validate().unwrap_err();
            assert!(err.starts_with(field), "{text}: {err}");
        }
        let cfg: Revo2Config =
            teleop_runtime::parse_toml("stale_command_ms = 60000\nresume_speed = 0.25\n", "r.toml")
                .unwrap();
        assert!(cfg.validate().is_ok());
        let cfg: Revo2Config =
            teleop_runtime::parse_toml("[device]\nled_switch = 1\nunit_mode = 0\n", "r.toml")
                .unwrap();
        assert_eq!(cfg.device.led_switch, Some(1));
        let err =
            teleop_runtime::parse_toml::<Revo2Config>("[device]\nled = 1\n", "r.toml").unwrap_err();
        assert!(err.to_string().contains("unknown field `led`"), "{err}");
    }
}
