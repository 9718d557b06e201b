//! Operator calibration profile: raw glove values at the extreme poses, and the operator's
//! thumb as the pinch step fitted it.

use serde::{Deserialize, Serialize};
use teleop_kinematics::{
    fit_pinches, OperatorHand, PinchFit, PinchSample, ThumbParams, GLOVE_CHANNEL_OF_FINGER,
};

use crate::error::{ConfigError, CALIBRATION_ORIGIN, POSES_ORIGIN};
use crate::GLOVE_CHANNELS;

/// Largest raw value the glove is specified to report.
pub const GLOVE_RAW_MAX: u16 = 1000;

/// Smallest accepted distance (raw units) between the two calibration values
/// of one channel (open/closed, inner/outer).
pub const MIN_CALIBRATION_SPAN: u16 = 50;

/// Names of the glove channels, glove order (also the TOML section names of a
/// calibration profile).
pub const GLOVE_CHANNEL_NAMES: [&str; GLOVE_CHANNELS] = teleop_hand_profile::GLOVE_CHANNELS;

/// Index of the thumb rotation channel in the glove order.
const THUMB_ROTATION: usize = 5;

/// Calibration of one finger's flexion channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FingerCalibration {
    /// Raw value with the hand fully open.
    pub open: u16,
    /// Raw value with the hand in a fist.
    pub closed: u16,
}

/// Calibration of the thumb rotation channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RotationCalibration {
    /// Raw value with the thumb rotated in toward the palm.
    pub inner: u16,
    /// Raw value with the thumb rotated out, away from the palm.
    pub outer: u16,
}

/// Operator calibration profile (TOML). Glove order for fingers: little, ring,
/// middle, index, thumb.
///
/// In TOML each finger is a table named after it (`[little]`, `[ring]`,
/// `[middle]`, `[index]`, `[thumb]`) with `open` and `closed`, and the thumb
/// rotation is `[thumb_rotation]` with `inner` and `outer`. All six tables
/// are required; an `[operator]` table (the fitted thumb, see
/// [`operator`](Self::operator)) is optional, with all its keys. Unknown keys
/// are rejected. Serde (de)serialisation uses that same shape; note that plain
/// serde deserialisation does not [`validate`](Self::validate) (use
/// [`from_toml_str`](Self::from_toml_str)).
///
/// Either direction is accepted for each channel (`open` may be above or
/// below `closed`), as long as the two values are at least
/// [`MIN_CALIBRATION_SPAN`] apart.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "CalibrationToml", into = "CalibrationToml")]
pub struct Calibration {
    /// Flexion channels in glove order: little, ring, middle, index, thumb.
    pub fingers: [FingerCalibration; 5],
    /// Thumb rotation channel.
    pub thumb_rotation: RotationCalibration,
    /// The operator's thumb as `teleop calibrate`'s pinch step fitted it
    /// ([`with_pinches`](Self::with_pinches)), relative to the default
    /// [`OperatorHand`]; `None`: the default hand ([`operator_hand`](Self::operator_hand)).
    pub operator: Option<ThumbParams>,
}

/// Human-friendly TOML mirror of [`Calibration`].
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CalibrationToml {
    little: FingerCalibration,
    ring: FingerCalibration,
    middle: FingerCalibration,
    index: FingerCalibration,
    thumb: FingerCalibration,
    thumb_rotation: RotationCalibration,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    operator: Option<OperatorToml>,
}

/// The `[operator]` table: [`ThumbParams`] under names that carry their units.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct OperatorToml {
    thumb_base_mm: [f32; 3],
    thumb_direction_deg: f32,
    opposition_deg: f32,
    thumb_flexion_scale: f32,
    thumb_length_scale: f32,
}

impl From<OperatorToml> for ThumbParams {
    fn from(t: OperatorToml) -> Self {
        ThumbParams {
            base_mm: t.thumb_base_mm,
            direction_deg: t.thumb_direction_deg,
            opposition_deg: t.opposition_deg,
            flexion_scale: t.thumb_flexion_scale,
            length_scale: t.thumb_length_scale,
        }
    }
}

impl From<ThumbParams> for OperatorToml {
    fn from(p: ThumbParams) -> Self {
        OperatorToml {
            thumb_base_mm: p.base_mm,
            thumb_direction_deg: p.direction_deg,
            opposition_deg: p.opposition_deg,
            thumb_flexion_scale: p.flexion_scale,
            thumb_length_scale: p.length_scale,
        }
    }
}

impl From<CalibrationToml> for Calibration {
    fn from(t: CalibrationToml) -> Self {
        Calibration {
            fingers: [t.little, t.ring, t.middle, t.index, t.thumb],
            thumb_rotation: t.thumb_rotation,
            operator: t.operator.map(ThumbParams::from),
        }
    }
}

impl From<Calibration> for CalibrationToml {
    fn from(c: Calibration) -> Self {
        let [little, ring, middle, index, thumb] = c.fingers;
        CalibrationToml {
            little,
            ring,
            middle,
            index,
            thumb,
            thumb_rotation: c.thumb_rotation,
            operator: c.operator.map(OperatorToml::from),
        }
    }
}

impl Default for FingerCalibration {
    fn default() -> Self {
        FingerCalibration {
            open: GLOVE_RAW_MAX,
            closed: 0,
        }
    }
}

impl Default for RotationCalibration {
    fn default() -> Self {
        RotationCalibration {
            inner: 0,
            outer: GLOVE_RAW_MAX,
        }
    }
}

impl Default for Calibration {
    /// The glove's nominal range: open 1000, closed 0, inner 0, outer 1000;
    /// the default operator hand.
    fn default() -> Self {
        Calibration {
            fingers: [FingerCalibration::default(); 5],
            thumb_rotation: RotationCalibration::default(),
            operator: None,
        }
    }
}

/// `(from - raw) / (from - to)` clamped to `[0, 1]`; 0 for a degenerate span.
fn fraction(raw: u16, from: u16, to: u16) -> f32 {
    let span = i32::from(from) - i32::from(to);
    if span == 0 {
        return 0.0;
    }
    let v = (i32::from(from) - i32::from(raw)) as f32 / span as f32;
    v.clamp(0.0, 1.0)
}

fn check_pair(
    origin: &str,
    section: &str,
    (a_name, a): (&str, u16),
    (b_name, b): (&str, u16),
) -> Result<(), ConfigError> {
    let field = format!("[{section}]");
    for (name, v) in [(a_name, a), (b_name, b)] {
        if v > GLOVE_RAW_MAX {
            return Err(ConfigError::invalid(
                origin,
                field,
                format!("{name} ({v}) is above the glove's maximum {GLOVE_RAW_MAX}"),
            ));
        }
    }
    let span = a.abs_diff(b);
    if span < MIN_CALIBRATION_SPAN {
        let reason = if span == 0 {
            format!(
                "{a_name} and {b_name} are both {a}; need at least {MIN_CALIBRATION_SPAN} apart"
            )
        } else {
            format!(
                "{a_name} ({a}) and {b_name} ({b}) are only {span} apart; need at least {MIN_CALIBRATION_SPAN}"
            )
        };
        return Err(ConfigError::invalid(origin, field, reason));
    }
    Ok(())
}

impl Calibration {
    /// Parses and validates a TOML profile. `origin` (normally the file path)
    /// prefixes every error message.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cal: Calibration = toml::from_str(text).map_err(|e| ConfigError::parse(origin, &e))?;
        cal.validate().map_err(|e| e.with_origin(origin))?;
        Ok(cal)
    }

    /// The profile as TOML, in the form [`from_toml_str`](Self::from_toml_str) reads.
    pub fn to_toml_string(&self) -> String {
        let mut out = String::new();
        for (name, f) in GLOVE_CHANNEL_NAMES.iter().zip(&self.fingers) {
            out.push_str(&format!(
                "[{name}]\nopen = {}\nclosed = {}\n\n",
                f.open, f.closed
            ));
        }
        out.push_str(&format!(
            "[{}]\ninner = {}\nouter = {}\n",
            GLOVE_CHANNEL_NAMES[THUMB_ROTATION],
            self.thumb_rotation.inner,
            self.thumb_rotation.outer
        ));
        if let Some(p) = &self.operator {
            // f32's Display is the shortest text that reads back as the same value.
            let [x, y, z] = p.base_mm;
            out.push_str(&format!(
                "\n[operator]\nthumb_base_mm = [{x}, {y}, {z}]\nthumb_direction_deg = {}\n\
                 opposition_deg = {}\nthumb_flexion_scale = {}\nthumb_length_scale = {}\n",
                p.direction_deg, p.opposition_deg, p.flexion_scale, p.length_scale
            ));
        }
        out
    }

    /// Checks every value is at most [`GLOVE_RAW_MAX`], each channel's two
    /// values are at least [`MIN_CALIBRATION_SPAN`] apart and the operator's
    /// thumb is within the human range ([`ThumbParams::check`]). The error
    /// names the finger (e.g. `[ring]`) and field, or `[operator]` and the
    /// parameter; its origin is `"calibration"`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if let Some(p) = &self.operator {
            p.check().map_err(|e| {
                ConfigError::invalid(CALIBRATION_ORIGIN, "[operator]", e.to_string())
            })?;
        }
        for (name, f) in GLOVE_CHANNEL_NAMES.iter().zip(&self.fingers) {
            check_pair(
                CALIBRATION_ORIGIN,
                name,
                ("open", f.open),
                ("closed", f.closed),
            )?;
        }
        check_pair(
            CALIBRATION_ORIGIN,
            GLOVE_CHANNEL_NAMES[THUMB_ROTATION],
            ("inner", self.thumb_rotation.inner),
            ("outer", self.thumb_rotation.outer),
        )
    }

    /// From the four captured poses (raw glove vectors, glove order): open
    /// hand, fist, thumb in, thumb out.
    ///
    /// All five flexion channels (thumb flexion included) come from `open` and
    /// `fist`; the rotation comes from index 5 of `thumb_in` and `thumb_out`.
    /// Raw values above [`GLOVE_RAW_MAX`] (devices overshoot slightly) are
    /// clamped to it. The result is validated; errors have the origin
    /// `"calibration poses"`.
    pub fn from_poses(
        open: [u16; GLOVE_CHANNELS],
        fist: [u16; GLOVE_CHANNELS],
        thumb_in: [u16; GLOVE_CHANNELS],
        thumb_out: [u16; GLOVE_CHANNELS],
    ) -> Result<Self, ConfigError> {
        let c = |v: u16| v.min(GLOVE_RAW_MAX);
        let fingers = std::array::from_fn(|i| FingerCalibration {
            open: c(open[i]),
            closed: c(fist[i]),
        });
        let cal = Calibration {
            fingers,
            thumb_rotation: RotationCalibration {
                inner: c(thumb_in[THUMB_ROTATION]),
                outer: c(thumb_out[THUMB_ROTATION]),
            },
            operator: None,
        };
        cal.validate().map_err(|e| e.with_origin(POSES_ORIGIN))?;
        Ok(cal)
    }

    /// The closure of each glove channel (glove order, any raw `u16`):
    /// flexion `(open - raw) / (open - closed)` for the fingers and
    /// `(outer - raw) / (outer - inner)` for the thumb rotation, each clamped
    /// to `[0, 1]` (0 = open / thumb out, 1 = closed / thumb in).
    pub fn closure(&self, raw: &[u16; GLOVE_CHANNELS]) -> [f32; GLOVE_CHANNELS] {
        std::array::from_fn(|ch| {
            if ch == THUMB_ROTATION {
                let r = self.thumb_rotation;
                fraction(raw[ch], r.outer, r.inner)
            } else {
                let f = self.fingers[ch];
                fraction(raw[ch], f.open, f.closed)
            }
        })
    }

    /// The glove's calibrated positions (glove order, any raw `u16`) in the
    /// operator model's sense ([`teleop_kinematics::OperatorPose::from_glove`]):
    /// `1 - closure`, so 0 = bent / thumb in and 1 = open / thumb out.
    pub fn position(&self, raw: &[u16; GLOVE_CHANNELS]) -> [f32; GLOVE_CHANNELS] {
        Self::position_of(&self.closure(raw))
    }

    /// The operator model's positions of closures (as [`closure`](Self::closure) gives them):
    /// `1 - closure`.
    pub fn position_of(closure: &[f32; GLOVE_CHANNELS]) -> [f32; GLOVE_CHANNELS] {
        closure.map(|c| 1.0 - c)
    }

    /// The operator's hand: the default [`OperatorHand`] with the fitted
    /// [`operator`](Self::operator) thumb applied, or the default hand without
    /// one (or with one out of the human range, which only a profile built
    /// without [`validate`](Self::validate) can hold).
    pub fn operator_hand(&self) -> OperatorHand {
        let default = OperatorHand::default();
        match self.operator {
            Some(p) if p.check().is_ok() => p.apply(&default),
            _ => default,
        }
    }

    /// This profile with the operator's thumb fitted to pinches recorded with
    /// it ([`teleop_kinematics::fit_pinches`], from the default hand), and the
    /// fit's report (per pinch, in the order given: the thumb-finger pad gap
    /// before and after, millimetres).
    ///
    /// Each pinch is the glove channel of the finger the thumb pinches
    /// ([`GLOVE_CHANNEL_NAMES`] index: 0 little, 1 ring, 2 middle, 3 index) and
    /// the raw glove vector recorded while pinching. Errors (origin
    /// `"calibration poses"`, field `[operator]`): no pinch, or a channel that
    /// is not a long finger's.
    pub fn with_pinches(
        &self,
        pinches: &[(usize, [u16; GLOVE_CHANNELS])],
    ) -> Result<(Self, PinchFit), ConfigError> {
        let invalid = |reason: String| ConfigError::invalid(POSES_ORIGIN, "[operator]", reason);
        let samples = pinches
            .iter()
            .enumerate()
            .map(|(i, (channel, raw))| {
                // The thumb (index 0) pinches; the long fingers are the rest.
                match GLOVE_CHANNEL_OF_FINGER.iter().skip(1).position(|c| c == channel) {
                    Some(k) => Ok(PinchSample {
                        finger: k + 1,
                        glove: self.position(raw),
                    }),
                    None => Err(invalid(format!(
                        "pinch {i}: glove channel {channel} is not a long finger's (0 little .. 3 index)"
                    ))),
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let fit =
            fit_pinches(&OperatorHand::default(), &samples).map_err(|e| invalid(e.to_string()))?;
        let fitted = Calibration {
            operator: Some(fit.params),
            ..*self
        };
        Ok((fitted, fit))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const SAMPLE: &str = r#"
[little]
open = 980
closed = 40

[ring]
open = 970
closed = 60

[middle]
open = 990
closed = 20

[index]
open = 960
closed = 30

[thumb]
open = 900
closed = 200

[thumb_rotation]
inner = 30
outer = 970
"#;

    #[test]
    fn default_maps_open_to_zero_and_fist_to_one() {
        let cal = Calibration::default();
        cal.validate().unwrap();
        assert_eq!(cal.closure(&[1000; 6])[..5], [0.0; 5]);
        assert_eq!(cal.closure(&[0; 6])[..5], [1.0; 5]);
        // thumb rotation: 1000 = outermost = closure 0 (thumb out)
        assert_eq!(cal.closure(&[1000; 6])[5], 0.0);
        assert_eq!(cal.closure(&[0; 6])[5], 1.0);
    }

    #[test]
    fn out_of_range_raw_is_clamped() {
        let cal = Calibration::default();
        assert_eq!(cal.closure(&[u16::MAX; 6]), [0.0; 6]);
        assert_eq!(cal.closure(&[1001; 6]), [0.0; 6]);
    }

    #[test]
    fn channel_order_and_rotation_sign() {
        let cal = Calibration::default();
        // glove order: little, ring, middle, index, thumb, thumb_rotation
        let raw = [900, 800, 700, 600, 500, 100];
        let n = cal.closure(&raw);
        let expect = [0.1, 0.2, 0.3, 0.4, 0.5, 0.9];
        for (a, b) in n.iter().zip(expect) {
            assert!((a - b).abs() < 1e-6, "{n:?} vs {expect:?}");
        }
    }

    #[test]
    fn toml_round_trip() {
        let cal = Calibration::from_toml_str(SAMPLE, "cal.toml").unwrap();
        assert_eq!(
            cal.fingers[0],
            FingerCalibration {
                open: 980,
                closed: 40
            }
        );
        assert_eq!(
            cal.fingers[4],
            FingerCalibration {
                open: 900,
                closed: 200
            }
        );
        assert_eq!(
            cal.thumb_rotation,
            RotationCalibration {
                inner: 30,
                outer: 970
            }
        );
        let text = cal.to_toml_string();
        assert_eq!(Calibration::from_toml_str(&text, "x").unwrap(), cal);
        // serde form matches the hand-written form
        let via_serde = toml::to_string(&cal).unwrap();
        assert_eq!(Calibration::from_toml_str(&via_serde, "x").unwrap(), cal);
        let d = Calibration::default();
        assert_eq!(
            Calibration::from_toml_str(&d.to_toml_string(), "x").unwrap(),
            d
        );
    }

    #[test]
    fn partial_profile_names_missing_finger() {
        let text = SAMPLE.replace("[ring]\nopen = 970\nclosed = 60\n", "");
        let err = Calibration::from_toml_str(&text, "cal.toml").unwrap_err();
        let msg = err.to_string();
        assert!(msg.starts_with("cal.toml: "), "{msg}");
        assert!(msg.contains("missing field `ring`"), "{msg}");
    }

    #[test]
    fn missing_field_in_finger_is_named() {
        let text = SAMPLE.replace("closed = 60\n", "");
        let msg = Calibration::from_toml_str(&text, "cal.toml")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("missing field `closed`"), "{msg}");
    }

    #[test]
    fn unknown_keys_are_errors() {
        let text = format!("{SAMPLE}\n[pinky]\nopen = 1\nclosed = 2\n");
        let msg = Calibration::from_toml_str(&text, "cal.toml")
            .unwrap_err()
            .to_string();
        assert!(msg.starts_with("cal.toml: "), "{msg}");
        assert!(msg.contains("unknown field `pinky`"), "{msg}");

        let text = SAMPLE.replace("closed = 60\n", "closed = 60\nmiddle = 3\n");
        let msg = Calibration::from_toml_str(&text, "cal.toml")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("unknown field `middle`"), "{msg}");
    }

    #[test]
    fn syntax_error_keeps_line_and_column() {
        let text = SAMPLE.replace("closed = 60", "closed = = 60");
        let msg = Calibration::from_toml_str(&text, "cal.toml")
            .unwrap_err()
            .to_string();
        assert!(msg.starts_with("cal.toml: "), "{msg}");
        assert!(msg.contains("line 8"), "{msg}");
        assert!(msg.contains("column"), "{msg}");
    }

    #[test]
    fn validation_messages_name_origin_and_finger() {
        let text = SAMPLE.replace("open = 970\nclosed = 60", "open = 500\nclosed = 480");
        let err = Calibration::from_toml_str(&text, "calibration.toml").unwrap_err();
        assert_eq!(
            err.to_string(),
            "calibration.toml: [ring]: open (500) and closed (480) are only 20 apart; need at least 50"
        );
        assert_eq!(err.origin(), "calibration.toml");

        let text = SAMPLE.replace("inner = 30", "inner = 1200");
        let msg = Calibration::from_toml_str(&text, "c.toml")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("c.toml: [thumb_rotation]: inner (1200)"),
            "{msg}"
        );

        let text = SAMPLE.replace("inner = 30", "inner = 970");
        let msg = Calibration::from_toml_str(&text, "c.toml")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("c.toml: [thumb_rotation]: inner and outer"),
            "{msg}"
        );

        let text = SAMPLE.replace("inner = 30", "inner = -3");
        let msg = Calibration::from_toml_str(&text, "c.toml")
            .unwrap_err()
            .to_string();
        assert!(msg.starts_with("c.toml: "), "{msg}");
    }

    #[test]
    fn inverted_channels_are_accepted_and_invert() {
        let mut cal = Calibration::default();
        cal.fingers[3] = FingerCalibration {
            open: 100,
            closed: 900,
        };
        cal.validate().unwrap();
        let n = cal.closure(&[0, 0, 0, 900, 0, 0]);
        assert_eq!(n[3], 1.0);
    }

    const OPERATOR: &str = r#"
[operator]
thumb_base_mm = [-22.5, 31, -9.75]
thumb_direction_deg = 40
opposition_deg = 88.5
thumb_flexion_scale = 1.1
thumb_length_scale = 0.95
"#;

    #[test]
    fn a_profile_without_operator_is_the_default_hand() {
        let cal = Calibration::from_toml_str(SAMPLE, "cal.toml").unwrap();
        assert_eq!(cal.operator, None);
        assert_eq!(
            cal.operator_hand(),
            teleop_kinematics::OperatorHand::default()
        );
        assert!(!cal.to_toml_string().contains("[operator]"));
        assert!(!toml::to_string(&cal).unwrap().contains("operator"));
    }

    #[test]
    fn operator_table_round_trips_and_applies_to_the_default_hand() {
        let text = format!("{SAMPLE}{OPERATOR}");
        let cal = Calibration::from_toml_str(&text, "cal.toml").unwrap();
        let p = cal.operator.unwrap();
        assert_eq!(p.base_mm, [-22.5, 31.0, -9.75]);
        assert_eq!(p.direction_deg, 40.0);
        assert_eq!(p.opposition_deg, 88.5);
        assert_eq!(p.flexion_scale, 1.1);
        assert_eq!(p.length_scale, 0.95);
        assert_eq!(
            Calibration::from_toml_str(&cal.to_toml_string(), "x").unwrap(),
            cal
        );
        let via_serde = toml::to_string(&cal).unwrap();
        assert_eq!(Calibration::from_toml_str(&via_serde, "x").unwrap(), cal);

        let hand = cal.operator_hand();
        let default = teleop_kinematics::OperatorHand::default();
        assert_eq!(hand, p.apply(&default));
        assert!((hand.thumb.base - glam::Vec3::new(-0.0225, 0.031, -0.00975)).length() < 1e-7);
        assert!((hand.opposition_rad - 88.5f32.to_radians()).abs() < 1e-6);
        assert!((hand.thumb.lengths[0] - default.thumb.lengths[0] * 0.95).abs() < 1e-7);
        assert_eq!(hand.fingers, default.fingers);
    }

    #[test]
    fn operator_table_is_validated() {
        let text = format!("{SAMPLE}{OPERATOR}").replace("-9.75", "25");
        let err = Calibration::from_toml_str(&text, "cal.toml").unwrap_err();
        assert_eq!(
            err.to_string(),
            "cal.toml: [operator]: thumb base z (25.00 mm) is outside the human range -35..10 mm"
        );
        let text = format!("{SAMPLE}{OPERATOR}").replace("= 1.1", "= nan");
        let msg = Calibration::from_toml_str(&text, "cal.toml")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("cal.toml: [operator]: thumb flexion scale (NaN)"),
            "{msg}"
        );
        let text = format!("{SAMPLE}{OPERATOR}").replace("thumb_length_scale = 0.95\n", "");
        let msg = Calibration::from_toml_str(&text, "cal.toml")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("missing field `thumb_length_scale`"), "{msg}");
        let text = format!("{SAMPLE}{OPERATOR}index_length_scale = 1\n");
        let msg = Calibration::from_toml_str(&text, "cal.toml")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("unknown field `index_length_scale`"), "{msg}");
        // An unvalidated profile out of range still gives a hand: the default.
        let mut cal = Calibration::from_toml_str(SAMPLE, "x").unwrap();
        let mut p = teleop_kinematics::ThumbParams::of(&teleop_kinematics::OperatorHand::default());
        p.opposition_deg = f32::NAN;
        cal.operator = Some(p);
        assert_eq!(
            cal.operator_hand(),
            teleop_kinematics::OperatorHand::default()
        );
    }

    #[test]
    fn position_is_one_minus_closure() {
        let cal = Calibration::from_toml_str(SAMPLE, "x").unwrap();
        let raw = [980, 60, 505, 30, 900, 30];
        assert_eq!(cal.position(&raw), [1.0, 0.0, 0.5, 0.0, 1.0, 0.0]);
    }

    /// Raw glove values that put `cal`'s calibrated positions at `position`.
    fn raw_at(cal: &Calibration, position: [f32; GLOVE_CHANNELS]) -> [u16; GLOVE_CHANNELS] {
        std::array::from_fn(|ch| {
            let (open, closed) = if ch == THUMB_ROTATION {
                (cal.thumb_rotation.outer, cal.thumb_rotation.inner)
            } else {
                (cal.fingers[ch].open, cal.fingers[ch].closed)
            };
            let (open, closed) = (f32::from(open), f32::from(closed));
            (closed + position[ch] * (open - closed)).round() as u16
        })
    }

    #[test]
    fn pinches_fit_the_operator_thumb() {
        let cal = Calibration::from_toml_str(SAMPLE, "x").unwrap();
        // The default hand pinches thumb and index at thumb flexion 0.275, opposition 0.625 and
        // index flexion 0.675 (glove: 1 - each); this operator's glove reads the thumb a
        // little more open and rotated out.
        let pinch = raw_at(&cal, [1.0, 1.0, 1.0, 0.325, 0.78, 0.45]);
        let (fitted, fit) = cal.with_pinches(&[(3, pinch)]).unwrap();
        assert_eq!(fit.gaps.len(), 1);
        assert_eq!(fit.gaps[0].finger, 1);
        assert!(fit.gaps[0].before_mm > 2.0, "{:?}", fit.gaps);
        assert!(fit.gaps[0].after_mm.abs() < 0.1, "{:?}", fit.gaps);
        assert_eq!(fitted.fingers, cal.fingers);
        assert_eq!(fitted.operator, Some(fit.params));
        fitted.validate().unwrap();
        // The written profile gives the fitted hand back, and it closes the pinch.
        let back = Calibration::from_toml_str(&fitted.to_toml_string(), "x").unwrap();
        assert_eq!(back, fitted);
        let pose = teleop_kinematics::OperatorPose::from_glove(&back.position(&pinch));
        assert!(back.operator_hand().pad_gap(&pose, 0, 1).abs() < 1e-4);

        let err = cal.with_pinches(&[(4, pinch)]).unwrap_err().to_string();
        assert_eq!(
            err,
            "calibration poses: [operator]: pinch 0: glove channel 4 is not a long finger's (0 little .. 3 index)"
        );
        let err = cal.with_pinches(&[]).unwrap_err().to_string();
        assert_eq!(
            err,
            "calibration poses: [operator]: no pinch samples to fit"
        );
    }

    #[test]
    fn from_poses_builds_and_validates() {
        let open = [980, 970, 990, 960, 900, 500];
        let fist = [40, 60, 20, 30, 200, 520];
        let thumb_in = [500, 500, 500, 500, 500, 30];
        let thumb_out = [500, 500, 500, 500, 500, 1004];
        let cal = Calibration::from_poses(open, fist, thumb_in, thumb_out).unwrap();
        assert_eq!(
            cal.fingers[1],
            FingerCalibration {
                open: 970,
                closed: 60
            }
        );
        assert_eq!(
            cal.fingers[4],
            FingerCalibration {
                open: 900,
                closed: 200
            }
        );
        assert_eq!(
            cal.thumb_rotation,
            RotationCalibration {
                inner: 30,
                outer: 1000
            }
        );

        let mut bad_fist = fist;
        bad_fist[2] = 970;
        let err = Calibration::from_poses(open, bad_fist, thumb_in, thumb_out).unwrap_err();
        assert_eq!(
            err.to_string(),
            "calibration poses: [middle]: open (990) and closed (970) are only 20 apart; need at least 50"
        );
        let err = Calibration::from_poses(open, fist, thumb_in, thumb_in).unwrap_err();
        assert!(err.to_string().contains("[thumb_rotation]"), "{err}");
    }
}
