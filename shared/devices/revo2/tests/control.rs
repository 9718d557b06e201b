//! Control modes, command building, unit conversions and tactile units.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used)]

use teleop_revo2_protocol::{
    current_ma_to_percent, current_percent_to_ma, direction, multi_command, multi_command_scaled,
    newtons, normalised_to_percent, param_limits, percent_to_normalised, single_command,
    CommandError, ControlMode, Joint, JointRange, PhysicalScale, TouchStatus, UnitMode,
    DEFAULT_JOINT_RANGES,
};

#[test]
fn modes() {
    for (v, mode) in (1u8..=5).zip(ControlMode::ALL) {
        assert_eq!(ControlMode::from_u8(v), Some(mode));
        assert_eq!(mode.to_u8(), v);
    }
    assert_eq!(ControlMode::from_u8(0), None);
    assert_eq!(ControlMode::from_u8(6), None);
    assert_eq!(
        ControlMode::PositionTime.param_meaning(),
        ("target position", "movement time (ms)")
    );
    assert_eq!(ControlMode::Current.param_meaning().1, "none");
    assert!(ControlMode::PositionSpeed.has_param2());
    assert!(!ControlMode::Pwm.has_param2());
    assert_eq!(UnitMode::from_u8(0), Some(UnitMode::Percent));
    assert_eq!(UnitMode::from_u8(1), Some(UnitMode::Physical));
    assert_eq!(UnitMode::from_u8(2), None);
}

#[test]
fn percent_position_time() {
    let cmd = multi_command(
        ControlMode::PositionTime,
        [0.0, 1000.0, 500.4, 500.6, 1.0, 999.0],
        [0.0, 65535.0, 100.0, 1.0, 2.0, 3.0],
        UnitMode::Percent,
    )
    .unwrap();
    assert_eq!(cmd.mode, 1);
    assert_eq!(cmd.param1, [0, 1000, 500, 501, 1, 999]);
    assert_eq!(cmd.param2, [0, 65535, 100, 1, 2, 3]);

    let err = multi_command(
        ControlMode::PositionTime,
        [0.0, 1001.0, 0.0, 0.0, 0.0, 0.0],
        [0.0; 6],
        UnitMode::Percent,
    );
    assert!(matches!(
        err,
        Err(CommandError::OutOfRange {
            joint: Joint::ThumbAbduct,
            param: 1,
            min: 0,
            max: 1000,
            ..
        })
    ));
    let err = multi_command(
        ControlMode::PositionTime,
        [0.0; 6],
        [0.0, 0.0, 0.0, 0.0, 0.0, -1.0],
        UnitMode::Percent,
    );
    assert!(matches!(
        err,
        Err(CommandError::OutOfRange {
            joint: Joint::Pinky,
            param: 2,
            ..
        })
    ));
}

#[test]
fn percent_signed_modes() {
    for mode in [ControlMode::Speed, ControlMode::Current, ControlMode::Pwm] {
        let cmd = multi_command(
            mode,
            [-1000.0, 1000.0, 0.0, -1.0, 1.0, 250.0],
            [f32::NAN; 6], // ignored
            UnitMode::Percent,
        )
        .unwrap();
        assert_eq!(cmd.param1, [-1000, 1000, 0, -1, 1, 250]);
        assert_eq!(cmd.param2, [0; 6]);
        assert!(multi_command(mode, [-1001.0; 6], [0.0; 6], UnitMode::Percent).is_err());
    }
    // Position + speed: speed is a magnitude.
    assert!(multi_command(
        ControlMode::PositionSpeed,
        [0.0; 6],
        [-1.0; 6],
        UnitMode::Percent
    )
    .is_err());
    assert!(multi_command(
        ControlMode::PositionSpeed,
        [0.0; 6],
        [1001.0; 6],
        UnitMode::Percent
    )
    .is_err());
}

#[test]
fn physical_mode() {
    let cmd = multi_command(
        ControlMode::PositionSpeed,
        [45.0, 90.0, 0.0, 1000.0, 32767.0, 10.2],
        [180.0, 0.0, 65535.0, 1.0, 1.0, 1.0],
        UnitMode::Physical,
    )
    .unwrap();
    assert_eq!(cmd.param1, [45, 90, 0, 1000, 32767, 10]);
    assert_eq!(cmd.param2, [180, 0, 65535, 1, 1, 1]);
    // Current limited to ±1000 mA, PWM always ±1000.
    assert!(multi_command(
        ControlMode::Current,
        [1000.0; 6],
        [0.0; 6],
        UnitMode::Physical
    )
    .is_ok());
    assert!(multi_command(
        ControlMode::Current,
        [1001.0; 6],
        [0.0; 6],
        UnitMode::Physical
    )
    .is_err());
    assert!(multi_command(ControlMode::Pwm, [1001.0; 6], [0.0; 6], UnitMode::Physical).is_err());
    assert!(multi_command(
        ControlMode::Speed,
        [-32768.0; 6],
        [0.0; 6],
        UnitMode::Physical
    )
    .is_ok());
    assert!(multi_command(
        ControlMode::PositionTime,
        [-1.0; 6],
        [0.0; 6],
        UnitMode::Physical
    )
    .is_err());
}

#[test]
fn physical_scale_is_applied() {
    let scale = PhysicalScale {
        position_per_deg: 10.0,
        speed_per_deg_s: 2.0,
        current_per_ma: 0.5,
    };
    let cmd = multi_command_scaled(
        ControlMode::PositionSpeed,
        [45.5; 6],
        [100.0; 6],
        UnitMode::Physical,
        &scale,
    )
    .unwrap();
    assert_eq!(cmd.param1, [455; 6]);
    assert_eq!(cmd.param2, [200; 6]);
    let cmd = multi_command_scaled(
        ControlMode::Current,
        [-1000.0; 6],
        [0.0; 6],
        UnitMode::Physical,
        &scale,
    )
    .unwrap();
    assert_eq!(cmd.param1, [-500; 6]);
    assert_eq!(
        param_limits(ControlMode::Current, UnitMode::Physical, &scale).param1,
        (-500, 500)
    );
    // Percent mode ignores the scale.
    let cmd = multi_command_scaled(
        ControlMode::PositionTime,
        [500.0; 6],
        [10.0; 6],
        UnitMode::Percent,
        &scale,
    )
    .unwrap();
    assert_eq!(cmd.param1, [500; 6]);
}

#[test]
fn non_finite_refused() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut targets = [0.0; 6];
        targets[3] = bad;
        assert!(matches!(
            multi_command(
                ControlMode::PositionTime,
                targets,
                [0.0; 6],
                UnitMode::Percent
            ),
            Err(CommandError::NotFinite {
                joint: Joint::Middle,
                param: 1,
                ..
            })
        ));
    }
    // Overflow to infinity by a huge scale is out of range, not a panic.
    let scale = PhysicalScale {
        position_per_deg: f32::MAX,
        ..PhysicalScale::DEFAULT
    };
    assert!(multi_command_scaled(
        ControlMode::PositionTime,
        [10.0; 6],
        [0.0; 6],
        UnitMode::Physical,
        &scale
    )
    .is_err());
}

#[test]
fn single_finger() {
    let cmd = single_command(
        ControlMode::PositionTime,
        Joint::Ring,
        800.0,
        300.0,
        UnitMode::Percent,
    )
    .unwrap();
    assert_eq!(
        (cmd.mode, cmd.joint, cmd.param1, cmd.param2),
        (1, 4, 800, 300)
    );
    assert!(single_command(
        ControlMode::Pwm,
        Joint::Index,
        2000.0,
        0.0,
        UnitMode::Percent
    )
    .is_err());
}

#[test]
fn conversions() {
    assert_eq!(normalised_to_percent(0.0), 0);
    assert_eq!(normalised_to_percent(0.5), 500);
    assert_eq!(normalised_to_percent(1.0), 1000);
    assert_eq!(normalised_to_percent(-3.0), 0);
    assert_eq!(normalised_to_percent(7.0), 1000);
    assert_eq!(normalised_to_percent(f32::NAN), 0);
    assert_eq!(percent_to_normalised(250), 0.25);
    assert_eq!(percent_to_normalised(5000), 1.0);
    assert_eq!(current_percent_to_ma(-1000), -1000.0);
    assert_eq!(current_percent_to_ma(123), 123.0);
    assert_eq!(current_ma_to_percent(2000.0), 1000);
    assert_eq!(current_ma_to_percent(-250.4), -250);
    assert_eq!(current_ma_to_percent(f32::NAN), 0);

    let r = JointRange::default_for(Joint::ThumbFlex);
    assert_eq!(r, DEFAULT_JOINT_RANGES[0]);
    assert_eq!((r.min_deg, r.max_deg), (0.0, 90.0));
    assert_eq!(r.percent_to_degrees(500), 45.0);
    assert_eq!(r.degrees_to_percent(90.0), 1000);
    assert_eq!(r.degrees_to_percent(-10.0), 0);
    let custom = JointRange {
        min_deg: 10.0,
        max_deg: 110.0,
    };
    assert_eq!(custom.percent_to_degrees(0), 10.0);
    assert_eq!(custom.degrees_to_percent(60.0), 500);
    let empty = JointRange {
        min_deg: 5.0,
        max_deg: 5.0,
    };
    assert_eq!(empty.degrees_to_percent(5.0), 0);
}

#[test]
fn tactile_units() {
    assert_eq!(newtons(1000), 10.0);
    assert_eq!(newtons(0), 0.0);
    assert!((newtons(2500) - 25.0).abs() < 1e-4);
    assert_eq!(direction(0), Some(0));
    assert_eq!(direction(359), Some(359));
    assert_eq!(direction(360), None);
    assert_eq!(direction(0xFFFF), None);
    let s = TouchStatus(0x2A00);
    assert_eq!((s.bits(), s.counter()), (0, 0x2A));
    assert!(s.is_valid());
    assert!(TouchStatus(0x2A08).is_valid()); // undocumented bit 3
    for (raw, invalid, stale, timeout) in [
        (0x0001, true, false, false),
        (0x0002, false, true, false),
        (0x0004, false, false, true),
    ] {
        let s = TouchStatus(raw);
        assert_eq!(
            (s.invalid_raw(), s.not_updated(), s.timed_out()),
            (invalid, stale, timeout)
        );
        assert!(!s.is_valid());
    }
    assert!(TouchStatus(0x0100).updated_since(TouchStatus(0x0000)));
    assert!(!TouchStatus(0x0101).updated_since(TouchStatus(0x0100)));
}
