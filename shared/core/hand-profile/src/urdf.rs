//! URDF export of a hand profile ([`HandProfile::to_urdf`]), for RViz, MuJoCo, Isaac and the
//! Python retargeting tools (pinocchio, yourdfpy, dex-retargeting) to load the very hand the
//! pipeline uses. On the command line: `teleop profile urdf HAND_OR_FILE [--out FILE]`.
//!
//! # What the URDF has
//!
//! One `<robot>` named after the profile. Its root link `wrist` is the hand frame (the crate's
//! [conventions](crate#conventions)). Per finger, in the profile's finger order:
//!
//! * one URDF joint per link of the finger's chain, each with a child link
//!   `<finger>_link<k>` (`k` from 1). The first joint's origin is the finger's `base` plus
//!   its rotated first `origin`, with rpy = the finger's `base_rpy` (the same roll-pitch-yaw
//!   convention); later joints sit at their link's `origin` with rpy 0. A link without a joint
//!   becomes a `fixed` joint `<finger>_joint<k>`.
//! * fixed frames `<finger>_tip` (at the profile's `tip`) and `<finger>_pad` (at its `pad`, with
//!   a visual and a collision sphere of `pad_radius` when that is above 0), both children of the
//!   finger's last link, joined by `<finger>_tip_joint` and `<finger>_pad_joint`.
//!
//! The revolute joints are named after the profile's joints: each profile joint is exactly one
//! URDF joint of its name, with its limits, so a program that maps joints by name (the
//! retargeting benchmark) drives the same hand. That joint is the first link (in finger order)
//! that the profile joint turns with `ratio` 1. Every other link it turns becomes its own joint
//! `<joint>_<k>` (`k`: the link's place in its finger) that mimics it:
//! `<mimic joint="<joint>" multiplier="<ratio>"/>`, the limits scaled by the ratio (the Revo2's
//! linkage-driven distal phalanges, `index_2` following `index` by 0.9). A profile joint with a
//! `coupling` (the Shadow Hand's J1 following J2) mimics the joint it follows with the
//! coupling's ratio; a link it turns with another ratio mimics that joint directly with the
//! product of both (URDF readers do not chain mimics). A profile joint that no link turns with
//! ratio 1 still gets its joint, on a stub link `<joint>_driver` at the wrist that moves nothing,
//! so that every profile joint is there by name. The profile clamps a coupled joint to its own
//! limits; a mimic joint does not, so the two agree while the followed joint stays in the range
//! that keeps the coupled one within its limits (true of the shipped profiles).
//!
//! Generated names that would collide with another name get `_2`, `_3`, ... appended; the
//! profile's joint names and `wrist` are never changed. Names are XML-escaped as they are.
//! Numbers are printed as the profile wrote them where they are its own, and computed ones
//! (the first joint's position, scaled limits and multipliers) with 9 decimals (nanometres,
//! nanoradians): enough to reproduce the profile to well under 1e-6 m.
//!
//! # What the profile does not say
//!
//! Profiles carry no torques, speeds, masses or meshes; URDF readers want them, so the export
//! writes placeholders, not datasheet figures: every revolute joint `effort` [`EFFORT`] N·m and
//! `velocity` [`VELOCITY`] rad/s; every chain link a [`LINK_MASS`] kg inertial with
//! [`LINK_INERTIA`] kg·m² about each axis (MuJoCo refuses moving bodies without mass). Each
//! chain link is drawn as a cylinder from its joint to the next one (or to the tip).

use std::collections::BTreeSet;
use std::fmt::Write;

use crate::{Finger, HandProfile, Joint};

/// Effort limit of every revolute joint, N·m: a placeholder of the order of a dexterous hand's
/// finger joints (profiles carry no torque limits; URDF requires the attribute).
pub const EFFORT: f64 = 1.0;
/// Velocity limit of every revolute joint, rad/s: a placeholder, as [`EFFORT`].
pub const VELOCITY: f64 = 5.0;
/// Mass of every chain link, kg: a placeholder so that simulators accept moving links.
pub const LINK_MASS: f64 = 0.01;
/// Principal moment of inertia of every chain link about each axis, kg·m²: a placeholder.
pub const LINK_INERTIA: f64 = 1e-6;
/// Radius of the cylinders drawn along the chain links, metres (drawing only).
const SEGMENT_RADIUS: f64 = 0.005;

impl HandProfile {
    /// The profile as a URDF document (see the [`urdf`](crate::urdf) module for its frames and
    /// names).
    pub fn to_urdf(&self) -> String {
        Model::of(self).render(&self.name)
    }
}

/// A pose relative to the parent frame: translation, then fixed-axis roll, pitch, yaw.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Origin {
    xyz: [f64; 3],
    rpy: [f64; 3],
}

impl Origin {
    const ZERO: Origin = Origin {
        xyz: [0.0; 3],
        rpy: [0.0; 3],
    };
}

/// What a URDF joint does.
#[derive(Debug, Clone, PartialEq)]
enum Motion {
    Fixed,
    Revolute {
        axis: [f64; 3],
        lower: f64,
        upper: f64,
        /// `(followed joint, multiplier)`.
        mimic: Option<(String, f64)>,
    },
}

/// What a link carries besides its frame.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Body {
    /// Nothing (a frame).
    Frame,
    /// A placeholder inertial, and a cylinder from the link's origin to this point when it is
    /// not the origin itself.
    Segment([f64; 3]),
    /// A pad sphere of this radius, metres (nothing drawn when 0).
    Pad(f64),
}

/// A URDF joint with its child link: a tree from `wrist` has exactly one per non-root link.
#[derive(Debug, Clone, PartialEq)]
struct Element {
    joint: String,
    parent: String,
    origin: Origin,
    motion: Motion,
    link: String,
    body: Body,
}

/// The export before it is written out.
struct Model {
    elements: Vec<Element>,
}

/// Hands out unique names.
struct Names(BTreeSet<String>);

impl Names {
    /// `wanted`, or `wanted_2`, `wanted_3`, ... whichever is still free.
    fn take(&mut self, wanted: String) -> String {
        let mut name = wanted.clone();
        let mut n = 2;
        while self.0.contains(&name) {
            name = format!("{wanted}_{n}");
            n += 1;
        }
        self.0.insert(name.clone());
        name
    }
}

const ROOT: &str = "wrist";

impl Model {
    fn of(profile: &HandProfile) -> Model {
        let joints = &profile.joints;
        let mut names = Names(
            std::iter::once(ROOT.to_string())
                .chain(joints.iter().map(|j| j.name.clone()))
                .collect(),
        );
        // The link each profile joint is named on: the first it turns with ratio 1.
        let primary: Vec<Option<(usize, usize)>> = (0..joints.len())
            .map(|j| {
                profile.fingers.iter().enumerate().find_map(|(f, finger)| {
                    let k = finger
                        .links
                        .iter()
                        .position(|l| l.joint == Some(j) && l.ratio == 1.0)?;
                    Some((f, k))
                })
            })
            .collect();
        let mut elements = Vec::new();
        for (f, finger) in profile.fingers.iter().enumerate() {
            let mut parent = ROOT.to_string();
            for (k, link) in finger.links.iter().enumerate() {
                let origin = if k == 0 {
                    at_base(finger, link.origin)
                } else {
                    Origin {
                        xyz: wide(link.origin),
                        rpy: [0.0; 3],
                    }
                };
                let (joint, motion) = match link.joint {
                    None => (
                        names.take(format!("{}_joint{}", finger.name, k + 1)),
                        Motion::Fixed,
                    ),
                    Some(j) if primary[j] == Some((f, k)) => {
                        (joints[j].name.clone(), driven(joints, j, wide(link.axis)))
                    }
                    Some(j) => (
                        names.take(format!("{}_{}", joints[j].name, k + 1)),
                        passive(joints, j, f64::from(link.ratio), wide(link.axis)),
                    ),
                };
                let end = finger
                    .links
                    .get(k + 1)
                    .map_or(finger.tip, |next| next.origin);
                let child = names.take(format!("{}_link{}", finger.name, k + 1));
                elements.push(Element {
                    joint,
                    parent: std::mem::replace(&mut parent, child.clone()),
                    origin,
                    motion,
                    link: child,
                    body: Body::Segment(wide(end)),
                });
            }
            let frame = |at: [f32; 3]| {
                if finger.links.is_empty() {
                    at_base(finger, at)
                } else {
                    Origin {
                        xyz: wide(at),
                        rpy: [0.0; 3],
                    }
                }
            };
            for (what, at, body) in [
                ("tip", finger.tip, Body::Frame),
                ("pad", finger.pad, Body::Pad(f64::from(finger.pad_radius))),
            ] {
                elements.push(Element {
                    joint: names.take(format!("{}_{what}_joint", finger.name)),
                    parent: parent.clone(),
                    origin: frame(at),
                    motion: Motion::Fixed,
                    link: names.take(format!("{}_{what}", finger.name)),
                    body,
                });
            }
        }
        for (j, joint) in joints.iter().enumerate() {
            if primary[j].is_none() {
                elements.push(Element {
                    joint: joint.name.clone(),
                    parent: ROOT.to_string(),
                    origin: Origin::ZERO,
                    motion: driven(joints, j, [0.0, 0.0, 1.0]),
                    link: names.take(format!("{}_driver", joint.name)),
                    body: Body::Segment([0.0; 3]),
                });
            }
        }
        Model { elements }
    }

    fn render(&self, robot: &str) -> String {
        let mut out = String::new();
        // Writing to a String cannot fail.
        let _ = self.write(&mut out, robot);
        out
    }

    fn write(&self, out: &mut String, robot: &str) -> std::fmt::Result {
        writeln!(out, r#"<?xml version="1.0"?>"#)?;
        writeln!(
            out,
            "<!-- Written by `teleop profile urdf` from a hand profile; frames, names and \
             placeholder values: the `urdf` module of teleop-hand-profile. -->"
        )?;
        writeln!(out, r#"<robot name="{}">"#, escape(robot))?;
        writeln!(
            out,
            r#"  <material name="segment"><color rgba="0.7 0.7 0.72 1"/></material>"#
        )?;
        writeln!(
            out,
            r#"  <material name="pad"><color rgba="0.9 0.45 0.2 1"/></material>"#
        )?;
        writeln!(out, r#"  <link name="{ROOT}"/>"#)?;
        for e in &self.elements {
            write_joint(out, e)?;
            write_link(out, &e.link, e.body)?;
        }
        writeln!(out, "</robot>")
    }
}

/// The pose of a point of `finger` given in its base frame (`base`, rotated by `base_rpy`).
fn at_base(finger: &Finger, offset: [f32; 3]) -> Origin {
    let rpy = wide(finger.base_rpy);
    let r = rpy_matrix(rpy);
    let o = wide(offset);
    let base = wide(finger.base);
    Origin {
        xyz: core::array::from_fn(|i| base[i] + (0..3).map(|c| r[i][c] * o[c]).sum::<f64>()),
        rpy,
    }
}

/// The URDF joint named after profile joint `j`: its limits, and a mimic when it is coupled.
fn driven(joints: &[Joint], j: usize, axis: [f64; 3]) -> Motion {
    let joint = &joints[j];
    Motion::Revolute {
        axis,
        lower: f64::from(joint.lower),
        upper: f64::from(joint.upper),
        mimic: joint
            .coupling
            .map(|c| (joints[c.to].name.clone(), f64::from(c.ratio))),
    }
}

/// A further link turned by profile joint `j` with `ratio`: it mimics the joint that `j` is
/// (or that `j` follows), over `j`'s range scaled.
fn passive(joints: &[Joint], j: usize, ratio: f64, axis: [f64; 3]) -> Motion {
    let joint = &joints[j];
    let (to, multiplier) = match joint.coupling {
        Some(c) => (c.to, ratio * f64::from(c.ratio)),
        None => (j, ratio),
    };
    let a = ratio * f64::from(joint.lower);
    let b = ratio * f64::from(joint.upper);
    Motion::Revolute {
        axis,
        lower: a.min(b),
        upper: a.max(b),
        mimic: Some((joints[to].name.clone(), multiplier)),
    }
}

fn write_joint(out: &mut String, e: &Element) -> std::fmt::Result {
    let kind = match e.motion {
        Motion::Fixed => "fixed",
        Motion::Revolute { .. } => "revolute",
    };
    writeln!(
        out,
        r#"  <joint name="{}" type="{kind}">"#,
        escape(&e.joint)
    )?;
    writeln!(out, r#"    <parent link="{}"/>"#, escape(&e.parent))?;
    writeln!(out, r#"    <child link="{}"/>"#, escape(&e.link))?;
    writeln!(out, "    {}", origin(&e.origin))?;
    if let Motion::Revolute {
        axis,
        lower,
        upper,
        mimic,
    } = &e.motion
    {
        writeln!(out, r#"    <axis xyz="{}"/>"#, triple(*axis))?;
        writeln!(
            out,
            r#"    <limit lower="{}" upper="{}" effort="{}" velocity="{}"/>"#,
            num(*lower),
            num(*upper),
            num(EFFORT),
            num(VELOCITY)
        )?;
        if let Some((to, multiplier)) = mimic {
            writeln!(
                out,
                r#"    <mimic joint="{}" multiplier="{}" offset="0"/>"#,
                escape(to),
                num(*multiplier)
            )?;
        }
    }
    writeln!(out, "  </joint>")
}

fn write_link(out: &mut String, name: &str, body: Body) -> std::fmt::Result {
    let name = escape(name);
    match body {
        Body::Frame => writeln!(out, r#"  <link name="{name}"/>"#),
        Body::Pad(radius) if radius <= 0.0 => writeln!(out, r#"  <link name="{name}"/>"#),
        Body::Pad(radius) => {
            let sphere = format!(r#"<geometry><sphere radius="{}"/></geometry>"#, num(radius));
            writeln!(out, r#"  <link name="{name}">"#)?;
            writeln!(
                out,
                r#"    <visual>{sphere}<material name="pad"/></visual>"#
            )?;
            writeln!(out, "    <collision>{sphere}</collision>")?;
            writeln!(out, "  </link>")
        }
        Body::Segment(end) => {
            writeln!(out, r#"  <link name="{name}">"#)?;
            let i = num(LINK_INERTIA);
            writeln!(
                out,
                r#"    <inertial><mass value="{}"/><inertia ixx="{i}" ixy="0" ixz="0" iyy="{i}" iyz="0" izz="{i}"/></inertial>"#,
                num(LINK_MASS)
            )?;
            if let Some((placement, length)) = segment(end) {
                writeln!(
                    out,
                    r#"    <visual>{}<geometry><cylinder radius="{}" length="{}"/></geometry><material name="segment"/></visual>"#,
                    origin(&placement),
                    num(SEGMENT_RADIUS),
                    num(length)
                )?;
            }
            writeln!(out, "  </link>")
        }
    }
}

/// Where a cylinder (along its own z, centred on its origin) lies to join the origin to `end`,
/// and its length; `None` for a segment too short to draw.
fn segment(end: [f64; 3]) -> Option<(Origin, f64)> {
    let [x, y, z] = end;
    let length = (x * x + y * y + z * z).sqrt();
    if length < 1e-6 {
        return None;
    }
    // Rz(yaw) Ry(pitch) turns z to (cos yaw sin pitch, sin yaw sin pitch, cos pitch).
    let pitch = x.hypot(y).atan2(z);
    let yaw = y.atan2(x);
    Some((
        Origin {
            xyz: [x / 2.0, y / 2.0, z / 2.0],
            rpy: [0.0, pitch, yaw],
        },
        length,
    ))
}

fn origin(o: &Origin) -> String {
    format!(
        r#"<origin xyz="{}" rpy="{}"/>"#,
        triple(o.xyz),
        triple(o.rpy)
    )
}

fn triple(v: [f64; 3]) -> String {
    format!("{} {} {}", num(v[0]), num(v[1]), num(v[2]))
}

/// `v` as the profile wrote it when it is one of its (f32) numbers (`0.028`, not
/// `0.028000001`), else with 9 decimals, without trailing zeros (`0.0435`, `1.256637115`, `0`).
fn num(v: f64) -> String {
    // f32's Display is the shortest text that reads back as the same f32.
    let narrow = v as f32;
    let s = if f64::from(narrow) == v {
        narrow.to_string()
    } else {
        format!("{v:.9}")
    };
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        &s
    };
    if s == "-0" {
        "0".to_string()
    } else {
        s.to_string()
    }
}

fn wide(v: [f32; 3]) -> [f64; 3] {
    v.map(f64::from)
}

/// The rotation of URDF `rpy`: roll about x, then pitch about y, then yaw about z, all about
/// the fixed axes (`Rz(yaw) Ry(pitch) Rx(roll)`), as rows.
fn rpy_matrix([roll, pitch, yaw]: [f64; 3]) -> [[f64; 3]; 3] {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
}

/// `s` with XML's special characters escaped, for an attribute value.
fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_short_and_exact_to_a_nanometre() {
        assert_eq!(num(0.0), "0");
        assert_eq!(num(-0.0), "0");
        assert_eq!(num(-1e-12), "0");
        assert_eq!(num(1.0), "1");
        assert_eq!(num(0.0435), "0.0435");
        assert_eq!(num(-1.5707963705062866), "-1.5707964");
        assert_eq!(num(f64::from(0.028f32)), "0.028");
        assert_eq!(num(1e-6), "0.000001");
        assert_eq!(num(0.9 * 1.5707963705062866), "1.413716733");
        assert_eq!(num(-1e-30), "0");
        assert_eq!(num(1000.0), "1000");
    }

    #[test]
    fn a_segment_cylinder_joins_the_origin_to_its_end() {
        for end in [
            [0.0, 0.05, 0.0],
            [0.01, -0.02, 0.03],
            [0.0, 0.0, -0.04],
            [-0.03, 0.0, 0.0],
        ] {
            let (o, length) = segment(end).unwrap();
            let r = rpy_matrix(o.rpy);
            // The cylinder's axis (z) turned by its rpy, times half its length, from its centre,
            // reaches the end.
            for i in 0..3 {
                let tip = o.xyz[i] + r[i][2] * length / 2.0;
                assert!((tip - end[i]).abs() < 1e-12, "{end:?}: {tip} at {i}");
            }
        }
        assert!(segment([0.0; 3]).is_none());
    }

    #[test]
    fn names_are_escaped_for_xml() {
        assert_eq!(escape(r#"a<b>&"c'"#), "a&lt;b&gt;&amp;&quot;c&apos;");
    }

    #[test]
    fn taken_names_get_a_suffix() {
        let mut names = Names(["a".to_string(), "a_2".to_string()].into());
        assert_eq!(names.take("a".into()), "a_3");
        assert_eq!(names.take("b".into()), "b");
        assert_eq!(names.take("b".into()), "b_2");
    }
}
