//! The shipped profiles load and say what docs/devices/ says; bad profiles are refused with the file,
//! the line and the field; no text makes the loader panic.

#![allow(clippy::unwrap_used)]

use std::path::Path;

use proptest::prelude::*;
use teleop_hand_profile::{CommandUnits, HandProfile, ProfileError, Role, TipSensor};

fn shipped(name: &str) -> HandProfile {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../config/hands")
        .join(format!("{name}.toml"));
    HandProfile::load(&path).unwrap()
}

#[test]
fn shipped_profiles_load_and_match_the_compiled_in_copies() {
    for name in HandProfile::builtin_names() {
        let from_file = shipped(name);
        assert_eq!(
            HandProfile::builtin(name).as_ref(),
            Some(&from_file),
            "{name}"
        );
        assert_eq!(from_file.name, name);
    }
    assert!(HandProfile::builtin("nope").is_none());
}

#[test]
fn revo2_profile_keeps_the_pipeline_order() {
    let p = shipped("revo2");
    let names: Vec<_> = p.joint_names().collect();
    assert_eq!(
        names,
        [
            "thumb_flex",
            "thumb_abduct",
            "index",
            "middle",
            "ring",
            "pinky"
        ]
    );
    assert_eq!(p.command_units, CommandUnits::Normalised);
    assert_eq!(p.model_id, 1);
    let tips: Vec<_> = p.fingertips().map(|f| f.name.as_str()).collect();
    assert_eq!(tips, ["thumb", "index", "middle", "ring", "pinky"]);
    // Each joint is driven by one glove channel with gain 1: little, ring, middle, index, thumb,
    // thumb_rotation = 0..5.
    let channels: Vec<_> = p.joints.iter().map(|j| j.glove.channels.clone()).collect();
    assert_eq!(
        channels,
        [
            vec![(4, 1.0)],
            vec![(5, 1.0)],
            vec![(3, 1.0)],
            vec![(2, 1.0)],
            vec![(1, 1.0)],
            vec![(0, 1.0)]
        ]
    );
    // Feedback: glove little <- pinky fingertip (4) and joint pinky (5), thumb <- thumb (0),
    // thumb_flex (0).
    assert_eq!(p.feedback[0].tactile, Some(4));
    assert_eq!(p.feedback[0].joints, [5]);
    assert_eq!(p.feedback[4].tactile, Some(0));
    assert_eq!(p.feedback[4].joints, [0]);
    // 1000 per mille at 90 degrees.
    let j = &p.joints[2];
    assert!((j.to_device(j.radians(1.0)) - 1000.0).abs() < 0.01);
    assert!((j.from_device(500.0) - j.radians(0.5)).abs() < 1e-5);
}

#[test]
fn allegro_profile_has_four_fingers_and_the_urdf_limits() {
    let p = shipped("allegro");
    assert_eq!(p.joints.len(), 16);
    assert_eq!(p.command_units, CommandUnits::Radians);
    assert_eq!(p.fingertips().count(), 0);
    // docs/devices/allegro.md, "Joints": fingers j1 -0.196..1.61, thumb j12 0.263..1.396.
    let j1 = &p.joints[p.joint_index("middle_1").unwrap()];
    assert_eq!((j1.lower, j1.upper), (-0.196, 1.61));
    let j12 = &p.joints[12];
    assert_eq!(j12.name, "thumb_0");
    assert_eq!((j12.lower, j12.upper), (0.263, 1.396));
    assert_eq!(p.joints[0].role, Role::Abduct);
    // The glove's little finger drives nothing and gets no force.
    assert!(p
        .joints
        .iter()
        .all(|j| j.glove.channels.iter().all(|c| c.0 != 0)));
    assert!(p.feedback[0].is_none());
    assert!(!p.feedback[3].is_none());
    // Position counts: 32768 at 0 rad, 333.3 degrees per 65536 counts.
    let j = &p.joints[1];
    assert_eq!(j.to_device(0.0), 32768.0);
    let per_degree = j.to_device(1f32.to_radians()) - 32768.0;
    assert!((per_degree - 65536.0 / 333.3).abs() < 0.01, "{per_degree}");
}

#[test]
fn shadow_profile_couples_j1_to_j2_and_has_pst_tips() {
    let p = shipped("shadow");
    assert_eq!(p.joints.len(), 24);
    for f in ["FF", "MF", "RF", "LF"] {
        let j1 = p.joint_index(&format!("{f}J1")).unwrap();
        let j2 = p.joint_index(&format!("{f}J2")).unwrap();
        let c = p.joints[j1].coupling.unwrap();
        assert_eq!((c.to, c.ratio), (j2, 1.0));
        assert!(p.joints[j1].glove.channels.is_empty());
        assert!(p.joints[j2].coupling.is_none());
    }
    assert_eq!(p.fingertips().count(), 5);
    assert!(p.fingertips().all(|f| f.tip_sensor == TipSensor::Pst));
    assert_eq!(p.joints.iter().filter(|j| j.coupling.is_some()).count(), 4);
}

fn error_of(text: &str) -> ProfileError {
    HandProfile::from_toml_str(text, "hands/bad.toml").unwrap_err()
}

const GOOD: &str = r#"[hand]
name = "two"
model = "A two-joint test hand"
model_id = 0
command_units = "radians"

[[joint]]
name = "a"
finger = "f"
role = "flex"
limits = [0.0, 1.0]
device = { unit = "rad", scale = 1.0 }
glove = { channels = ["index"] }

[[joint]]
name = "b"
finger = "f"
role = "flex"
limits = [0.0, 1.0]
device = { unit = "rad", scale = 1.0 }
coupled = { to = "a", ratio = 0.5 }

[[finger]]
name = "f"
tip_sensor = "revo2"
base = [0.0, 0.1, 0.0]
tip = [0.0, 0.02, 0.0]
link = [{ joint = "a", axis = [-1.0, 0.0, 0.0] }]

[[feedback]]
glove_finger = "index"
tactile = "f"
joints = ["a"]
"#;

/// `GOOD` with the first occurrence of `from` replaced.
fn with(from: &str, to: &str) -> String {
    assert!(GOOD.contains(from), "{from}");
    GOOD.replacen(from, to, 1)
}

fn invalid(text: &str) -> (usize, String, String) {
    match error_of(text) {
        ProfileError::Invalid {
            origin,
            line,
            field,
            reason,
        } => {
            assert_eq!(origin, "hands/bad.toml");
            (line, field, reason)
        }
        other => panic!("expected Invalid, got {other}"),
    }
}

#[test]
fn the_test_profile_is_good() {
    let p = HandProfile::from_toml_str(GOOD, "good.toml").unwrap();
    assert_eq!(p.joints[1].coupling.unwrap().to, 0);
}

#[test]
fn a_limit_out_of_order_names_file_line_and_field() {
    let text = with("limits = [0.0, 1.0]", "limits = [1.2, 0.3]");
    let (line, field, reason) = invalid(&text);
    assert_eq!((line, field.as_str()), (11, "joint[0].limits"));
    assert!(
        reason.contains("lower (1.2) must be below upper (0.3)"),
        "{reason}"
    );
    let shown = error_of(&text).to_string();
    assert!(
        shown.starts_with("hands/bad.toml:11: joint[0].limits: "),
        "{shown}"
    );
}

#[test]
fn bad_joint_names_are_refused_with_their_line() {
    let (line, field, reason) = invalid(&with("name = \"b\"", "name = \"a\""));
    assert_eq!((line, field.as_str()), (16, "joint[1].name"));
    assert!(reason.contains("already"), "{reason}");
    let (_, field, _) = invalid(&with("name = \"a\"", "name = \" \""));
    assert_eq!(field, "joint[0].name");
}

#[test]
fn maps_to_joints_that_do_not_exist_are_refused() {
    let (line, field, reason) = invalid(&with("joints = [\"a\"]", "joints = [\"a\", \"zz\"]"));
    assert_eq!((line, field.as_str()), (33, "feedback[0].joints"));
    assert!(reason.contains("`zz`"), "{reason}");
    let (line, field, _) = invalid(&with("to = \"a\"", "to = \"nope\""));
    assert_eq!((line, field.as_str()), (21, "joint[1].coupled.to"));
    let (_, field, _) = invalid(&with("{ joint = \"a\"", "{ joint = \"q\""));
    assert_eq!(field, "finger[0].link[0].joint");
    let (_, field, reason) = invalid(&with("tactile = \"f\"", "tactile = \"g\""));
    assert_eq!(field, "feedback[0].tactile");
    assert!(reason.contains("`g`"), "{reason}");
    let (_, field, _) = invalid(&with("channels = [\"index\"]", "channels = [\"pinky\"]"));
    assert_eq!(field, "joint[0].glove.channels");
    let (_, field, _) = invalid(&with("finger = \"f\"", "finger = \"nope\""));
    assert_eq!(field, "joint[0].finger");
    let (_, field, _) = invalid(&with(
        "glove_finger = \"index\"",
        "glove_finger = \"pinky\"",
    ));
    assert_eq!(field, "feedback[0].glove_finger");
}

#[test]
fn other_inconsistencies_are_refused() {
    let (_, field, _) = invalid(&with(
        "limits = [0.0, 1.0]\ndevice",
        "limits = [0.0, 1.0]\nopen = 2.0\ndevice",
    ));
    assert_eq!(field, "joint[0].open");
    let (_, field, _) = invalid(&with("scale = 1.0", "scale = 0.0"));
    assert_eq!(field, "joint[0].device");
    let (_, field, _) = invalid(&with(
        "ratio = 0.5 }",
        "ratio = 0.5 }\nglove = { offset = 0.1 }",
    ));
    assert_eq!(field, "joint[1].glove");
    let (_, field, _) = invalid(&with("to = \"a\"", "to = \"b\""));
    assert_eq!(field, "joint[1].coupled.to");
    let (_, field, _) = invalid(&with("axis = [-1.0, 0.0, 0.0]", "axis = [0.0, 0.0, 0.0]"));
    assert_eq!(field, "finger[0].link[0].axis");
    let (_, field, _) = invalid(&with(
        "channels = [\"index\"] }",
        "channels = [\"index\"], gains = [1.0, 2.0] }",
    ));
    assert_eq!(field, "joint[0].glove.gains");
    let (_, field, _) = invalid(&with("limits = [0.0, 1.0]", "limits = [0.0, nan]"));
    assert_eq!(field, "joint[0].limits");
}

#[test]
fn shape_errors_keep_toml_line_and_key() {
    let shown = error_of(&with("role = \"flex\"", "role = \"bend\"")).to_string();
    assert!(shown.starts_with("hands/bad.toml: "), "{shown}");
    assert!(
        shown.contains("line 10") && shown.contains("bend"),
        "{shown}"
    );
    let shown = error_of(&with("model_id = 0", "model_id = 0\ncolour = 1")).to_string();
    assert!(shown.contains("colour"), "{shown}");
    let err = HandProfile::load(Path::new("/nonexistent/hand.toml")).unwrap_err();
    assert!(matches!(err, ProfileError::Read { .. }));
    assert!(err
        .to_string()
        .starts_with("/nonexistent/hand.toml: cannot read"));
}

proptest! {
    #[test]
    fn any_text_gives_a_profile_or_an_error(text in "\\PC{0,400}") {
        let _ = HandProfile::from_toml_str(&text, "p.toml");
    }

    #[test]
    fn any_edit_of_a_good_profile_gives_a_profile_or_an_error(
        at in 0usize..GOOD.len(), junk in "[\\[\\]=\".,0-9a-z\\n -]{0,8}"
    ) {
        let mut cut = at;
        while !GOOD.is_char_boundary(cut) { cut -= 1; }
        let text = format!("{}{}{}", &GOOD[..cut], junk, &GOOD[cut..]);
        let _ = HandProfile::from_toml_str(&text, "p.toml");
    }
}

#[test]
fn builtins_by_model_and_profiles_embedded_in_recordings() {
    use std::collections::BTreeMap;
    use teleop_hand_profile::RECORDING_METADATA;
    for (id, name) in [(1, "revo2"), (2, "allegro"), (3, "shadow"), (5, "leap")] {
        assert_eq!(HandProfile::builtin_for_model(id).unwrap().name, name);
    }
    assert!(HandProfile::builtin_for_model(0).is_none());

    let record = |fields: &[(&str, &str)]| {
        vec![
            ("software".to_string(), BTreeMap::new()),
            (
                RECORDING_METADATA.to_string(),
                fields
                    .iter()
                    .map(|(k, v)| (k.to_string(), v.to_string()))
                    .collect::<BTreeMap<_, _>>(),
            ),
        ]
    };
    let none: Vec<(String, BTreeMap<String, String>)> = Vec::new();
    assert!(HandProfile::from_recording_metadata("r.mcap", &none).is_none());
    let good = record(&[("file", "config/hands/x.toml"), ("text", GOOD)]);
    let p = HandProfile::from_recording_metadata("r.mcap", &good)
        .unwrap()
        .unwrap();
    assert_eq!(p.name, "two");
    let bad_text = with("limits = [0.0, 1.0]", "limits = [1.0, 0.0]");
    let bad = record(&[("file", "config/hands/x.toml"), ("text", &bad_text)]);
    let e = HandProfile::from_recording_metadata("r.mcap", &bad)
        .unwrap()
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(
            "r.mcap (metadata hand_profile, from config/hands/x.toml):11: joint[0].limits"
        ),
        "{e}"
    );
    let no_text = record(&[("file", "x")]);
    let e = HandProfile::from_recording_metadata("r.mcap", &no_text)
        .unwrap()
        .unwrap_err()
        .to_string();
    assert!(e.contains("no `text` field"), "{e}");
}

#[test]
fn every_shipped_finger_but_the_shadow_wrist_follows_an_operator_finger_with_a_pad() {
    for name in HandProfile::builtin_names() {
        let p = HandProfile::builtin(name).unwrap();
        for f in &p.fingers {
            if f.name == "wrist" {
                assert_eq!(f.operator, None, "{name}");
                continue;
            }
            assert!(f.operator.is_some(), "{name}.{}", f.name);
            assert!(f.pad_radius > 0.0, "{name}.{}", f.name);
        }
        assert!(p.retarget.scaling > 0.0, "{name}");
    }
}

#[test]
fn pads_operators_and_retarget_defaults_are_checked() {
    let text = include_str!("../../../../config/hands/revo2.toml");
    let cases = [
        (
            text.replace("operator = \"index\"", "operator = \"thumb\""),
            "follows the operator's `thumb` already",
        ),
        (
            text.replacen("operator = \"index\"", "operator = \"elbow\"", 1),
            "`elbow` is not an operator finger",
        ),
        (
            text.replacen("pad_radius = 0.008", "pad_radius = 0.5", 1),
            "is not a pad radius",
        ),
        (
            text.replace("scaling = 1.0", "scaling = -1.0"),
            "retarget.scaling",
        ),
        (
            text.replace("mode = \"pinch\"", "mode = \"magic\""),
            "magic",
        ),
    ];
    for (bad, expect) in cases {
        let e = HandProfile::from_toml_str(&bad, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains(expect), "{e}");
    }
}
