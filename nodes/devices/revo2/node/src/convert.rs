//! Pure conversions between the message contract and the Revo2 process data: admitted hand
//! commands to outputs, the hold command, and inputs to hand state and tactile samples.

use teleop_msgs::{
    control_mode, device_model, fingertip_sensor, link_kind, units, Fingertip, HandCommand,
    HandState, Tactile,
};
use teleop_revo2_protocol::{
    direction, multi_command, newtons, ControlMode, Inputs, JointData, MultiFingerCommand, Outputs,
    TouchStatus, UnitMode, DEFAULT_JOINT_RANGES, JOINTS, MAX_CURRENT_MA, PERCENT_FULL,
};

use crate::config::Revo2Config;

/// Outputs for `cmd`, a command admitted by `teleop-hand-node` (for the Revo2, normalised, a
/// mode it has, every value finite, positions within the hand profile's limits and drives
/// stopped at them), in the device's `units`. `None` when a value does not fit the unit mode's
/// ranges.
///
/// Normalised values become the unit mode's values (percent: per mille of travel, of full speed
/// and of the maximum current; physical: degrees over the joint's range, degrees per second, mA)
/// and go through the protocol crate's unit-aware builder ([`multi_command`]), which checks
/// them against the ranges of that unit mode.
pub fn outputs_for(cmd: &HandCommand, config: &Revo2Config, units: UnitMode) -> Option<Outputs> {
    let mode = match cmd.control_mode {
        control_mode::POSITION => ControlMode::PositionSpeed,
        control_mode::POSITION_TIME => ControlMode::PositionTime,
        control_mode::VELOCITY => ControlMode::Speed,
        control_mode::EFFORT => ControlMode::Current,
        control_mode::DUTY => ControlMode::Pwm,
        _ => return None,
    };
    let full = config.full_speed_travel_per_s;
    let mut targets = [0.0; JOINTS];
    let mut seconds = [0.0; JOINTS];
    for (j, range) in DEFAULT_JOINT_RANGES.iter().enumerate() {
        let joint = cmd.joints[j];
        // Travel (0..1) in the unit mode: per mille, or degrees over the joint's range.
        let (offset, span) = match units {
            UnitMode::Percent => (0.0, f32::from(PERCENT_FULL)),
            UnitMode::Physical => (range.min_deg, range.max_deg - range.min_deg),
        };
        match mode {
            ControlMode::PositionSpeed | ControlMode::PositionTime => {
                targets[j] = offset + span * joint.target;
                seconds[j] = if mode == ControlMode::PositionSpeed {
                    // Speed limit in travel per second (0 = none), at least the smallest step.
                    let of_full = if joint.speed_limit > 0.0 {
                        (joint.speed_limit / full).min(1.0)
                    } else {
                        1.0
                    };
                    match units {
                        UnitMode::Percent => (of_full * span).round().max(1.0),
                        UnitMode::Physical => (of_full * full * span).round().max(1.0),
                    }
                } else {
                    joint.speed_limit.clamp(0.0, 65535.0)
                };
            }
            ControlMode::Speed => {
                let v = joint.target / full;
                targets[j] = match units {
                    UnitMode::Percent => v * span,
                    UnitMode::Physical => v * full * span,
                }
            }
            ControlMode::Current => {
                targets[j] = match units {
                    UnitMode::Percent => joint.target * f32::from(PERCENT_FULL),
                    UnitMode::Physical => joint.target * MAX_CURRENT_MA,
                }
            }
            ControlMode::Pwm => targets[j] = joint.target * f32::from(PERCENT_FULL),
        }
    }
    let multi = multi_command(mode, targets, seconds, units).ok()?;
    Some(Outputs {
        multi,
        ..Default::default()
    })
}

/// The raw position targets of `outputs` when they command positions (position + speed or
/// position + time), in the device's units: what [`hold_outputs`] holds.
pub fn position_targets(outputs: &Outputs) -> Option<[i16; JOINTS]> {
    let mode = ControlMode::from_u8(outputs.multi.mode)?;
    matches!(mode, ControlMode::PositionSpeed | ControlMode::PositionTime)
        .then_some(outputs.multi.param1)
}

/// The hold speed of every joint in the device's `units`: `hold_speed_per_mille` of full speed
/// (physical: of `full_speed_travel_per_s` over the joint's range, in degrees per second).
pub fn hold_speeds(config: &Revo2Config, units: UnitMode) -> [u16; JOINTS] {
    let per_mille = config.hold_speed_per_mille;
    core::array::from_fn(|j| match units {
        UnitMode::Percent => per_mille,
        UnitMode::Physical => {
            let range = DEFAULT_JOINT_RANGES[j];
            let deg_s = f32::from(per_mille) / f32::from(PERCENT_FULL)
                * config.full_speed_travel_per_s
                * (range.max_deg - range.min_deg);
            deg_s.round().clamp(1.0, f32::from(u16::MAX)) as u16
        }
    })
}

/// Position + speed command that holds the hand: at `target`, the last commanded position
/// targets (so a grasped object stays squeezed, with the device's configured protection
/// currents bounding the squeeze), or where the joints are now when no position was commanded;
/// at `speeds` (see [`hold_speeds`]). Both are in the device's units.
pub fn hold_outputs(
    target: Option<&[i16; JOINTS]>,
    joints: &JointData,
    speeds: &[u16; JOINTS],
) -> Outputs {
    let measured: [i16; JOINTS] =
        core::array::from_fn(|j| joints.position[j].min(i16::MAX as u16) as i16);
    Outputs {
        multi: MultiFingerCommand {
            mode: ControlMode::PositionSpeed as u8,
            param1: *target.unwrap_or(&measured),
            param2: *speeds,
        },
        ..Default::default()
    }
}

/// Normalised joint position (0 open .. 1 closed) from the device's reading.
pub fn normalised_position(raw: u16, joint: usize, unit_mode: UnitMode) -> f32 {
    let per_mille = match unit_mode {
        UnitMode::Percent => raw,
        UnitMode::Physical => DEFAULT_JOINT_RANGES[joint].degrees_to_percent(f32::from(raw)),
    };
    (f32::from(per_mille) / 1000.0).clamp(0.0, 1.0)
}

/// The hand state message for these inputs (link fields are filled by the caller).
pub fn hand_state(inputs: &Inputs, unit_mode: UnitMode, full_speed: f32) -> HandState {
    let mut state = HandState {
        hand_model: device_model::REVO2,
        joint_count: JOINTS as u8,
        units: units::NORMALISED,
        link_kind: link_kind::ETHERCAT,
        ..Default::default()
    };
    let j = &inputs.joints;
    for (i, range) in DEFAULT_JOINT_RANGES.iter().enumerate() {
        let speed = match unit_mode {
            UnitMode::Percent => f32::from(j.speed[i]) / 1000.0 * full_speed,
            UnitMode::Physical => f32::from(j.speed[i]) / (range.max_deg - range.min_deg).max(1.0),
        };
        state.joints[i] = teleop_msgs::JointState {
            position: normalised_position(j.position[i], i, unit_mode),
            speed,
            // The Revo2 neither measures nor estimates joint torque.
            effort: f32::NAN,
            // Percentage mode reports current as per mille of 1000 mA, i.e. mA.
            current_ma: f32::from(j.current[i]),
            status: u32::from(j.status[i]),
        };
    }
    state
}

/// The tactile message for these inputs (`None` without tactile data).
pub fn tactile(inputs: &Inputs) -> Option<Tactile> {
    let t = inputs.tactile.as_ref()?;
    let mut msg = Tactile {
        hand_model: device_model::REVO2,
        fingertip_count: 5,
        ..Default::default()
    };
    for i in 0..5 {
        let status = TouchStatus(t.touch_status[i]);
        let dir = direction(t.direction[i]);
        msg.fingertips[i] = Fingertip {
            normal_n: newtons(t.normal[i]),
            tangential_n: newtons(t.tangential[i]),
            direction_deg: dir.map_or(0.0, f32::from),
            proximity: t.proximity[i],
            status: status.bits(),
            update_counter: status.counter(),
            direction_valid: u8::from(dir.is_some()),
            pressure: 0,
            temperature: 0,
            sensor_kind: fingertip_sensor::REVO2_FORCE,
        };
    }
    Some(msg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use teleop_revo2_protocol::TactileData;

    fn cmd(targets: [f32; 6], speed: f32) -> HandCommand {
        teleop_e2e::revo2_position_command(targets, speed)
    }

    #[test]
    fn position_commands_become_position_speed_outputs() {
        let config = Revo2Config::default();
        let out = outputs_for(
            &cmd([0.0, 0.5, 0.6, 1.0, 0.25, 0.0], 1.0),
            &config,
            UnitMode::Percent,
        )
        .unwrap();
        assert_eq!(out.multi.mode, ControlMode::PositionSpeed as u8);
        assert_eq!(out.multi.param1, [0, 500, 600, 1000, 250, 0]);
        assert_eq!(
            out.multi.param2, [500; 6],
            "1 travel/s of 2 travel/s full speed"
        );
        let out = outputs_for(&cmd([0.5; 6], 0.0), &config, UnitMode::Percent).unwrap();
        assert_eq!(out.multi.param2, [1000; 6], "no limit = full speed");
    }

    /// The Revo2's own joint ranges (the protocol's `DEFAULT_JOINT_RANGES`, 0..90 degrees) hold
    /// the shipped profile's limits, and the profile's open and closed angles are the ends of
    /// the device's travel (0 and 1000 per mille), so normalised commands span the travel.
    #[test]
    fn the_profile_limits_lie_within_the_devices_joint_ranges() {
        let profile = teleop_hand_profile::HandProfile::builtin("revo2").unwrap();
        assert_eq!(profile.joints.len(), JOINTS);
        for (joint, range) in profile.joints.iter().zip(DEFAULT_JOINT_RANGES) {
            let (lo, hi) = (joint.lower.to_degrees(), joint.upper.to_degrees());
            assert!(
                range.min_deg <= lo + 1e-3 && hi <= range.max_deg + 1e-3,
                "{}: profile {lo}..{hi} degrees, device {}..{}",
                joint.name,
                range.min_deg,
                range.max_deg
            );
            assert!(
                (joint.open.to_degrees() - range.min_deg).abs() < 1e-3,
                "{}",
                joint.name
            );
            assert!(
                (joint.closed.to_degrees() - range.max_deg).abs() < 1e-3,
                "{}",
                joint.name
            );
        }
    }

    #[test]
    fn physical_units_go_out_in_degrees_and_degrees_per_second() {
        let config = Revo2Config::default();
        let out = outputs_for(
            &cmd([0.0, 0.5, 1.0, 0.25, 0.5, 0.5], 1.0),
            &config,
            UnitMode::Physical,
        )
        .unwrap();
        // 0..90 degrees per joint: half travel is 45 degrees (not 500 per mille).
        assert_eq!(out.multi.param1, [0, 45, 90, 23, 45, 45]);
        // 1 travel/s of 2 travel/s full speed over 90 degrees: 90 degrees per second.
        assert_eq!(out.multi.param2, [90; 6]);
        let mut effort = cmd([0.5; 6], 0.0);
        effort.control_mode = control_mode::EFFORT;
        let out = outputs_for(&effort, &config, UnitMode::Physical).unwrap();
        assert_eq!(
            out.multi.param1, [500; 6],
            "half the maximum current, in mA"
        );
        let mut velocity = cmd([-1.0; 6], 0.0);
        velocity.control_mode = control_mode::VELOCITY;
        let out = outputs_for(&velocity, &config, UnitMode::Physical).unwrap();
        assert_eq!(
            out.multi.param1, [-90; 6],
            "half of full speed over 90 degrees"
        );
        let out = outputs_for(&velocity, &config, UnitMode::Percent).unwrap();
        assert_eq!(out.multi.param1, [-500; 6]);
    }

    #[test]
    fn hold_keeps_the_last_commanded_target_else_the_measured_position() {
        let joints = JointData {
            position: [10, 20, 30, 40, 50, 60],
            ..Default::default()
        };
        let config = Revo2Config::default();
        let speeds = hold_speeds(&config, UnitMode::Percent);
        let out = hold_outputs(None, &joints, &speeds);
        assert_eq!(out.multi.param1, [10, 20, 30, 40, 50, 60]);
        assert_eq!(out.multi.param2, [300; 6]);
        // A grasp: the target lies past where the object stopped the fingers.
        let grasp = outputs_for(&cmd([0.8; 6], 1.0), &config, UnitMode::Percent).unwrap();
        let target = position_targets(&grasp).unwrap();
        let out = hold_outputs(Some(&target), &joints, &speeds);
        assert_eq!(out.multi.mode, ControlMode::PositionSpeed as u8);
        assert_eq!(out.multi.param1, [800; 6], "the squeeze stays");
        assert_eq!(out.multi.param2, [300; 6], "at the hold speed");
        let mut velocity = cmd([0.5; 6], 0.0);
        velocity.control_mode = control_mode::VELOCITY;
        let moving = outputs_for(&velocity, &config, UnitMode::Percent).unwrap();
        assert_eq!(position_targets(&moving), None, "no position to hold");
        // 300 per mille of 2 travel/s over 90 degrees.
        assert_eq!(hold_speeds(&config, UnitMode::Physical), [54; 6]);
    }

    #[test]
    fn inputs_become_messages() {
        let inputs = Inputs {
            joints: JointData {
                position: [0, 250, 500, 750, 1000, 1200],
                current: [100, 0, 0, 0, 0, 0],
                ..Default::default()
            },
            tactile: Some(TactileData {
                normal: [230, 0, 0, 0, 0],
                direction: [90, 0xFFFF, 0, 0, 0],
                touch_status: [0x0501, 0, 0, 0, 0],
                ..Default::default()
            }),
        };
        let s = hand_state(&inputs, UnitMode::Percent, 2.0);
        let p: Vec<f32> = s.active_joints().iter().map(|j| j.position).collect();
        assert_eq!(p, vec![0.0, 0.25, 0.5, 0.75, 1.0, 1.0]);
        assert_eq!(s.joints[0].current_ma, 100.0);
        assert!(s.active_joints().iter().all(|j| j.effort.is_nan()));
        assert_eq!(s.link_kind, link_kind::ETHERCAT);
        let t = tactile(&inputs).unwrap();
        assert!(t
            .active_fingertips()
            .iter()
            .all(|f| f.sensor_kind == fingertip_sensor::REVO2_FORCE));
        assert!((t.fingertips[0].normal_n - 2.3).abs() < 1e-6);
        assert_eq!(
            (t.fingertips[0].status, t.fingertips[0].update_counter),
            (1, 5)
        );
        assert!(!t.fingertips[0].is_valid());
        assert_eq!(t.fingertips[0].direction_valid, 1);
        assert_eq!(t.fingertips[1].direction_valid, 0);
    }
}
