//! The LEAP Hand's profile (`config/hands/leap.toml`) against the hand it describes:
//! - its kinematic chains, read as `teleop_hand_profile::Finger` and `Link` document them, give the
//!   fingertips the URDF gives (the URDF's own joint origins and fixed rotations, transcribed
//!   below, with dex-urdf's fingertip frames), to 1e-6 m, at zero and at random joint angles;
//! - its joints are in motor-ID order, its counts are the protocol crate's (2048 = 0 rad), and
//!   every limit is a servo position inside one turn of the control table's position limits;
//! - the file and the compiled-in copy (`HandProfile::builtin("leap")`) are the same profile.
//!
//! Sources: docs/devices/leap.md, "Kinematics" (URDF, tip frames, the hand frame, test vectors)
//! and "Joints and IDs".

#![allow(clippy::unwrap_used)]
// The URDF's angles are pi/2 give or take an ulp or two: written as the URDF has them.
#![allow(clippy::approx_constant)]

use std::f64::consts::{FRAC_PI_2, PI};
use std::path::Path;

use proptest::prelude::*;
use teleop_hand_profile::{CommandUnits, Finger, HandProfile, Role, GLOVE_FINGERS};
use teleop_leap_protocol::xc330::{self, Range, State};

type V3 = [f64; 3];
type M3 = [[f64; 3]; 3];

/// One revolute joint of the URDF: its name (the motor ID), origin and fixed rotation in the
/// parent link. Every joint of the LEAP URDF turns about (0, 0, -1) of its child link.
struct UrdfJoint {
    id: usize,
    xyz: V3,
    rpy: V3,
}

/// The URDF's revolute axis, the same for all 16 joints.
const URDF_AXIS: V3 = [0.0, 0.0, -1.0];

/// leap-hand/LEAP_Hand_Sim `assets/leap_hand/robot.urdf` (at e8fc513), palm_lower to fingertip,
/// in chain order (MCP forward, MCP side, PIP, DIP), as written there.
const INDEX: [UrdfJoint; 4] = [
    UrdfJoint {
        id: 1,
        xyz: [
            -0.007095249652862546,
            0.023057756134899472,
            -0.01872240357846022,
        ],
        rpy: [1.570796326794895, 1.5707963267948946, 0.0],
    },
    UrdfJoint {
        id: 0,
        xyz: [-0.012200000000000008, 0.038099999999999995, 0.0145],
        rpy: [-FRAC_PI_2, -1.0065212660796337e-15, 1.5707963267948943],
    },
    UrdfJoint {
        id: 2,
        xyz: [
            0.014999999999999968,
            0.014299999999999905,
            -0.012999999999999824,
        ],
        rpy: [1.570796326794896, -1.5707963267948963, 0.0],
    },
    UrdfJoint {
        id: 3,
        xyz: [
            -4.088058249557269e-09,
            -0.03610000421036737,
            0.0002000000000000786,
        ],
        rpy: [
            4.5935029425113685e-17,
            -2.8730071914463795e-16,
            4.439548105392361e-32,
        ],
    },
];

const MIDDLE: [UrdfJoint; 4] = [
    UrdfJoint {
        id: 5,
        xyz: [
            -0.007095249652862539,
            -0.022392243865100525,
            -0.01872240357846023,
        ],
        rpy: [FRAC_PI_2, FRAC_PI_2, 0.0],
    },
    UrdfJoint {
        id: 4,
        xyz: [
            -0.01220000000000002,
            0.03809999999999998,
            0.014500000000000006,
        ],
        rpy: [-FRAC_PI_2, -1.006521276005794e-15, 1.5707963267948943],
    },
    UrdfJoint {
        id: 6,
        xyz: [0.014999999999999975, 0.0143, -0.013000000000000018],
        rpy: [1.570796326794896, -1.5707963267948963, 0.0],
    },
    UrdfJoint {
        id: 7,
        xyz: [
            1.0061396160665481e-16,
            -0.036099999999999854,
            0.0002000000000000786,
        ],
        rpy: [
            4.5935029425113654e-17,
            -2.8730071914463795e-16,
            1.4408183216511869e-31,
        ],
    },
];

const RING: [UrdfJoint; 4] = [
    UrdfJoint {
        id: 9,
        xyz: [
            -0.007095245442639837,
            -0.06784224386510052,
            -0.018722407666402933,
        ],
        rpy: [1.570796326794895, 1.5707963267948946, 0.0],
    },
    UrdfJoint {
        id: 8,
        xyz: [-0.012200000000000004, 0.0381, 0.014499999999999999],
        rpy: [-FRAC_PI_2, -1.006521266079636e-15, 1.5707963267948943],
    },
    UrdfJoint {
        id: 10,
        xyz: [
            0.014999999999999972,
            0.014299999999999952,
            -0.01299999999999996,
        ],
        rpy: [1.570796326794896, -1.5707963267948963, 0.0],
    },
    UrdfJoint {
        id: 11,
        xyz: [
            9.71445146547012e-17,
            -0.03609999999999987,
            0.00020000000000007512,
        ],
        rpy: [
            4.5935029425113685e-17,
            -2.87300719144638e-16,
            1.5565411607615035e-32,
        ],
    },
];

const THUMB: [UrdfJoint; 4] = [
    UrdfJoint {
        id: 12,
        xyz: [
            -0.06939524965286253,
            -0.0012422438651005258,
            -0.021622403578460216,
        ],
        rpy: [-8.238176646493942e-17, 1.5707963267948957, 0.0],
    },
    UrdfJoint {
        id: 13,
        xyz: [
            -2.7755575615628914e-17,
            0.014300000000000005,
            -0.013000000000000012,
        ],
        rpy: [1.570796326794896, -1.5707963267948963, 0.0],
    },
    UrdfJoint {
        id: 14,
        xyz: [0.0, 0.014499999999999966, -0.017000000000000053],
        rpy: [-FRAC_PI_2, 1.6050198443300131e-46, -1.9721522630516625e-31],
    },
    UrdfJoint {
        id: 15,
        xyz: [
            -1.249000902703301e-16,
            0.046599999999999864,
            0.0001999999999999771,
        ],
        rpy: [1.506395849149178e-44, 5.423418723393526e-31, PI],
    },
];

/// dexsuite/dex-urdf `robots/hands/leap_hand/leap_hand_right.urdf` (at 77eb4ac): the fixed
/// `*_tip_head` frames in the last link (fingertip, fingertip_2, fingertip_3, thumb_fingertip).
const FINGER_TIP: V3 = [0.0, -0.048, 0.015];
const THUMB_TIP: V3 = [0.0, -0.06, -0.015];

/// The URDF fingers by the profile's finger name.
fn urdf_finger(name: &str) -> (&'static [UrdfJoint; 4], V3) {
    match name {
        "index" => (&INDEX, FINGER_TIP),
        "middle" => (&MIDDLE, FINGER_TIP),
        "ring" => (&RING, FINGER_TIP),
        "thumb" => (&THUMB, THUMB_TIP),
        other => panic!("the LEAP URDF has no finger {other}"),
    }
}

/// The profile's hand frame (config/hands/leap.toml's header): dex-urdf's `base` link, where
/// palm_lower sits at xyz (0, 0.038, 0.098), rpy (0, -pi/2, 0), in the project's axes (x towards the
/// little finger, y along the fingers, z out of the back of the hand).
fn hand_of_palm(p: V3) -> V3 {
    [-(p[1] + 0.038), p[0] + 0.098, p[2]]
}

fn mul(a: &M3, b: &M3) -> M3 {
    core::array::from_fn(|i| core::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn apply(m: &M3, v: V3) -> V3 {
    core::array::from_fn(|i| (0..3).map(|k| m[i][k] * v[k]).sum())
}

fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn distance(a: V3, b: V3) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// URDF's rpy: roll about x, then pitch about y, then yaw about z, all about fixed axes
/// (R = Rz(yaw) Ry(pitch) Rx(roll)).
fn rpy(r: V3) -> M3 {
    let (sr, cr) = r[0].sin_cos();
    let (sp, cp) = r[1].sin_cos();
    let (sy, cy) = r[2].sin_cos();
    let x = [[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]];
    let y = [[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]];
    let z = [[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]];
    mul(&z, &mul(&y, &x))
}

/// Rotation by `angle` about the unit vector `a` (Rodrigues).
fn about(a: V3, angle: f64) -> M3 {
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    let [x, y, z] = a;
    [
        [c + t * x * x, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, c + t * y * y, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, c + t * z * z],
    ]
}

const IDENTITY: M3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The URDF's fingertip in palm_lower at motor angles `q` (by motor ID): at each joint translate
/// by its xyz, turn by its fixed rpy, then by the joint's angle about its axis.
fn urdf_tip(finger: &str, q: &[f64; 16]) -> V3 {
    let (joints, tip) = urdf_finger(finger);
    let (mut p, mut r) = ([0.0; 3], IDENTITY);
    for j in joints {
        p = add(p, apply(&r, j.xyz));
        r = mul(&mul(&r, &rpy(j.rpy)), &about(URDF_AXIS, q[j.id]));
    }
    add(p, apply(&r, tip))
}

/// A profile finger's fingertip in the hand frame at joint angles `q` (profile joint order), as
/// `Finger` and `Link` document the chain: from the base pose, each link translates by its
/// `origin` from the previous frame, then turns by `ratio` x its joint's angle about its `axis`;
/// the tip is `tip` in the last frame.
fn profile_tip(finger: &Finger, q: &[f64; 16]) -> V3 {
    let f = |v: [f32; 3]| v.map(f64::from);
    let (mut p, mut r) = (f(finger.base), rpy(f(finger.base_rpy)));
    for link in &finger.links {
        p = add(p, apply(&r, f(link.origin)));
        let angle = link.joint.map_or(0.0, |j| q[j]) * f64::from(link.ratio);
        r = mul(&r, &about(f(link.axis), angle));
    }
    add(p, apply(&r, f(finger.tip)))
}

fn shipped() -> HandProfile {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../config/hands/leap.toml");
    HandProfile::load(&path).unwrap()
}

/// Each finger's profile chain against the URDF's, at motor angles `q`.
fn assert_chains_match(profile: &HandProfile, q: &[f64; 16], tolerance: f64) {
    for finger in &profile.fingers {
        let urdf = hand_of_palm(urdf_tip(&finger.name, q));
        let ours = profile_tip(finger, q);
        let d = distance(urdf, ours);
        assert!(
            d < tolerance,
            "{}: profile {ours:?}, URDF {urdf:?}, {d} m apart at {q:?}",
            finger.name
        );
    }
}

#[test]
fn the_chains_reproduce_the_urdf_at_zero() {
    let profile = shipped();
    assert_eq!(profile.fingers.len(), 4);
    assert_chains_match(&profile, &[0.0; 16], 1e-6);
}

proptest! {
    #[test]
    fn the_chains_reproduce_the_urdf_at_any_angles(q in prop::array::uniform16(-PI..PI)) {
        assert_chains_match(&shipped(), &q, 1e-6);
    }
}

#[test]
fn the_chains_give_the_independently_computed_fingertips() {
    // docs/devices/leap.md, "Kinematics": fingertips in palm_lower (URDF angles, dex-urdf tips),
    // computed independently of this test; to 1e-4 m as they are given to 0.1 mm.
    let profile = shipped();
    let finger = |name: &str| profile.fingers.iter().find(|f| f.name == name).unwrap();
    let at = |angles: &[(usize, f64)]| {
        let mut q = [0.0; 16];
        for &(id, a) in angles {
            q[id] = a;
        }
        q
    };
    let cases: [(&str, [f64; 16], V3); 8] = [
        ("index", at(&[]), [0.1301, 0.0077, -0.0195]),
        ("middle", at(&[]), [0.1301, -0.0378, -0.0195]),
        ("ring", at(&[]), [0.1301, -0.0832, -0.0195]),
        ("thumb", at(&[]), [-0.0824, 0.1367, -0.0219]),
        ("index", at(&[(1, 0.5)]), [0.1129, 0.0077, -0.0852]),
        ("index", at(&[(0, 0.5)]), [0.1175, -0.0397, -0.0195]),
        (
            "index",
            at(&[(1, 0.5), (2, 0.5), (3, 0.5)]),
            [0.0620, 0.0077, -0.1231],
        ),
        (
            "thumb",
            at(&[(12, 0.5), (13, 0.5), (14, 0.5), (15, 0.5)]),
            [-0.0186, 0.0737, -0.1026],
        ),
    ];
    for (name, q, palm) in cases {
        let want = hand_of_palm(palm);
        let got = profile_tip(finger(name), &q);
        assert!(
            distance(got, want) < 1e-4,
            "{name} at {q:?}: {got:?}, want {want:?}"
        );
        let urdf = urdf_tip(name, &q);
        assert!(
            distance(urdf, palm) < 1e-4,
            "URDF {name}: {urdf:?}, want {palm:?}"
        );
    }
}

/// Joint names in motor-ID order (docs/devices/leap.md, "Joints and IDs").
const BY_ID: [&str; 16] = [
    "index_mcp_side",
    "index_mcp_forward",
    "index_pip",
    "index_dip",
    "middle_mcp_side",
    "middle_mcp_forward",
    "middle_pip",
    "middle_dip",
    "ring_mcp_side",
    "ring_mcp_forward",
    "ring_pip",
    "ring_dip",
    "thumb_cmc",
    "thumb_axial",
    "thumb_mcp",
    "thumb_ip",
];

#[test]
fn joints_are_in_motor_id_order() {
    let profile = shipped();
    let names: Vec<&str> = profile.joint_names().collect();
    assert_eq!(names, BY_ID);
    for (id, joint) in profile.joints.iter().enumerate() {
        let finger = ["index", "middle", "ring", "thumb"][id / 4];
        assert_eq!(profile.fingers[joint.finger].name, finger, "ID {id}");
    }
    // Each URDF joint (named by its motor ID) drives the profile joint of that index: moving
    // motor `id` alone moves the same fingertip the same way in both.
    for id in 0..16 {
        let mut q = [0.0; 16];
        q[id] = 0.4;
        assert_chains_match(&profile, &q, 1e-6);
        let finger = &profile.fingers[profile.joints[id].finger];
        let moved = distance(profile_tip(finger, &q), profile_tip(finger, &[0.0; 16]));
        // The thumb's axial joint turns the thumb about a line close to its tip.
        assert!(
            moved > 1e-4,
            "{}: motor {id} moves its tip {moved} m",
            BY_ID[id]
        );
    }
}

/// One turn of servo positions: the range of the position limits (Min/Max Position Limit), which
/// Present Position is brought back into at power-up and reboot.
fn one_turn() -> core::ops::RangeInclusive<f32> {
    let limit = |addr| xc330::item_at(addr).unwrap().range;
    match (
        limit(xc330::MIN_POSITION_LIMIT),
        limit(xc330::MAX_POSITION_LIMIT),
    ) {
        (Range::Span(lowest, _), Range::Span(_, highest)) => lowest as f32..=highest as f32,
        other => panic!("position limits {other:?}"),
    }
}

#[test]
fn every_limit_is_a_servo_position_inside_one_turn_and_back() {
    let profile = shipped();
    let turn = one_turn();
    assert_eq!(turn, 0.0..=4095.0);
    // A count is 2 pi / 4096 rad.
    let count_rad = xc330::RAD_PER_COUNT as f32;
    for joint in &profile.joints {
        assert_eq!(joint.device.unit, "count", "{}", joint.name);
        // The profile's counts are the protocol's: 2048 counts (pi, 180 degrees) is the URDF's
        // 0 rad, so a Present Position reads as the protocol's angle less pi.
        for count in [0, 1, 2047, 2048, 2049, 4095] {
            let servo = State {
                position: count,
                ..State::default()
            };
            let urdf = (servo.position_rad() - PI) as f32;
            let ours = joint.from_device(count as f32);
            assert!(
                (ours - urdf).abs() < 1e-5,
                "{}: {count} counts are {ours} rad, the servo's {urdf}",
                joint.name
            );
        }
        for limit in [joint.lower, joint.upper, joint.open, joint.closed] {
            let count = joint.to_device(limit).round();
            assert!(
                turn.contains(&count),
                "{}: {limit} rad is {count} counts",
                joint.name
            );
            let back = joint.from_device(count);
            assert!(
                (back - limit).abs() <= count_rad / 2.0 + 1e-6,
                "{}: {limit} rad -> {count} -> {back}",
                joint.name
            );
        }
    }
    assert_eq!(xc330::COUNTS_PER_REV, 4096);
}

#[test]
fn the_file_is_the_compiled_in_profile_and_says_what_the_hand_is() {
    let profile = shipped();
    assert_eq!(HandProfile::builtin("leap").as_ref(), Some(&profile));
    assert_eq!(HandProfile::builtin_for_model(5).as_ref(), Some(&profile));
    assert_eq!(profile.name, "leap");
    assert_eq!(profile.model_id, 5);
    assert_eq!(profile.command_units, CommandUnits::Radians);
    assert_eq!(profile.fingertips().count(), 0);
    let little = GLOVE_FINGERS.iter().position(|f| *f == "little").unwrap();
    // The glove's little finger drives nothing and feels nothing; the others feel their
    // finger's servos.
    assert!(profile
        .joints
        .iter()
        .all(|j| j.glove.channels.iter().all(|&(c, _)| c != little)));
    for (g, source) in profile.feedback.iter().enumerate() {
        assert_eq!(source.is_none(), g == little, "{}", GLOVE_FINGERS[g]);
        for &j in &source.joints {
            let finger = &profile.fingers[profile.joints[j].finger].name;
            assert_eq!(finger, GLOVE_FINGERS[g], "{}", profile.joints[j].name);
        }
    }
    // Side joints rest at 0 rad: no glove channel spreads the fingers.
    for joint in &profile.joints {
        let rests = joint.role == Role::Abduct;
        assert_eq!(joint.glove.channels.is_empty(), rests, "{}", joint.name);
        if rests {
            assert_eq!(joint.radians(joint.glove.offset), 0.0, "{}", joint.name);
        }
        // Open is flat, closed closes (positive angles close every joint).
        assert_eq!(joint.open, 0.0, "{}", joint.name);
        assert!(joint.closed > joint.open, "{}", joint.name);
    }
}
