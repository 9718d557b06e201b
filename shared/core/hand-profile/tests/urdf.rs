//! The URDF export ([`HandProfile::to_urdf`]) read back by an independent XML parser
//! (roxmltree): a well-formed tree (links and joints that exist, one root, no cycles, mimics of
//! existing driven joints, every profile joint by name), whose `<finger>_tip` and `<finger>_pad`
//! frames, posed from the URDF alone, are where the profile's own forward kinematics puts them
//! (to 1e-6 m, for random joint vectors within the limits).
//!
//! The same frames are also checked in pinocchio (pip `pin`, the library dex-retargeting loads
//! robots with), mimic joints as pinocchio reads them; without `import pinocchio` that test
//! prints why and passes, unless `TELEOP_REQUIRE_CHECKS` (set by `.ci/run` as root) is set.

#![allow(clippy::unwrap_used)]

use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;
use std::process::{Command, Stdio};

use proptest::prelude::*;
use teleop_hand_profile::{HandProfile, MAX_JOINTS};

type Vec3 = [f64; 3];
type Mat3 = [[f64; 3]; 3];

/// A URDF joint as the file says it.
#[derive(Debug, Clone)]
struct UrdfJoint {
    name: String,
    revolute: bool,
    parent: String,
    child: String,
    xyz: Vec3,
    rpy: Vec3,
    axis: Vec3,
    lower: f64,
    upper: f64,
    /// `(joint, multiplier, offset)`.
    mimic: Option<(String, f64, f64)>,
}

/// A parsed and checked URDF.
#[derive(Debug)]
struct Urdf {
    robot: String,
    root: String,
    joints: Vec<UrdfJoint>,
    /// Radius of each link's collision sphere, if it has one.
    spheres: BTreeMap<String, f64>,
}

impl Urdf {
    fn joint(&self, name: &str) -> Option<&UrdfJoint> {
        self.joints.iter().find(|j| j.name == name)
    }
}

fn numbers(text: Option<&str>, what: &str) -> Result<Vec3, String> {
    let Some(text) = text else {
        return Ok([0.0; 3]);
    };
    let v: Vec<f64> = text
        .split_whitespace()
        .map(|s| s.parse::<f64>().map_err(|e| format!("{what}: `{s}`: {e}")))
        .collect::<Result<_, _>>()?;
    v.try_into()
        .map_err(|v: Vec<f64>| format!("{what}: {} numbers, not 3", v.len()))
}

fn number(node: roxmltree::Node, attr: &str, what: &str) -> Result<f64, String> {
    let text = node
        .attribute(attr)
        .ok_or_else(|| format!("{what}: no `{attr}`"))?;
    text.parse()
        .map_err(|e| format!("{what}: {attr} `{text}`: {e}"))
}

fn child<'a, 'i>(node: roxmltree::Node<'a, 'i>, tag: &str) -> Option<roxmltree::Node<'a, 'i>> {
    node.children().find(|c| c.has_tag_name(tag))
}

/// Parses `text` and checks that it is a well-formed kinematic tree.
fn parse(text: &str) -> Result<Urdf, String> {
    let doc = roxmltree::Document::parse(text).map_err(|e| format!("not XML: {e}"))?;
    let robot = doc.root_element();
    if !robot.has_tag_name("robot") {
        return Err(format!("root element <{}>", robot.tag_name().name()));
    }
    let mut links = BTreeSet::new();
    let mut spheres = BTreeMap::new();
    for link in robot.children().filter(|c| c.has_tag_name("link")) {
        let name = link.attribute("name").ok_or("a link without a name")?;
        if !links.insert(name.to_string()) {
            return Err(format!("two links are called `{name}`"));
        }
        if let Some(sphere) = child(link, "collision")
            .and_then(|c| child(c, "geometry"))
            .and_then(|g| child(g, "sphere"))
        {
            spheres.insert(name.to_string(), number(sphere, "radius", name)?);
        }
    }
    let mut joints: Vec<UrdfJoint> = Vec::new();
    for j in robot.children().filter(|c| c.has_tag_name("joint")) {
        let name = j
            .attribute("name")
            .ok_or("a joint without a name")?
            .to_string();
        if joints.iter().any(|k| k.name == name) {
            return Err(format!("two joints are called `{name}`"));
        }
        let revolute = match j.attribute("type") {
            Some("revolute") => true,
            Some("fixed") => false,
            other => return Err(format!("{name}: type {other:?}")),
        };
        let link_of = |tag: &str| -> Result<String, String> {
            let l = child(j, tag)
                .and_then(|n| n.attribute("link"))
                .ok_or_else(|| format!("{name}: no <{tag} link>"))?;
            if !links.contains(l) {
                return Err(format!("{name}: {tag} `{l}` is not a link"));
            }
            Ok(l.to_string())
        };
        let origin = child(j, "origin");
        let mut joint = UrdfJoint {
            parent: link_of("parent")?,
            child: link_of("child")?,
            xyz: numbers(origin.and_then(|o| o.attribute("xyz")), &name)?,
            rpy: numbers(origin.and_then(|o| o.attribute("rpy")), &name)?,
            axis: [0.0; 3],
            lower: 0.0,
            upper: 0.0,
            mimic: None,
            revolute,
            name,
        };
        if revolute {
            let what = &joint.name;
            joint.axis = numbers(child(j, "axis").and_then(|a| a.attribute("xyz")), what)?;
            let norm = joint.axis.iter().map(|a| a * a).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > 1e-6 {
                return Err(format!("{what}: axis of length {norm}"));
            }
            let limit = child(j, "limit").ok_or_else(|| format!("{what}: no <limit>"))?;
            joint.lower = number(limit, "lower", what)?;
            joint.upper = number(limit, "upper", what)?;
            if joint.lower > joint.upper {
                return Err(format!("{what}: limits {} > {}", joint.lower, joint.upper));
            }
            for attr in ["effort", "velocity"] {
                if number(limit, attr, what)? <= 0.0 {
                    return Err(format!("{what}: {attr} not positive"));
                }
            }
            if let Some(m) = child(j, "mimic") {
                let to = m
                    .attribute("joint")
                    .ok_or_else(|| format!("{what}: mimic no joint"))?;
                let multiplier = m
                    .attribute("multiplier")
                    .map_or(Ok(1.0), |_| number(m, "multiplier", what))?;
                let offset = m
                    .attribute("offset")
                    .map_or(Ok(0.0), |_| number(m, "offset", what))?;
                joint.mimic = Some((to.to_string(), multiplier, offset));
            }
        }
        joints.push(joint);
    }
    // A tree: every link the child of at most one joint, exactly one link the child of none,
    // and every link reached from it (so no cycles).
    let mut parents: BTreeMap<&str, &str> = BTreeMap::new();
    for j in &joints {
        if parents.insert(&j.child, &j.name).is_some() {
            return Err(format!("link `{}` is the child of two joints", j.child));
        }
    }
    let roots: Vec<&String> = links
        .iter()
        .filter(|l| !parents.contains_key(l.as_str()))
        .collect();
    let [root] = roots[..] else {
        return Err(format!("roots {roots:?}, not one"));
    };
    let mut reached = BTreeSet::from([root.as_str()]);
    let mut frontier = vec![root.as_str()];
    while let Some(link) = frontier.pop() {
        for j in joints.iter().filter(|j| j.parent == link) {
            if reached.insert(&j.child) {
                frontier.push(&j.child);
            }
        }
    }
    if reached.len() != links.len() {
        let cut: Vec<_> = links
            .iter()
            .filter(|l| !reached.contains(l.as_str()))
            .collect();
        return Err(format!(
            "links {cut:?} are not reached from `{root}` (a cycle)"
        ));
    }
    for j in &joints {
        if let Some((to, _, _)) = &j.mimic {
            match joints.iter().find(|k| &k.name == to) {
                None => return Err(format!("{}: mimics `{to}`, no such joint", j.name)),
                Some(k) if !k.revolute || k.mimic.is_some() => {
                    return Err(format!("{}: mimics `{to}`, not a driven joint", j.name))
                }
                Some(_) => {}
            }
        }
    }
    Ok(Urdf {
        robot: robot.attribute("name").unwrap_or_default().to_string(),
        root: root.clone(),
        joints,
        spheres,
    })
}

fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    core::array::from_fn(|i| core::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn apply(a: &Mat3, v: Vec3) -> Vec3 {
    core::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

fn add(a: Vec3, b: Vec3) -> Vec3 {
    core::array::from_fn(|i| a[i] + b[i])
}

/// Rotation by `angle` about the unit `axis` (Rodrigues).
fn axis_angle(axis: Vec3, angle: f64) -> Mat3 {
    let [x, y, z] = axis;
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

/// URDF rpy: roll about x, pitch about y, yaw about z, fixed axes.
fn rpy(v: Vec3) -> Mat3 {
    let [r, p, y] = v;
    mul(
        &axis_angle([0.0, 0.0, 1.0], y),
        &mul(
            &axis_angle([0.0, 1.0, 0.0], p),
            &axis_angle([1.0, 0.0, 0.0], r),
        ),
    )
}

fn wide(v: [f32; 3]) -> Vec3 {
    v.map(f64::from)
}

/// The profile's angles for `fractions` of each joint's range; a coupled joint follows its
/// joint, clamped to its limits, as the profile says.
fn profile_angles(profile: &HandProfile, fractions: &[f64]) -> Vec<f64> {
    let mut q: Vec<f64> = profile
        .joints
        .iter()
        .zip(fractions)
        .map(|(j, u)| f64::from(j.lower) + u * (f64::from(j.upper) - f64::from(j.lower)))
        .collect();
    for (i, j) in profile.joints.iter().enumerate() {
        if let Some(c) = j.coupling {
            q[i] = (f64::from(c.ratio) * q[c.to]).clamp(f64::from(j.lower), f64::from(j.upper));
        }
    }
    q
}

/// The profile's forward kinematics, written from its definition: per finger `(tip, pad)` in
/// the hand frame.
fn profile_fk(profile: &HandProfile, q: &[f64]) -> Vec<(Vec3, Vec3)> {
    profile
        .fingers
        .iter()
        .map(|f| {
            let mut p = wide(f.base);
            let mut r = rpy(wide(f.base_rpy));
            for link in &f.links {
                p = add(p, apply(&r, wide(link.origin)));
                let angle = link.joint.map_or(0.0, |j| f64::from(link.ratio) * q[j]);
                r = mul(&r, &axis_angle(wide(link.axis), angle));
            }
            (
                add(p, apply(&r, wide(f.tip))),
                add(p, apply(&r, wide(f.pad))),
            )
        })
        .collect()
}

/// Each URDF joint's angle when the profile's joints are at `q`: driven joints by name, mimic
/// joints from the joint they follow. Panics on a driven joint that is no profile joint.
fn urdf_angles(urdf: &Urdf, profile: &HandProfile, q: &[f64]) -> BTreeMap<String, f64> {
    let driven = |name: &str| {
        let i = profile
            .joint_index(name)
            .unwrap_or_else(|| panic!("driven URDF joint `{name}` is no profile joint"));
        q[i]
    };
    urdf.joints
        .iter()
        .filter(|j| j.revolute)
        .map(|j| {
            let angle = match &j.mimic {
                Some((to, multiplier, offset)) => multiplier * driven(to) + offset,
                None => driven(&j.name),
            };
            (j.name.clone(), angle)
        })
        .collect()
}

/// Every link's pose in the root's frame (the URDF's own forward kinematics).
fn urdf_fk(urdf: &Urdf, angles: &BTreeMap<String, f64>) -> BTreeMap<String, (Vec3, Mat3)> {
    let identity = rpy([0.0; 3]);
    let mut poses = BTreeMap::from([(urdf.root.clone(), ([0.0; 3], identity))]);
    let mut frontier = vec![urdf.root.clone()];
    while let Some(link) = frontier.pop() {
        let (p, r) = poses[&link];
        for j in urdf.joints.iter().filter(|j| j.parent == link) {
            let turn = angles
                .get(&j.name)
                .map_or(identity, |a| axis_angle(j.axis, *a));
            let child_p = add(p, apply(&r, j.xyz));
            let child_r = mul(&mul(&r, &rpy(j.rpy)), &turn);
            poses.insert(j.child.clone(), (child_p, child_r));
            frontier.push(j.child.clone());
        }
    }
    poses
}

/// Equal within the precision of the profile's numbers (f32, which the URDF may print as the
/// profile's text: `1.5707964`, not `1.570796371`).
fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 2.0 * f64::from(f32::EPSILON) * b.abs().max(1.0)
}

fn distance(a: Vec3, b: Vec3) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
}

/// Checks the export of `profile` at `fractions` of each joint's range: names, limits, pads, and
/// every tip and pad frame against the profile's kinematics.
fn check(profile: &HandProfile, fractions: &[f64]) -> Result<(), String> {
    let text = profile.to_urdf();
    let urdf = parse(&text).map_err(|e| format!("{}: {e}", profile.name))?;
    let at = |what: String| format!("{}: {what}", profile.name);
    if urdf.robot != profile.name || urdf.root != "wrist" {
        return Err(at(format!(
            "robot `{}` rooted at `{}`",
            urdf.robot, urdf.root
        )));
    }
    for j in &profile.joints {
        let u = urdf
            .joint(&j.name)
            .filter(|u| u.revolute)
            .ok_or_else(|| at(format!("no revolute joint `{}`", j.name)))?;
        let mimic = u.mimic.as_ref().map(|(to, m, _)| (to.as_str(), *m));
        let want = j
            .coupling
            .map(|c| (profile.joints[c.to].name.as_str(), f64::from(c.ratio)));
        let same = match (mimic, want) {
            (None, None) => true,
            (Some((a, m)), Some((b, n))) => a == b && close(m, n),
            _ => false,
        };
        if !same {
            return Err(at(format!("`{}` mimics {mimic:?}, not {want:?}", j.name)));
        }
        if !close(u.lower, f64::from(j.lower)) || !close(u.upper, f64::from(j.upper)) {
            return Err(at(format!(
                "`{}` limits [{}, {}]",
                j.name, u.lower, u.upper
            )));
        }
    }
    let q = profile_angles(profile, fractions);
    let angles = urdf_angles(&urdf, profile, &q);
    for j in urdf.joints.iter().filter(|j| j.revolute) {
        let a = angles[&j.name];
        if !(a >= j.lower || close(a, j.lower)) || !(a <= j.upper || close(a, j.upper)) {
            return Err(at(format!(
                "`{}` at {a} outside [{}, {}]",
                j.name, j.lower, j.upper
            )));
        }
    }
    let poses = urdf_fk(&urdf, &angles);
    for (f, (tip, pad)) in profile.fingers.iter().zip(profile_fk(profile, &q)) {
        for (frame, want) in [("tip", tip), ("pad", pad)] {
            let name = format!("{}_{frame}", f.name);
            let (got, _) = poses
                .get(&name)
                .ok_or_else(|| at(format!("no link `{name}`")))?;
            let error = distance(*got, want);
            if error > 1e-6 {
                return Err(at(format!(
                    "`{name}` at {got:?}, the profile says {want:?} ({error:e} m off) for {q:?}"
                )));
            }
        }
        let pad = format!("{}_pad", f.name);
        let radius = urdf.spheres.get(&pad).copied().unwrap_or(0.0);
        if !close(radius, f64::from(f.pad_radius)) {
            return Err(at(format!("`{pad}` sphere {radius}, not {}", f.pad_radius)));
        }
    }
    Ok(())
}

/// A profile with what the shipped ones lack: a fixed link, a finger without links, a joint
/// only a linkage turns (ratio 0.5), a coupled joint that also turns a linkage, one joint in
/// two fingers, names with XML's special characters, and names the export would generate.
const ODD: &str = r#"
[hand]
name = "odd & <hand>"
model = "test"
model_id = 200
command_units = "radians"

[[joint]]
name = "a\"1"
finger = "f&1"
role = "flex"
limits = [-0.5, 1.2]
device = { unit = "rad", scale = 1.0 }

[[joint]]
name = "a2"
finger = "f&1"
role = "flex"
limits = [-0.5, 1.0]
device = { unit = "rad", scale = 1.0 }
coupled = { to = "a\"1", ratio = 0.8 }

[[joint]]
name = "lonely"
finger = "g"
role = "abduct"
limits = [-0.3, 0.4]
device = { unit = "rad", scale = 1.0 }

[[joint]]
name = "f&1_link1"
finger = "g"
role = "flex"
limits = [-1.0, 0.2]
device = { unit = "rad", scale = 1.0 }

[[finger]]
name = "f&1"
base = [0.01, 0.02, -0.003]
base_rpy = [0.3, -1.1, 2.0]
tip = [0.001, 0.03, 0.002]
pad = [0.0, 0.025, -0.004]
pad_radius = 0.007
link = [
  { joint = "a\"1", axis = [0.0, 0.6, 0.8], origin = [0.004, 0.01, 0.0] },
  { axis = [1.0, 0.0, 0.0], origin = [0.0, 0.02, 0.001] },
  { joint = "a2", axis = [-1.0, 0.0, 0.0], origin = [0.0, 0.03, 0.0] },
  { joint = "a2", ratio = 0.7, axis = [-1.0, 0.0, 0.0], origin = [0.0, 0.02, 0.0] },
]

[[finger]]
name = "g"
base = [0.03, 0.05, 0.0]
base_rpy = [0.0, 0.2, -0.4]
tip = [0.0, 0.04, 0.0]
link = [
  { joint = "lonely", ratio = 0.5, axis = [0.0, 0.0, 1.0], origin = [0.0, 0.0, 0.01] },
  { joint = "f&1_link1", axis = [-1.0, 0.0, 0.0], origin = [0.0, 0.03, 0.0] },
  { joint = "a\"1", ratio = -1.3, axis = [0.0, 1.0, 0.0], origin = [0.0, 0.01, 0.0] },
]

[[finger]]
name = "stub"
base = [-0.02, 0.0, 0.01]
base_rpy = [0.5, 0.0, 0.0]
tip = [0.0, 0.01, 0.02]
pad_radius = 0.004
"#;

/// True when `joint` mimics `to` with `multiplier` (as far as f32 profile values allow) and no
/// offset.
fn mimics(joint: &UrdfJoint, to: &str, multiplier: f64) -> bool {
    joint
        .mimic
        .as_ref()
        .is_some_and(|(t, m, o)| t == to && close(*m, multiplier) && *o == 0.0)
}

fn odd() -> HandProfile {
    HandProfile::from_toml_str(ODD, "odd.toml").unwrap()
}

#[test]
fn odd_profile_exports_a_checked_tree() {
    let profile = odd();
    for u in [0.0, 0.3, 1.0] {
        check(&profile, &[u; MAX_JOINTS]).unwrap();
    }
    let urdf = parse(&profile.to_urdf()).unwrap();
    assert_eq!(urdf.robot, "odd & <hand>");
    // The joint a linkage alone turns is there by name, on a stub off the wrist, and the link
    // that was to be called like an existing joint is still a link of its own name.
    let lonely = urdf.joint("lonely").unwrap();
    assert_eq!(
        (lonely.parent.as_str(), lonely.mimic.as_ref()),
        ("wrist", None)
    );
    let g1 = urdf.joint("lonely_1").unwrap();
    assert!(mimics(g1, "lonely", 0.5), "{g1:?}");
    // Half of [-0.3, 0.4] (as f32).
    assert!(close(g1.lower, -0.15) && close(g1.upper, 0.2), "{g1:?}");
    let negative = urdf.joint("a\"1_3").unwrap();
    assert!(mimics(negative, "a\"1", -1.3), "{negative:?}");
    assert!(negative.lower < negative.upper);
    // A coupled joint's linkage mimics the joint it follows, with both ratios.
    assert!(mimics(urdf.joint("a2_4").unwrap(), "a\"1", 0.8 * 0.7));
    assert!(urdf.joint("f&1_joint2").is_some_and(|j| !j.revolute));
    assert_eq!(urdf.joint("f&1_link1").unwrap().parent, "g_link1");
}

#[test]
fn checks_fail_on_broken_urdf() {
    let good = HandProfile::builtin("shadow").unwrap().to_urdf();
    for (from, to, why) in [
        (
            r#"<mimic joint="FFJ2""#,
            r#"<mimic joint="FFJ9""#,
            "no such joint",
        ),
        (
            r#"<mimic joint="FFJ2""#,
            r#"<mimic joint="MFJ1""#,
            "not a driven joint",
        ),
        (
            r#"<child link="ff_link2"/>"#,
            r#"<child link="ff_link9"/>"#,
            "not a link",
        ),
        (
            r#"<child link="ff_link2"/>"#,
            r#"<child link="ff_link1"/>"#,
            "child of two",
        ),
        (
            r#"<parent link="ff_link1"/>"#,
            r#"<parent link="ff_link3"/>"#,
            "a cycle",
        ),
        (
            r#"<link name="wrist"/>"#,
            r#"<link name="wrist"/><link name="x"/>"#,
            "not one",
        ),
        (r#" effort="1""#, "", "no `effort`"),
    ] {
        assert!(good.contains(from), "{from}");
        let bad = good.replacen(from, to, 1);
        let e = parse(&bad).unwrap_err();
        assert!(e.contains(why), "{from} -> {to}: {e}");
    }
    // A frame moved by a micrometre is caught by the kinematic check.
    let profile = HandProfile::builtin("allegro").unwrap();
    let mut moved = profile.clone();
    moved.fingers[3].links[2].origin[1] += 2e-6;
    let urdf = parse(&moved.to_urdf()).unwrap();
    let q = profile_angles(&profile, &[0.5; MAX_JOINTS]);
    let poses = urdf_fk(&urdf, &urdf_angles(&urdf, &profile, &q));
    let (tip, _) = profile_fk(&profile, &q)[3];
    assert!(distance(poses["thumb_tip"].0, tip) > 1e-6);
}

#[test]
fn every_builtin_profile_exports_at_its_limits() {
    for name in HandProfile::builtin_names() {
        let profile = HandProfile::builtin(name).unwrap();
        for u in [0.0, 0.5, 1.0] {
            check(&profile, &[u; MAX_JOINTS]).unwrap();
        }
    }
}

/// Reads lines `case<TAB>urdf file<TAB>joint=angle...` (the profile's driven joints) on standard
/// input; prints per case its configuration size (`case<TAB>#nq<TAB>n`) and every tip and pad
/// frame (`case<TAB>frame<TAB>x<TAB>y<TAB>z`), posed by pinocchio with its mimic joints.
const PINOCCHIO: &str = r#"
import sys
import pinocchio as pin
models = {}
for line in sys.stdin:
    case, path, *angles = line.rstrip("\n").split("\t")
    if path not in models:
        models[path] = pin.buildModelFromUrdf(path, mimic=True)
    model = models[path]
    data = model.createData()
    q = pin.neutral(model)
    for item in angles:
        name, value = item.rsplit("=", 1)
        q[model.joints[model.getJointId(name)].idx_q] = float(value)
    pin.framesForwardKinematics(model, data, q)
    print(f"{case}\t#nq\t{model.nq}")
    for i, frame in enumerate(model.frames):
        if frame.name.endswith(("_tip", "_pad")):
            x, y, z = map(float, data.oMf[i].translation)
            print(f"{case}\t{frame.name}\t{x!r}\t{y!r}\t{z!r}")
"#;

#[test]
fn pinocchio_puts_tips_and_pads_where_the_profile_does() {
    let ready = Command::new("python3")
        .args(["-c", "import pinocchio"])
        .output()
        .map_err(|e| e.to_string())
        .and_then(|o| {
            o.status
                .success()
                .then_some(())
                .ok_or_else(|| String::from_utf8_lossy(&o.stderr).trim().to_string())
        });
    if let Err(reason) = ready {
        assert!(
            std::env::var_os("TELEOP_REQUIRE_CHECKS").is_none(),
            "pinocchio required but missing: {reason}"
        );
        println!("SKIPPED: python3 cannot import pinocchio ({reason}); pip install pin==4.1.0");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // Per case: the profile, and its angles at spread fractions of each joint's range.
    let mut cases = Vec::new();
    let mut input = String::new();
    for name in HandProfile::builtin_names() {
        let profile = HandProfile::builtin(name).unwrap();
        let path = dir.path().join(format!("{name}.urdf"));
        std::fs::write(&path, profile.to_urdf()).unwrap();
        for k in 0..8 {
            let fractions: Vec<f64> = (0..MAX_JOINTS)
                .map(|i| ((k * 7 + i * 13) % 11) as f64 / 10.0)
                .collect();
            let q = profile_angles(&profile, &fractions);
            input.push_str(&format!("{}\t{}", cases.len(), path.display()));
            for (j, angle) in profile.joints.iter().zip(&q) {
                if j.coupling.is_none() {
                    input.push_str(&format!("\t{}={angle:e}", j.name));
                }
            }
            input.push('\n');
            cases.push((profile.clone(), q));
        }
    }
    let mut child = Command::new("python3")
        .args(["-c", PINOCCHIO])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut seen = BTreeMap::new();
    let mut worst = 0.0f64;
    for line in String::from_utf8(out.stdout).unwrap().lines() {
        let fields: Vec<&str> = line.split('\t').collect();
        let (profile, q) = &cases[fields[0].parse::<usize>().unwrap()];
        if fields[1] == "#nq" {
            // One configuration entry per driven joint: the coupled ones are mimics.
            let driven = profile
                .joints
                .iter()
                .filter(|j| j.coupling.is_none())
                .count();
            assert_eq!(fields[2], driven.to_string(), "{}", profile.name);
            continue;
        }
        let got: Vec<f64> = fields[2..].iter().map(|v| v.parse().unwrap()).collect();
        let fk = profile_fk(profile, q);
        let (f, frame) = profile
            .fingers
            .iter()
            .enumerate()
            .find_map(|(f, finger)| {
                let frame = fields[1].strip_prefix(finger.name.as_str())?;
                matches!(frame, "_tip" | "_pad").then_some((f, frame))
            })
            .unwrap_or_else(|| panic!("{}: frame {} of no finger", profile.name, fields[1]));
        let want = if frame == "_tip" { fk[f].0 } else { fk[f].1 };
        let error = distance([got[0], got[1], got[2]], want);
        assert!(
            error < 1e-6,
            "{}: {} {error:e} m off",
            profile.name,
            fields[1]
        );
        worst = worst.max(error);
        *seen.entry(profile.name.clone()).or_insert(0) += 1;
    }
    for (profile, _) in cases.iter().step_by(8) {
        assert_eq!(
            seen.get(&profile.name),
            Some(&(8 * 2 * profile.fingers.len())),
            "{}: every tip and pad of every case",
            profile.name
        );
    }
    println!(
        "pinocchio: every tip and pad of {} cases within {worst:e} m",
        cases.len()
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn urdf_frames_follow_the_profile_kinematics(
        name in prop::sample::select(HandProfile::builtin_names().collect::<Vec<_>>()),
        fractions in prop::collection::vec(0.0..=1.0f64, MAX_JOINTS),
    ) {
        let profile = HandProfile::builtin(name).unwrap();
        prop_assert_eq!(check(&profile, &fractions), Ok(()));
    }

    #[test]
    fn odd_urdf_frames_follow_the_profile_kinematics(
        fractions in prop::collection::vec(0.0..=1.0f64, MAX_JOINTS),
    ) {
        prop_assert_eq!(check(&odd(), &fractions), Ok(()));
    }
}
