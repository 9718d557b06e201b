//! Property tests: decoders are total, images round-trip, command building
//! never panics and stays in range.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used)]

use proptest::collection::vec;
use proptest::prelude::*;
use teleop_revo2_protocol::{
    config_entries, decode_config_value, multi_command, param_limits, parse_config_value,
    parse_file_name, single_command, ControlMode, FirmwareHeader, Inputs, Joint, JointData,
    MappingEntry, Outputs, PhysicalScale, TactileData, UnitMode, DICTIONARY, JOINT_TX_LEN, RX_LEN,
    TACTILE_TX_LEN,
};

const ASSIGNMENTS: [&[u16]; 4] = [&[0x1A00], &[0x1A00, 0x1A01], &[0x1A01, 0x1A00], &[0x1A01]];

fn arb_mode() -> impl Strategy<Value = ControlMode> {
    prop::sample::select(ControlMode::ALL.to_vec())
}

fn arb_units() -> impl Strategy<Value = UnitMode> {
    prop_oneof![Just(UnitMode::Percent), Just(UnitMode::Physical)]
}

/// Floats biased towards the interesting ranges, plus specials.
fn arb_value() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -1500.0f32..1500.0,
        2 => -70000.0f32..70000.0,
        1 => any::<f32>(),
        1 => prop_oneof![
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
            Just(1000.5f32),
            Just(-1000.5f32),
            Just(65535.4f32),
        ],
    ]
}

proptest! {
    #[test]
    fn unpack_never_panics(bytes in vec(any::<u8>(), 0..256)) {
        let _ = Outputs::unpack(&bytes);
        let _ = JointData::unpack(&bytes);
        let _ = TactileData::unpack(&bytes);
        for assignment in ASSIGNMENTS {
            let _ = Inputs::unpack(&bytes, assignment);
        }
        let _ = Inputs::unpack(&bytes, &[]);
        let _ = FirmwareHeader::parse(&bytes);
        for e in DICTIONARY {
            let _ = decode_config_value(e, &bytes);
        }
    }

    #[test]
    fn unpack_with_arbitrary_assignment_never_panics(
        bytes in vec(any::<u8>(), 0..256),
        assignment in vec(prop_oneof![Just(0x1A00u16), Just(0x1A01), any::<u16>()], 0..4),
    ) {
        let _ = Inputs::unpack(&bytes, &assignment);
        let mut out = bytes.clone();
        let _ = Inputs::default().pack(&mut out, &assignment);
    }

    #[test]
    fn outputs_round_trip(bytes in any::<[u8; RX_LEN]>()) {
        let o = Outputs::unpack(&bytes).unwrap();
        let mut out = [0u8; RX_LEN];
        o.pack(&mut out).unwrap();
        prop_assert_eq!(out, bytes);
        prop_assert_eq!(o.to_array(), bytes);
    }

    #[test]
    fn joint_data_round_trip(bytes in vec(any::<u8>(), JOINT_TX_LEN)) {
        let d = JointData::unpack(&bytes).unwrap();
        let mut out = [0u8; JOINT_TX_LEN];
        d.pack(&mut out).unwrap();
        prop_assert_eq!(&out[..], &bytes[..]);
    }

    #[test]
    fn tactile_data_round_trip(bytes in vec(any::<u8>(), TACTILE_TX_LEN)) {
        let d = TactileData::unpack(&bytes).unwrap();
        let mut out = [0u8; TACTILE_TX_LEN];
        d.pack(&mut out).unwrap();
        prop_assert_eq!(&out[..], &bytes[..]);
    }

    #[test]
    fn inputs_round_trip(
        bytes in vec(any::<u8>(), JOINT_TX_LEN + TACTILE_TX_LEN),
        which in 0usize..3,
    ) {
        let assignment = ASSIGNMENTS[which];
        let len = Inputs::image_len(assignment).unwrap();
        let bytes = &bytes[..len];
        let inputs = Inputs::unpack(bytes, assignment).unwrap();
        prop_assert_eq!(inputs.tactile.is_some(), assignment.contains(&0x1A01));
        let mut out = vec![0u8; len];
        inputs.pack(&mut out, assignment).unwrap();
        prop_assert_eq!(&out[..], bytes);
    }

    #[test]
    fn mapping_entry_round_trip(raw in any::<u32>()) {
        prop_assert_eq!(MappingEntry::decode(raw).encode(), raw);
    }

    #[test]
    fn multi_command_in_range_or_error(
        mode in arb_mode(),
        units in arb_units(),
        targets in proptest::array::uniform6(arb_value()),
        second in proptest::array::uniform6(arb_value()),
    ) {
        let limits = param_limits(mode, units, &PhysicalScale::DEFAULT);
        if let Ok(cmd) = multi_command(mode, targets, second, units) {
            prop_assert_eq!(cmd.mode, mode.to_u8());
            for i in 0..6 {
                prop_assert!((limits.param1.0..=limits.param1.1).contains(&cmd.param1[i]));
                prop_assert!((limits.param2.0..=limits.param2.1).contains(&cmd.param2[i]));
            }
        }
        let s = single_command(mode, Joint::Ring, targets[0], second[0], units);
        if let Ok(cmd) = s {
            prop_assert!((limits.param1.0..=limits.param1.1).contains(&cmd.param1));
            prop_assert!((limits.param2.0..=limits.param2.1).contains(&cmd.param2));
        }
    }

    #[test]
    fn in_range_commands_are_accepted(
        mode in arb_mode(),
        units in arb_units(),
        a in 0.0f32..=1.0,
        b in 0.0f32..=1.0,
    ) {
        let l = param_limits(mode, units, &PhysicalScale::DEFAULT);
        let p1 = f32::from(l.param1.0) + a * (f32::from(l.param1.1) - f32::from(l.param1.0));
        let p2 = f32::from(l.param2.0) + b * (f32::from(l.param2.1) - f32::from(l.param2.0));
        prop_assert!(multi_command(mode, [p1; 6], [p2; 6], units).is_ok());
    }

    #[test]
    fn config_parsing_never_panics(which in any::<prop::sample::Index>(), text in ".{0,24}") {
        let names: Vec<&str> = config_entries().map(|e| e.name).collect();
        let name = names[which.index(names.len())];
        let _ = parse_config_value(name, &text);
        let _ = parse_file_name(&text);
    }
}
