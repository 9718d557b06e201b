//! Process images: known-answer bytes, round trips, length and assignment
//! errors.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used)]

use teleop_revo2_protocol::{
    image_len, ControlMode, ImageError, Inputs, Joint, JointData, MultiFingerCommand, Outputs,
    SingleFingerCommand, TactileData, DEFAULT_RX_ASSIGNMENT, DEFAULT_TX_ASSIGNMENT,
    JOINT_ONLY_TX_ASSIGNMENT, JOINT_TX_LEN, RX_LEN, TACTILE_TX_LEN,
};

fn sample_outputs() -> Outputs {
    Outputs {
        multi: MultiFingerCommand {
            mode: 2,
            param1: [1, -1, 0x1234, 1000, 0, -1000],
            param2: [0xABCD, 0, 1, 500, 0xFFFF, 2],
        },
        single: SingleFingerCommand {
            mode: 5,
            joint: 3,
            param1: -2,
            param2: 0x0102,
        },
    }
}

const SAMPLE_OUTPUT_BYTES: [u8; RX_LEN] = [
    0x02, // multi mode
    0x01, 0x00, 0xFF, 0xFF, 0x34, 0x12, 0xE8, 0x03, 0x00, 0x00, 0x18, 0xFC, // param1
    0xCD, 0xAB, 0x00, 0x00, 0x01, 0x00, 0xF4, 0x01, 0xFF, 0xFF, 0x02, 0x00, // param2
    0x05, // single mode
    0x03, // joint
    0xFE, 0xFF, // param1
    0x02, 0x01, // param2
];

#[test]
fn outputs_known_answer() {
    let mut out = [0u8; RX_LEN];
    sample_outputs().pack(&mut out).unwrap();
    assert_eq!(out, SAMPLE_OUTPUT_BYTES);
    assert_eq!(sample_outputs().to_array(), SAMPLE_OUTPUT_BYTES);
    assert_eq!(
        Outputs::unpack(&SAMPLE_OUTPUT_BYTES).unwrap(),
        sample_outputs()
    );
}

#[test]
fn outputs_accessors() {
    let o = sample_outputs();
    assert_eq!(o.multi.control_mode(), Some(ControlMode::PositionSpeed));
    assert_eq!(o.single.control_mode(), Some(ControlMode::Pwm));
    assert_eq!(o.single.target_joint(), Some(Joint::Middle));
    let d = Outputs::default();
    assert_eq!(d.multi.control_mode(), None);
    assert_eq!(d.to_array(), [0; RX_LEN]);
    let bad = SingleFingerCommand {
        joint: 6,
        ..SingleFingerCommand::default()
    };
    assert_eq!(bad.target_joint(), None);
}

#[test]
fn outputs_wrong_length() {
    for len in [0, RX_LEN - 1, RX_LEN + 1, 64] {
        let mut buf = vec![0u8; len];
        let err = ImageError::WrongLength {
            expected: RX_LEN,
            got: len,
        };
        assert_eq!(Outputs::default().pack(&mut buf), Err(err));
        assert_eq!(Outputs::unpack(&buf), Err(err));
    }
}

fn sample_joints() -> JointData {
    JointData {
        position: [0, 1, 2, 3, 1000, 0xFFFF],
        speed: [-1, 1, i16::MIN, i16::MAX, 0, 100],
        current: [10, -10, 0, 0x0102, 0, -1000],
        status: [0x8001, 0, 0, 0, 0, 0x00FF],
    }
}

const SAMPLE_JOINT_BYTES: [u8; JOINT_TX_LEN] = [
    0x00, 0x00, 0x01, 0x00, 0x02, 0x00, 0x03, 0x00, 0xE8, 0x03, 0xFF, 0xFF, // position
    0xFF, 0xFF, 0x01, 0x00, 0x00, 0x80, 0xFF, 0x7F, 0x00, 0x00, 0x64, 0x00, // speed
    0x0A, 0x00, 0xF6, 0xFF, 0x00, 0x00, 0x02, 0x01, 0x00, 0x00, 0x18, 0xFC, // current
    0x01, 0x80, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xFF, 0x00, // status
];

#[test]
fn joint_data_known_answer() {
    let mut out = [0u8; JOINT_TX_LEN];
    sample_joints().pack(&mut out).unwrap();
    assert_eq!(out, SAMPLE_JOINT_BYTES);
    assert_eq!(
        JointData::unpack(&SAMPLE_JOINT_BYTES).unwrap(),
        sample_joints()
    );
    assert_eq!(
        JointData::unpack(&SAMPLE_JOINT_BYTES[1..]),
        Err(ImageError::WrongLength {
            expected: 48,
            got: 47
        })
    );
}

fn sample_tactile() -> TactileData {
    TactileData {
        normal: [100, 2500, 0, 1, 0x0203],
        tangential: [0, 0xFFFF, 1000, 0, 0],
        direction: [0, 359, 0xFFFF, 90, 180],
        proximity: [0x0102_0304, 0, 0xFFFF_FFFF, 1, 0x8000_0000],
        touch_status: [0x0100, 0x0001, 0xFF07, 0, 0x1234],
    }
}

const SAMPLE_TACTILE_BYTES: [u8; TACTILE_TX_LEN] = [
    0x64, 0x00, 0xC4, 0x09, 0x00, 0x00, 0x01, 0x00, 0x03, 0x02, // normal
    0x00, 0x00, 0xFF, 0xFF, 0xE8, 0x03, 0x00, 0x00, 0x00, 0x00, // tangential
    0x00, 0x00, 0x67, 0x01, 0xFF, 0xFF, 0x5A, 0x00, 0xB4, 0x00, // direction
    0x04, 0x03, 0x02, 0x01, 0x00, 0x00, 0x00, 0x00, 0xFF, 0xFF, // proximity
    0xFF, 0xFF, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, //
    0x00, 0x01, 0x01, 0x00, 0x07, 0xFF, 0x00, 0x00, 0x34, 0x12, // touch_status
];

#[test]
fn tactile_data_known_answer() {
    let mut out = [0u8; TACTILE_TX_LEN];
    sample_tactile().pack(&mut out).unwrap();
    assert_eq!(out, SAMPLE_TACTILE_BYTES);
    assert_eq!(
        TactileData::unpack(&SAMPLE_TACTILE_BYTES).unwrap(),
        sample_tactile()
    );
    let mut short = [0u8; 59];
    assert_eq!(
        sample_tactile().pack(&mut short),
        Err(ImageError::WrongLength {
            expected: 60,
            got: 59
        })
    );
}

#[test]
fn inputs_with_tactile_known_answer() {
    let mut image = [0u8; JOINT_TX_LEN + TACTILE_TX_LEN];
    image[..JOINT_TX_LEN].copy_from_slice(&SAMPLE_JOINT_BYTES);
    image[JOINT_TX_LEN..].copy_from_slice(&SAMPLE_TACTILE_BYTES);
    let inputs = Inputs {
        joints: sample_joints(),
        tactile: Some(sample_tactile()),
    };
    assert_eq!(
        Inputs::unpack(&image, &DEFAULT_TX_ASSIGNMENT).unwrap(),
        inputs
    );
    let mut out = [0u8; 108];
    inputs.pack(&mut out, &DEFAULT_TX_ASSIGNMENT).unwrap();
    assert_eq!(out, image);
    assert_eq!(Inputs::image_len(&DEFAULT_TX_ASSIGNMENT), Ok(108));
}

#[test]
fn inputs_joint_only_known_answer() {
    let inputs = Inputs {
        joints: sample_joints(),
        tactile: None,
    };
    assert_eq!(
        Inputs::unpack(&SAMPLE_JOINT_BYTES, &JOINT_ONLY_TX_ASSIGNMENT).unwrap(),
        inputs
    );
    let mut out = [0u8; JOINT_TX_LEN];
    inputs.pack(&mut out, &JOINT_ONLY_TX_ASSIGNMENT).unwrap();
    assert_eq!(out, SAMPLE_JOINT_BYTES);
    // The 108-byte image does not fit the joint-only assignment.
    assert_eq!(
        Inputs::unpack(&[0u8; 108], &JOINT_ONLY_TX_ASSIGNMENT),
        Err(ImageError::WrongLength {
            expected: 48,
            got: 108
        })
    );
}

#[test]
fn inputs_reversed_assignment_follows_order() {
    let mut image = [0u8; 108];
    image[..TACTILE_TX_LEN].copy_from_slice(&SAMPLE_TACTILE_BYTES);
    image[TACTILE_TX_LEN..].copy_from_slice(&SAMPLE_JOINT_BYTES);
    let inputs = Inputs::unpack(&image, &[0x1A01, 0x1A00]).unwrap();
    assert_eq!(inputs.joints, sample_joints());
    assert_eq!(inputs.tactile, Some(sample_tactile()));
}

#[test]
fn inputs_pack_missing_tactile_writes_zeros_and_unassigned_is_dropped() {
    let joints_only = Inputs {
        joints: sample_joints(),
        tactile: None,
    };
    let mut out = [0xAAu8; 108];
    joints_only.pack(&mut out, &DEFAULT_TX_ASSIGNMENT).unwrap();
    assert_eq!(out[..48], SAMPLE_JOINT_BYTES);
    assert!(out[48..].iter().all(|&b| b == 0));

    let both = Inputs {
        joints: sample_joints(),
        tactile: Some(sample_tactile()),
    };
    let mut out = [0u8; 48];
    both.pack(&mut out, &JOINT_ONLY_TX_ASSIGNMENT).unwrap();
    assert_eq!(out, SAMPLE_JOINT_BYTES);
}

#[test]
fn inputs_bad_assignments() {
    let image = [0u8; 108];
    assert_eq!(
        Inputs::unpack(&image, &[]),
        Err(ImageError::MissingPdo(0x1A00))
    );
    assert_eq!(
        Inputs::unpack(&image[..60], &[0x1A01]),
        Err(ImageError::MissingPdo(0x1A00))
    );
    assert_eq!(
        Inputs::unpack(&image, &[0x1A00, 0x1A02]),
        Err(ImageError::UnknownPdo(0x1A02))
    );
    assert_eq!(
        Inputs::unpack(&image, &DEFAULT_RX_ASSIGNMENT),
        Err(ImageError::UnknownPdo(0x1600))
    );
    assert_eq!(
        Inputs::unpack(&[0u8; 96], &[0x1A00, 0x1A00]),
        Err(ImageError::DuplicatePdo(0x1A00))
    );
    let mut out = [0u8; 108];
    assert_eq!(
        Inputs::default().pack(&mut out, &[0x1A00, 0x1A01, 0x1A01]),
        Err(ImageError::DuplicatePdo(0x1A01))
    );
    assert_eq!(
        Inputs::image_len(&[0x1A03]),
        Err(ImageError::UnknownPdo(0x1A03))
    );
}

#[test]
fn lengths_agree_with_assignments() {
    assert_eq!(RX_LEN, 31);
    assert_eq!(Outputs::LEN, RX_LEN);
    assert_eq!(JointData::LEN, JOINT_TX_LEN);
    assert_eq!(TactileData::LEN, TACTILE_TX_LEN);
    assert_eq!(image_len(&DEFAULT_RX_ASSIGNMENT), Some(RX_LEN));
    assert_eq!(
        image_len(&DEFAULT_TX_ASSIGNMENT),
        Some(JOINT_TX_LEN + TACTILE_TX_LEN)
    );
    assert_eq!(image_len(&JOINT_ONLY_TX_ASSIGNMENT), Some(JOINT_TX_LEN));
    assert_eq!(
        Inputs::image_len(&DEFAULT_TX_ASSIGNMENT).ok(),
        image_len(&DEFAULT_TX_ASSIGNMENT)
    );
}

#[test]
fn error_messages() {
    assert_eq!(
        ImageError::WrongLength {
            expected: 31,
            got: 30
        }
        .to_string(),
        "process image has 30 bytes, expected 31"
    );
    assert_eq!(
        ImageError::UnknownPdo(0x1A05).to_string(),
        "unknown PDO 0x1A05 in the assignment"
    );
}
