//! The profile file as written (with the source position of every value worth naming in an
//! error), and its checking into a [`HandProfile`].

use serde::Deserialize;
use toml::Spanned;

use crate::{
    CommandUnits, Coupling, DeviceMap, FeedbackSource, Finger, GloveMap, HandProfile, Joint, Link,
    ProfileError, RetargetDefaults, RetargetMode, Role, TipSensor, GLOVE_CHANNELS, GLOVE_FINGERS,
    MAX_FINGERTIPS, MAX_JOINTS,
};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProfile {
    hand: RawHand,
    #[serde(default)]
    joint: Vec<Spanned<RawJoint>>,
    #[serde(default)]
    finger: Vec<Spanned<RawFinger>>,
    #[serde(default)]
    feedback: Vec<Spanned<RawFeedback>>,
    retarget: Option<Spanned<RawRetarget>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRetarget {
    #[serde(default = "joint_mode")]
    mode: RetargetMode,
    #[serde(default = "one")]
    scaling: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHand {
    name: Spanned<String>,
    model: String,
    model_id: u8,
    command_units: CommandUnits,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawJoint {
    name: Spanned<String>,
    finger: Spanned<String>,
    role: Role,
    limits: Spanned<[f32; 2]>,
    open: Option<Spanned<f32>>,
    closed: Option<Spanned<f32>>,
    device: Spanned<RawDevice>,
    glove: Option<Spanned<RawGlove>>,
    coupled: Option<Spanned<RawCoupling>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDevice {
    unit: String,
    scale: f32,
    #[serde(default)]
    offset: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGlove {
    #[serde(default)]
    channels: Vec<String>,
    #[serde(default)]
    gains: Vec<f32>,
    #[serde(default)]
    offset: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCoupling {
    to: String,
    #[serde(default = "one")]
    ratio: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFinger {
    name: Spanned<String>,
    #[serde(default = "no_sensor")]
    tip_sensor: TipSensor,
    base: [f32; 3],
    #[serde(default)]
    base_rpy: [f32; 3],
    #[serde(default)]
    link: Vec<Spanned<RawLink>>,
    tip: [f32; 3],
    pad: Option<[f32; 3]>,
    #[serde(default)]
    pad_radius: f32,
    operator: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLink {
    joint: Option<String>,
    #[serde(default = "one")]
    ratio: f32,
    axis: [f32; 3],
    #[serde(default)]
    origin: [f32; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFeedback {
    glove_finger: Spanned<String>,
    tactile: Option<Spanned<String>>,
    joints: Option<Spanned<Vec<String>>>,
}

fn one() -> f32 {
    1.0
}

fn joint_mode() -> RetargetMode {
    RetargetMode::Joint
}

fn no_sensor() -> TipSensor {
    TipSensor::None
}

/// Builds errors with the line of a source position.
struct Checker<'a> {
    text: &'a str,
    origin: &'a str,
}

impl Checker<'_> {
    fn err<T>(
        &self,
        span: core::ops::Range<usize>,
        field: impl Into<String>,
        reason: impl Into<String>,
    ) -> Result<T, ProfileError> {
        let end = span.start.min(self.text.len());
        Err(ProfileError::Invalid {
            origin: self.origin.to_string(),
            line: self.text[..end].matches('\n').count() + 1,
            field: field.into(),
            reason: reason.into(),
        })
    }

    fn finite(
        &self,
        span: &core::ops::Range<usize>,
        field: &str,
        values: &[f32],
    ) -> Result<(), ProfileError> {
        if let Some(v) = values.iter().find(|v| !v.is_finite()) {
            return self.err(span.clone(), field, format!("{v} is not a finite number"));
        }
        Ok(())
    }
}

pub(crate) fn parse(text: &str, origin: &str) -> Result<HandProfile, ProfileError> {
    let raw: RawProfile = toml::from_str(text).map_err(|e| ProfileError::Parse {
        origin: origin.to_string(),
        message: e.to_string().trim_end().to_string(),
    })?;
    let c = Checker { text, origin };

    if raw.hand.name.get_ref().trim().is_empty() {
        return c.err(raw.hand.name.span(), "hand.name", "must not be empty");
    }
    let fingers = fingers_of(&c, &raw.finger)?;
    let joints = joints_of(&c, &raw.joint, &fingers)?;
    let fingers = link_fingers(&c, &raw.finger, fingers, &joints)?;
    let feedback = feedback_of(&c, &raw.feedback, &fingers, &joints)?;
    let retarget = retarget_of(&c, raw.retarget.as_ref())?;
    Ok(HandProfile {
        name: raw.hand.name.into_inner(),
        model: raw.hand.model,
        model_id: raw.hand.model_id,
        command_units: raw.hand.command_units,
        joints,
        fingers,
        feedback,
        retarget,
    })
}

fn retarget_of(
    c: &Checker,
    raw: Option<&Spanned<RawRetarget>>,
) -> Result<RetargetDefaults, ProfileError> {
    let Some(raw) = raw else {
        return Ok(RetargetDefaults {
            mode: RetargetMode::Joint,
            scaling: 1.0,
        });
    };
    let r = raw.get_ref();
    if !(r.scaling.is_finite() && r.scaling > 0.0) {
        return c.err(
            raw.span(),
            "retarget.scaling",
            format!("{} must be a positive number", r.scaling),
        );
    }
    Ok(RetargetDefaults {
        mode: r.mode,
        scaling: r.scaling,
    })
}

/// Fingers without their links (joints refer to fingers, links to joints).
fn fingers_of(c: &Checker, raw: &[Spanned<RawFinger>]) -> Result<Vec<Finger>, ProfileError> {
    if raw.is_empty() {
        return c.err(0..0, "finger", "a profile needs at least one [[finger]]");
    }
    let mut fingers: Vec<Finger> = Vec::with_capacity(raw.len());
    for (i, f) in raw.iter().enumerate() {
        let span = f.span();
        let f = f.get_ref();
        let name = f.name.get_ref();
        let field = format!("finger[{i}]");
        if name.trim().is_empty() {
            return c.err(f.name.span(), format!("{field}.name"), "must not be empty");
        }
        if fingers.iter().any(|g| &g.name == name) {
            return c.err(
                f.name.span(),
                format!("{field}.name"),
                format!("`{name}` is already the name of another finger"),
            );
        }
        c.finite(&span, &field, &f.base)?;
        c.finite(&span, &field, &f.base_rpy)?;
        c.finite(&span, &field, &f.tip)?;
        let pad = f.pad.unwrap_or(f.tip);
        c.finite(&span, &format!("{field}.pad"), &pad)?;
        if !(f.pad_radius.is_finite() && (0.0..0.05).contains(&f.pad_radius)) {
            return c.err(
                span,
                format!("{field}.pad_radius"),
                format!("{} m is not a pad radius (0 to 0.05 m)", f.pad_radius),
            );
        }
        let operator = match &f.operator {
            None => None,
            Some(o) => {
                let Some(g) = GLOVE_FINGERS.iter().position(|n| n == o.get_ref()) else {
                    return c.err(
                        o.span(),
                        format!("{field}.operator"),
                        format!(
                            "`{}` is not an operator finger (fingers: {})",
                            o.get_ref(),
                            names(GLOVE_FINGERS.iter().copied())
                        ),
                    );
                };
                if fingers.iter().any(|other| other.operator == Some(g)) {
                    return c.err(
                        o.span(),
                        format!("{field}.operator"),
                        format!(
                            "another finger follows the operator's `{}` already",
                            o.get_ref()
                        ),
                    );
                }
                Some(g)
            }
        };
        fingers.push(Finger {
            name: name.clone(),
            tip_sensor: f.tip_sensor,
            base: f.base,
            base_rpy: f.base_rpy,
            links: Vec::new(),
            tip: f.tip,
            pad,
            pad_radius: f.pad_radius,
            operator,
        });
    }
    let tips = fingers
        .iter()
        .filter(|f| f.tip_sensor != TipSensor::None)
        .count();
    if tips > MAX_FINGERTIPS {
        return c.err(
            raw[0].span(),
            "finger",
            format!("{tips} fingertip sensors; the contract carries at most {MAX_FINGERTIPS}"),
        );
    }
    Ok(fingers)
}

fn joints_of(
    c: &Checker,
    raw: &[Spanned<RawJoint>],
    fingers: &[Finger],
) -> Result<Vec<Joint>, ProfileError> {
    if raw.is_empty() || raw.len() > MAX_JOINTS {
        return c.err(
            raw.first().map_or(0..0, Spanned::span),
            "joint",
            format!(
                "a profile needs 1 to {MAX_JOINTS} [[joint]] entries, this one has {}",
                raw.len()
            ),
        );
    }
    let mut joints: Vec<Joint> = Vec::with_capacity(raw.len());
    for (i, j) in raw.iter().enumerate() {
        let j = j.get_ref();
        let field = format!("joint[{i}]");
        let name = j.name.get_ref();
        if name.trim().is_empty() {
            return c.err(j.name.span(), format!("{field}.name"), "must not be empty");
        }
        if joints.iter().any(|k| &k.name == name) {
            return c.err(
                j.name.span(),
                format!("{field}.name"),
                format!("`{name}` is already the name of another joint"),
            );
        }
        let Some(finger) = fingers.iter().position(|f| &f.name == j.finger.get_ref()) else {
            return c.err(
                j.finger.span(),
                format!("{field}.finger"),
                format!(
                    "no finger is called `{}` (fingers: {})",
                    j.finger.get_ref(),
                    names(fingers.iter().map(|f| f.name.as_str()))
                ),
            );
        };
        let [lower, upper] = *j.limits.get_ref();
        c.finite(
            &j.limits.span(),
            &format!("{field}.limits"),
            &[lower, upper],
        )?;
        if lower >= upper {
            return c.err(
                j.limits.span(),
                format!("{field}.limits"),
                format!("lower ({lower}) must be below upper ({upper})"),
            );
        }
        let angle = |v: &Option<Spanned<f32>>, what: &str, default: f32| {
            let Some(v) = v else { return Ok(default) };
            let x = *v.get_ref();
            if !(lower..=upper).contains(&x) {
                return c.err(
                    v.span(),
                    format!("{field}.{what}"),
                    format!("{x} is outside the limits [{lower}, {upper}]"),
                );
            }
            Ok(x)
        };
        let open = angle(&j.open, "open", lower)?;
        let closed = angle(&j.closed, "closed", upper)?;
        if open == closed {
            return c.err(
                j.closed.as_ref().map_or(j.limits.span(), Spanned::span),
                format!("{field}.closed"),
                format!("equals open ({open}): normalised commands would have no range"),
            );
        }
        let device = j.device.get_ref();
        let dfield = format!("{field}.device");
        c.finite(&j.device.span(), &dfield, &[device.scale, device.offset])?;
        if device.scale == 0.0 {
            return c.err(j.device.span(), dfield, "scale must not be 0");
        }
        let glove = match &j.glove {
            Some(g) => glove_of(c, g, &format!("{field}.glove"))?,
            None => GloveMap {
                channels: Vec::new(),
                offset: 0.0,
            },
        };
        joints.push(Joint {
            name: name.clone(),
            finger,
            role: j.role,
            lower,
            upper,
            open,
            closed,
            device: DeviceMap {
                unit: device.unit.clone(),
                scale: device.scale,
                offset: device.offset,
            },
            glove,
            coupling: None,
        });
    }
    // Couplings refer to joints by name, in any order.
    for (i, j) in raw.iter().enumerate() {
        let Some(cp) = &j.get_ref().coupled else {
            continue;
        };
        let field = format!("joint[{i}].coupled");
        let to_name = &cp.get_ref().to;
        let ratio = cp.get_ref().ratio;
        let Some(to) = joints.iter().position(|k| &k.name == to_name) else {
            return c.err(
                cp.span(),
                format!("{field}.to"),
                format!("no joint is called `{to_name}`"),
            );
        };
        if to == i {
            return c.err(
                cp.span(),
                format!("{field}.to"),
                "a joint cannot follow itself",
            );
        }
        if raw[to].get_ref().coupled.is_some() {
            return c.err(
                cp.span(),
                format!("{field}.to"),
                format!("`{to_name}` follows another joint itself; couple to a driven joint"),
            );
        }
        c.finite(&cp.span(), &format!("{field}.ratio"), &[ratio])?;
        if let Some(g) = &j.get_ref().glove {
            return c.err(
                g.span(),
                format!("joint[{i}].glove"),
                "a coupled joint follows its joint, not the glove: remove one of the two",
            );
        }
        joints[i].coupling = Some(Coupling { to, ratio });
    }
    Ok(joints)
}

fn glove_of(c: &Checker, g: &Spanned<RawGlove>, field: &str) -> Result<GloveMap, ProfileError> {
    let raw = g.get_ref();
    let gains = if raw.gains.is_empty() {
        vec![1.0; raw.channels.len()]
    } else {
        raw.gains.clone()
    };
    if gains.len() != raw.channels.len() {
        return c.err(
            g.span(),
            format!("{field}.gains"),
            format!(
                "{} gains for {} channels: give one gain per channel (or none for 1.0 each)",
                gains.len(),
                raw.channels.len()
            ),
        );
    }
    c.finite(&g.span(), &format!("{field}.gains"), &gains)?;
    c.finite(&g.span(), &format!("{field}.offset"), &[raw.offset])?;
    let mut channels = Vec::with_capacity(gains.len());
    for (name, gain) in raw.channels.iter().zip(gains) {
        let Some(ch) = GLOVE_CHANNELS.iter().position(|c| c == name) else {
            return c.err(
                g.span(),
                format!("{field}.channels"),
                format!(
                    "`{name}` is not a glove channel (channels: {})",
                    names(GLOVE_CHANNELS.iter().copied())
                ),
            );
        };
        channels.push((ch, gain));
    }
    Ok(GloveMap {
        channels,
        offset: raw.offset,
    })
}

fn link_fingers(
    c: &Checker,
    raw: &[Spanned<RawFinger>],
    mut fingers: Vec<Finger>,
    joints: &[Joint],
) -> Result<Vec<Finger>, ProfileError> {
    for (i, (f, finger)) in raw.iter().zip(&mut fingers).enumerate() {
        for (k, l) in f.get_ref().link.iter().enumerate() {
            let field = format!("finger[{i}].link[{k}]");
            let raw_link = l.get_ref();
            let joint = match &raw_link.joint {
                Some(name) => match joints.iter().position(|j| &j.name == name) {
                    Some(j) => Some(j),
                    None => {
                        return c.err(
                            l.span(),
                            format!("{field}.joint"),
                            format!("no joint is called `{name}`"),
                        )
                    }
                },
                None => None,
            };
            c.finite(&l.span(), &field, &raw_link.axis)?;
            c.finite(&l.span(), &field, &raw_link.origin)?;
            c.finite(&l.span(), &field, &[raw_link.ratio])?;
            let [x, y, z] = raw_link.axis;
            let len = (x * x + y * y + z * z).sqrt();
            if len < 1e-6 {
                return c.err(l.span(), format!("{field}.axis"), "must not be zero");
            }
            finger.links.push(Link {
                joint,
                ratio: raw_link.ratio,
                axis: [x / len, y / len, z / len],
                origin: raw_link.origin,
            });
        }
    }
    Ok(fingers)
}

fn feedback_of(
    c: &Checker,
    raw: &[Spanned<RawFeedback>],
    fingers: &[Finger],
    joints: &[Joint],
) -> Result<[FeedbackSource; 5], ProfileError> {
    let mut out: [FeedbackSource; 5] = Default::default();
    let mut seen = [false; 5];
    let tips: Vec<&str> = fingers
        .iter()
        .filter(|f| f.tip_sensor != TipSensor::None)
        .map(|f| f.name.as_str())
        .collect();
    for (i, fb) in raw.iter().enumerate() {
        let fb = fb.get_ref();
        let field = format!("feedback[{i}]");
        let Some(g) = GLOVE_FINGERS
            .iter()
            .position(|n| n == fb.glove_finger.get_ref())
        else {
            return c.err(
                fb.glove_finger.span(),
                format!("{field}.glove_finger"),
                format!(
                    "`{}` is not a glove finger (fingers: {})",
                    fb.glove_finger.get_ref(),
                    names(GLOVE_FINGERS.iter().copied())
                ),
            );
        };
        if seen[g] {
            return c.err(
                fb.glove_finger.span(),
                format!("{field}.glove_finger"),
                format!("`{}` has a feedback source already", GLOVE_FINGERS[g]),
            );
        }
        seen[g] = true;
        if let Some(t) = &fb.tactile {
            let Some(tip) = tips.iter().position(|n| n == t.get_ref()) else {
                return c.err(
                    t.span(),
                    format!("{field}.tactile"),
                    format!(
                        "no finger with a fingertip sensor is called `{}` (with sensors: {})",
                        t.get_ref(),
                        names(tips.iter().copied())
                    ),
                );
            };
            out[g].tactile = Some(tip);
        }
        if let Some(js) = &fb.joints {
            for name in js.get_ref() {
                let Some(j) = joints.iter().position(|j| &j.name == name) else {
                    return c.err(
                        js.span(),
                        format!("{field}.joints"),
                        format!("no joint is called `{name}`"),
                    );
                };
                out[g].joints.push(j);
            }
        }
    }
    Ok(out)
}

fn names<'a>(it: impl Iterator<Item = &'a str>) -> String {
    it.collect::<Vec<_>>().join(", ")
}
