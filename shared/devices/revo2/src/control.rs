//! Control modes, unit modes and typed command building (section 5).

use crate::identity::{Joint, JOINTS};
use crate::image::{MultiFingerCommand, SingleFingerCommand};

/// Mode value meaning "no command" in 0x7000:01 / 0x7010:01.
///
/// The document defines modes 1..=5 only. We use 0 for "no command" (an
/// all-zero output image, as a master sends before its first cycle), and
/// never assume what the hand does with it (ambiguity 8).
pub const MODE_NONE: u8 = 0;

/// Control mode (section 5.1), for multi- and single-finger control.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum ControlMode {
    /// `CTRL_MODE_POS_TIME`: param1 target position, param2 movement time
    /// in ms.
    PositionTime = 1,
    /// `CTRL_MODE_POS_SPD`: param1 target position, param2 movement speed
    /// (a magnitude).
    PositionSpeed = 2,
    /// `CTRL_MODE_SPD`: param1 target speed, param2 unused.
    Speed = 3,
    /// `CTRL_MODE_CURRENT`: param1 target current, param2 unused.
    Current = 4,
    /// `CTRL_MODE_PWM`: param1 PWM ratio -1000..=1000 (unitless in both
    /// unit modes), param2 unused.
    Pwm = 5,
}

impl ControlMode {
    /// All modes.
    pub const ALL: [ControlMode; 5] = [
        ControlMode::PositionTime,
        ControlMode::PositionSpeed,
        ControlMode::Speed,
        ControlMode::Current,
        ControlMode::Pwm,
    ];

    /// The mode with wire value `v` (1..=5); `None` for 0 and unknown.
    pub const fn from_u8(v: u8) -> Option<ControlMode> {
        match v {
            1 => Some(ControlMode::PositionTime),
            2 => Some(ControlMode::PositionSpeed),
            3 => Some(ControlMode::Speed),
            4 => Some(ControlMode::Current),
            5 => Some(ControlMode::Pwm),
            _ => None,
        }
    }

    /// The wire value.
    pub const fn to_u8(self) -> u8 {
        self as u8
    }

    /// What param1 and param2 mean in this mode (section 5.1).
    pub const fn param_meaning(self) -> (&'static str, &'static str) {
        match self {
            ControlMode::PositionTime => ("target position", "movement time (ms)"),
            ControlMode::PositionSpeed => ("target position", "movement speed"),
            ControlMode::Speed => ("target speed", "none"),
            ControlMode::Current => ("target current", "none"),
            ControlMode::Pwm => ("PWM ratio (-1000..=1000)", "none"),
        }
    }

    /// Whether param2 is used.
    pub const fn has_param2(self) -> bool {
        matches!(self, ControlMode::PositionTime | ControlMode::PositionSpeed)
    }
}

/// Unit mode, configuration entry `unit_mode` 0x8000:05 (section 5.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[repr(u8)]
pub enum UnitMode {
    /// Dimensionless: positions 0..=1000 of travel, speeds and currents
    /// -1000..=1000 of the maximum (current maximum 1000 mA).
    #[default]
    Percent = 0,
    /// Physical: degrees, degrees per second, mA.
    Physical = 1,
}

impl UnitMode {
    /// The unit mode with wire value `v`.
    pub const fn from_u8(v: u8) -> Option<UnitMode> {
        match v {
            0 => Some(UnitMode::Percent),
            1 => Some(UnitMode::Physical),
            _ => None,
        }
    }

    /// The wire value.
    pub const fn to_u8(self) -> u8 {
        self as u8
    }
}

/// Full scale of the dimensionless ("percent") mode: 1000 = 100 %.
pub const PERCENT_FULL: u16 = 1000;
/// Maximum motor current, mA (section 5.3: percent of 1000 mA).
pub const MAX_CURRENT_MA: f32 = 1000.0;

/// Raw units per degree of a physical-mode position. The document gives
/// the unit (°) but no scale; 1 raw = 1° is assumed (ambiguity 10).
pub const POSITION_RAW_PER_DEG: f32 = 1.0;
/// Raw units per degree/second of a physical-mode speed (assumed 1).
pub const SPEED_RAW_PER_DEG_S: f32 = 1.0;
/// Raw units per mA of a physical-mode current (assumed 1).
pub const CURRENT_RAW_PER_MA: f32 = 1.0;

/// Scales of the physical unit mode, raw units per physical unit. The
/// document names the units but not the resolution; the defaults are the
/// `*_RAW_PER_*` constants (1 raw = 1 unit). Correct them here if the
/// hardware shows otherwise (e.g. 0.1° resolution = 10 raw per degree).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicalScale {
    /// Raw units per degree (positions).
    pub position_per_deg: f32,
    /// Raw units per degree/second (speeds).
    pub speed_per_deg_s: f32,
    /// Raw units per mA (currents).
    pub current_per_ma: f32,
}

impl PhysicalScale {
    /// The assumed scales (all 1).
    pub const DEFAULT: PhysicalScale = PhysicalScale {
        position_per_deg: POSITION_RAW_PER_DEG,
        speed_per_deg_s: SPEED_RAW_PER_DEG_S,
        current_per_ma: CURRENT_RAW_PER_MA,
    };
}

impl Default for PhysicalScale {
    fn default() -> Self {
        PhysicalScale::DEFAULT
    }
}

/// Accepted raw parameter ranges for one mode and unit mode (inclusive).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamLimits {
    /// (min, max) of param1.
    pub param1: (i16, i16),
    /// (min, max) of param2; (0, 0) when the mode does not use it.
    pub param2: (u16, u16),
}

/// Raw parameter ranges the command builders accept.
///
/// * Percent mode: positions 0..=1000, speeds, currents and PWM
///   -1000..=1000, param2 speed 0..=1000 (a magnitude).
/// * Physical mode: positions 0..=32767 raw (the positions read back in
///   0x6000:01 are unsigned, so targets are taken as non-negative;
///   ambiguity 11), speeds the whole `i16` range, param2 speed the whole
///   `u16` range, currents within ±1000 mA (the maximum of section 5.3)
///   times the scale, PWM -1000..=1000.
/// * Movement time (position + time param2): 0..=65535 ms in both modes.
pub fn param_limits(mode: ControlMode, units: UnitMode, scale: &PhysicalScale) -> ParamLimits {
    const PCT: i16 = PERCENT_FULL as i16;
    let percent = units == UnitMode::Percent;
    let position = if percent { (0, PCT) } else { (0, i16::MAX) };
    match mode {
        ControlMode::PositionTime => ParamLimits {
            param1: position,
            param2: (0, u16::MAX),
        },
        ControlMode::PositionSpeed => ParamLimits {
            param1: position,
            param2: if percent {
                (0, PERCENT_FULL)
            } else {
                (0, u16::MAX)
            },
        },
        ControlMode::Speed => ParamLimits {
            param1: if percent {
                (-PCT, PCT)
            } else {
                (i16::MIN, i16::MAX)
            },
            param2: (0, 0),
        },
        ControlMode::Current => {
            let max = if percent {
                PCT
            } else {
                let m = (MAX_CURRENT_MA * scale.current_per_ma).abs().round();
                if m.is_finite() {
                    m.min(f32::from(i16::MAX)) as i16
                } else {
                    i16::MAX
                }
            };
            ParamLimits {
                param1: (-max, max),
                param2: (0, 0),
            }
        }
        ControlMode::Pwm => ParamLimits {
            param1: (-PCT, PCT),
            param2: (0, 0),
        },
    }
}

/// Raw units per given unit of (param1, param2).
fn factors(mode: ControlMode, units: UnitMode, scale: &PhysicalScale) -> (f32, f32) {
    if units == UnitMode::Percent {
        return (1.0, 1.0);
    }
    match mode {
        ControlMode::PositionTime => (scale.position_per_deg, 1.0),
        ControlMode::PositionSpeed => (scale.position_per_deg, scale.speed_per_deg_s),
        ControlMode::Speed => (scale.speed_per_deg_s, 1.0),
        ControlMode::Current => (scale.current_per_ma, 1.0),
        ControlMode::Pwm => (1.0, 1.0),
    }
}

/// Why a command could not be built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum CommandError {
    /// A value is NaN or infinite.
    #[error("{joint:?} param{param}: {value} is not a finite number")]
    NotFinite {
        /// The joint.
        joint: Joint,
        /// 1 or 2.
        param: u8,
        /// The value given.
        value: f32,
    },
    /// A value is outside the range of the mode and unit mode.
    #[error("{joint:?} param{param}: {raw} (raw, from {value}) outside {min}..={max}")]
    OutOfRange {
        /// The joint.
        joint: Joint,
        /// 1 or 2.
        param: u8,
        /// The value given.
        value: f32,
        /// The value scaled and rounded to raw units.
        raw: f32,
        /// Smallest raw value accepted.
        min: i32,
        /// Largest raw value accepted.
        max: i32,
    },
}

fn to_raw(
    joint: Joint,
    param: u8,
    value: f32,
    factor: f32,
    (min, max): (i32, i32),
) -> Result<i32, CommandError> {
    if !value.is_finite() {
        return Err(CommandError::NotFinite {
            joint,
            param,
            value,
        });
    }
    let raw = (value * factor).round();
    // `min`/`max` are i16/u16 values, exact in f32.
    if !raw.is_finite() || raw < min as f32 || raw > max as f32 {
        return Err(CommandError::OutOfRange {
            joint,
            param,
            value,
            raw,
            min,
            max,
        });
    }
    Ok(raw as i32)
}

/// Converts one joint's target and second parameter to raw (param1,
/// param2).
fn convert(
    mode: ControlMode,
    joint: Joint,
    target: f32,
    second: f32,
    units: UnitMode,
    scale: &PhysicalScale,
) -> Result<(i16, u16), CommandError> {
    let limits = param_limits(mode, units, scale);
    let (f1, f2) = factors(mode, units, scale);
    let p1 = to_raw(
        joint,
        1,
        target,
        f1,
        (i32::from(limits.param1.0), i32::from(limits.param1.1)),
    )?;
    let p2 = if mode.has_param2() {
        to_raw(
            joint,
            2,
            second,
            f2,
            (i32::from(limits.param2.0), i32::from(limits.param2.1)),
        )?
    } else {
        0
    };
    // In range of the limits, hence of the types.
    Ok((
        i16::try_from(p1).unwrap_or_default(),
        u16::try_from(p2).unwrap_or_default(),
    ))
}

/// Builds a multi-finger command with the assumed physical scales
/// ([`PhysicalScale::DEFAULT`]); see [`multi_command_scaled`].
pub fn multi_command(
    mode: ControlMode,
    targets: [f32; JOINTS],
    second: [f32; JOINTS],
    units: UnitMode,
) -> Result<MultiFingerCommand, CommandError> {
    multi_command_scaled(mode, targets, second, units, &PhysicalScale::DEFAULT)
}

/// Builds a multi-finger command (0x7000) for all 6 joints.
///
/// `targets` is param1 per joint and `second` param2, in the units of
/// `units` (the hand's `unit_mode`, which the caller must know):
///
/// | mode | `targets` percent / physical | `second` |
/// |---|---|---|
/// | position + time | 0..=1000 / degrees | time, ms (0..=65535) |
/// | position + speed | 0..=1000 / degrees | speed magnitude, 0..=1000 / °/s |
/// | speed | -1000..=1000 / °/s | ignored (param2 = 0) |
/// | current | -1000..=1000 / mA (±1000) | ignored (param2 = 0) |
/// | PWM | -1000..=1000 in both | ignored (param2 = 0) |
///
/// Values are scaled by `scale` (physical mode), rounded to the nearest
/// integer and checked against [`param_limits`]; NaN and infinities are
/// refused. Ignored values are not checked.
pub fn multi_command_scaled(
    mode: ControlMode,
    targets: [f32; JOINTS],
    second: [f32; JOINTS],
    units: UnitMode,
    scale: &PhysicalScale,
) -> Result<MultiFingerCommand, CommandError> {
    let mut cmd = MultiFingerCommand {
        mode: mode.to_u8(),
        ..MultiFingerCommand::default()
    };
    for joint in Joint::ALL {
        let i = joint.index();
        let (p1, p2) = convert(mode, joint, targets[i], second[i], units, scale)?;
        cmd.param1[i] = p1;
        cmd.param2[i] = p2;
    }
    Ok(cmd)
}

/// Builds a single-finger command with the assumed physical scales; see
/// [`single_command_scaled`].
pub fn single_command(
    mode: ControlMode,
    joint: Joint,
    target: f32,
    second: f32,
    units: UnitMode,
) -> Result<SingleFingerCommand, CommandError> {
    single_command_scaled(mode, joint, target, second, units, &PhysicalScale::DEFAULT)
}

/// Builds a single-finger command (0x7010) for one joint, with the same
/// conversions and checks as [`multi_command_scaled`].
pub fn single_command_scaled(
    mode: ControlMode,
    joint: Joint,
    target: f32,
    second: f32,
    units: UnitMode,
    scale: &PhysicalScale,
) -> Result<SingleFingerCommand, CommandError> {
    let (param1, param2) = convert(mode, joint, target, second, units, scale)?;
    Ok(SingleFingerCommand {
        mode: mode.to_u8(),
        joint: joint.id(),
        param1,
        param2,
    })
}

/// Maps a normalised position 0.0..=1.0 to the percent scale 0..=1000
/// (clamped; NaN gives 0).
pub fn normalised_to_percent(x: f32) -> u16 {
    if x.is_nan() {
        return 0;
    }
    (x.clamp(0.0, 1.0) * f32::from(PERCENT_FULL)).round() as u16
}

/// Maps a percent-scale value 0..=1000 to 0.0..=1.0 (values above 1000 are
/// clamped).
pub fn percent_to_normalised(p: u16) -> f32 {
    f32::from(p.min(PERCENT_FULL)) / f32::from(PERCENT_FULL)
}

/// Converts a percent-mode current (-1000..=1000 of 1000 mA) to mA
/// (section 5.3 defines this one: 1 unit = 1 mA).
pub fn current_percent_to_ma(p: i16) -> f32 {
    f32::from(p) * MAX_CURRENT_MA / f32::from(PERCENT_FULL)
}

/// Converts mA to a percent-mode current, clamped to -1000..=1000 (NaN
/// gives 0).
pub fn current_ma_to_percent(ma: f32) -> i16 {
    if ma.is_nan() {
        return 0;
    }
    let pct = f32::from(PERCENT_FULL);
    (ma * pct / MAX_CURRENT_MA).clamp(-pct, pct).round() as i16
}

/// Angular range of a joint, needed to convert a percent-mode position to
/// degrees. The document gives none; the defaults
/// ([`DEFAULT_JOINT_RANGES`]) are assumptions to be measured on the
/// hardware. Percent 0 is taken as `min_deg` (finger open/straight) and
/// 1000 as `max_deg` (bent; section 5: positive is the bending direction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointRange {
    /// Angle at percent 0, degrees.
    pub min_deg: f32,
    /// Angle at percent 1000, degrees.
    pub max_deg: f32,
}

/// Assumed joint ranges in [`Joint`] order: thumb flex 0..90°, thumb
/// abduct 0..90°, fingers 0..90° (not from the document).
pub const DEFAULT_JOINT_RANGES: [JointRange; JOINTS] = [JointRange {
    min_deg: 0.0,
    max_deg: 90.0,
}; JOINTS];

impl JointRange {
    /// The assumed range of `joint` ([`DEFAULT_JOINT_RANGES`]).
    pub const fn default_for(joint: Joint) -> JointRange {
        DEFAULT_JOINT_RANGES[joint.index()]
    }

    /// Degrees of a percent-mode position (clamped to 0..=1000).
    pub fn percent_to_degrees(&self, p: u16) -> f32 {
        self.min_deg + (self.max_deg - self.min_deg) * percent_to_normalised(p)
    }

    /// Percent-mode position of an angle, clamped to 0..=1000 (an empty or
    /// invalid range gives 0).
    pub fn degrees_to_percent(&self, deg: f32) -> u16 {
        let span = self.max_deg - self.min_deg;
        if span == 0.0 || !span.is_finite() {
            return 0;
        }
        normalised_to_percent((deg - self.min_deg) / span)
    }
}
