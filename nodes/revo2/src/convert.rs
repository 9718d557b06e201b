//! Pure conversions between the message contract and the Revo2 process data: hand commands to
//! outputs (with joint limits), the hold command, and inputs to hand state and tactile samples.

use teleop_msgs::{
    control_mode, fingertip_sensor, hand_model, link_kind, units, Fingertip, HandCommand,
    HandState, Tactile,
};
use teleop_revo2_protocol::{
    direction, newtons, ControlMode, Inputs, JointData, MultiFingerCommand, Outputs, TouchStatus,
    UnitMode, DEFAULT_JOINT_RANGES, JOINTS,
};

use crate::config::Revo2Config;

/// Outputs for `cmd`, and how many targets were clamped to the configured joint limits.
/// `None` when the command is not for a Revo2 or has a mode the Revo2 lacks.
pub fn outputs_for(cmd: &HandCommand, config: &Revo2Config) -> Option<(Outputs, u32)> {
    if cmd.hand_model != hand_model::REVO2 || usize::from(cmd.joint_count) < JOINTS {
        return None;
    }
    if cmd.units != units::NORMALISED {
        return None;
    }
    let full = config.full_speed_travel_per_s;
    let per_mille = |x: f32| (x * 1000.0).round().clamp(-1000.0, 1000.0);
    let mut clamps = 0;
    let mut multi = MultiFingerCommand::default();
    for j in 0..JOINTS {
        let joint = cmd.joints[j];
        let (p1, p2) = match cmd.control_mode {
            control_mode::POSITION | control_mode::POSITION_TIME => {
                let target = if joint.target.is_finite() {
                    joint.target
                } else {
                    0.0
                };
                let limited = target.clamp(config.joint_min[j], config.joint_max[j]);
                if limited != target {
                    clamps += 1;
                }
                let second = if cmd.control_mode == control_mode::POSITION {
                    // Speed limit in travel per second -> per mille of full speed (0 = none).
                    if joint.speed_limit > 0.0 {
                        per_mille(joint.speed_limit / full).max(1.0)
                    } else {
                        1000.0
                    }
                } else {
                    joint.speed_limit.clamp(0.0, 65535.0).round()
                };
                (per_mille(limited), second)
            }
            control_mode::VELOCITY => (per_mille(joint.target / full), 0.0),
            control_mode::EFFORT | control_mode::DUTY => (per_mille(joint.target), 0.0),
            _ => return None,
        };
        multi.param1[j] = p1 as i16;
        multi.param2[j] = p2 as u16;
    }
    let mode = match cmd.control_mode {
        control_mode::POSITION => ControlMode::PositionSpeed,
        control_mode::POSITION_TIME => ControlMode::PositionTime,
        control_mode::VELOCITY => ControlMode::Speed,
        control_mode::EFFORT => ControlMode::Current,
        _ => ControlMode::Pwm,
    };
    multi.mode = mode as u8;
    Some((
        Outputs {
            multi,
            ..Default::default()
        },
        clamps,
    ))
}

/// Position + speed command to where the joints are now: the hand holds.
pub fn hold_outputs(joints: &JointData, unit_mode: UnitMode, speed_per_mille: u16) -> Outputs {
    let mut multi = MultiFingerCommand {
        mode: ControlMode::PositionSpeed as u8,
        ..Default::default()
    };
    for j in 0..JOINTS {
        multi.param1[j] = joints.position[j].min(i16::MAX as u16) as i16;
        multi.param2[j] = speed_per_mille;
    }
    let _ = unit_mode; // positions are echoed in the units they were read in
    Outputs {
        multi,
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
        hand_model: hand_model::REVO2,
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
        hand_model: hand_model::REVO2,
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
        let mut c = HandCommand {
            hand_model: hand_model::REVO2,
            joint_count: 6,
            control_mode: control_mode::POSITION,
            units: units::NORMALISED,
            ..Default::default()
        };
        for (j, t) in c.joints.iter_mut().zip(targets) {
            j.target = t;
            j.speed_limit = speed;
        }
        c
    }

    #[test]
    fn position_commands_become_position_speed_outputs_with_limits() {
        let config = Revo2Config {
            joint_max: [1.0, 1.0, 0.6, 1.0, 1.0, 1.0],
            ..Default::default()
        };
        let (out, clamps) =
            outputs_for(&cmd([0.0, 0.5, 0.9, 1.0, 0.25, f32::NAN], 1.0), &config).unwrap();
        assert_eq!(out.multi.mode, ControlMode::PositionSpeed as u8);
        assert_eq!(out.multi.param1, [0, 500, 600, 1000, 250, 0]);
        assert_eq!(
            out.multi.param2, [500; 6],
            "1 travel/s of 2 travel/s full speed"
        );
        assert_eq!(clamps, 1);
        let (out, _) = outputs_for(&cmd([0.5; 6], 0.0), &config).unwrap();
        assert_eq!(out.multi.param2, [1000; 6], "no limit = full speed");
        let mut other = cmd([0.5; 6], 0.0);
        other.hand_model = hand_model::ALLEGRO;
        assert!(outputs_for(&other, &config).is_none());
    }

    #[test]
    fn hold_echoes_the_measured_positions() {
        let joints = JointData {
            position: [10, 20, 30, 40, 50, 60],
            ..Default::default()
        };
        let out = hold_outputs(&joints, UnitMode::Percent, 300);
        assert_eq!(out.multi.param1, [10, 20, 30, 40, 50, 60]);
        assert_eq!(out.multi.param2, [300; 6]);
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
