//! The hand behind the servos, over the real pty: brought up as the LEAP API does it (mode 5
//! with the torque off, torque on, gains, Goal Current, goals by Sync Write), free fingers
//! reach their goals, a finger closing on the ball stops at it with its current rising to Goal
//! Current while its position error stays, a servo with the torque off stays limp.
#![allow(clippy::unwrap_used)]

mod common;

use std::f64::consts::PI;
use std::time::{Duration, Instant};

use common::{wait_for, Host, Sim, BAUD};
use teleop_leap_protocol::packet;
use teleop_leap_protocol::xc330::{self, State};

const ALL: [u8; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15];
const GOAL_CURRENT_MA: i32 = 350;

/// Counts of a URDF angle.
fn counts(rad: f64) -> i32 {
    2048 + (rad * 4096.0 / (2.0 * PI)).round() as i32
}

/// The LEAP API's bring-up: mode 5 (torque off), torque on per servo, gains, Goal Current.
fn bring_up(host: &mut Host) {
    let each = |v: i32| ALL.iter().map(|&id| (id, v)).collect::<Vec<_>>();
    host.sync_write(xc330::OPERATING_MODE, &each(5), 1);
    for id in ALL {
        assert_eq!(host.write(id, xc330::TORQUE_ENABLE, &[1]), 0);
    }
    host.sync_write(xc330::POSITION_P_GAIN, &each(800), 2);
    host.sync_write(xc330::POSITION_I_GAIN, &each(0), 2);
    host.sync_write(xc330::POSITION_D_GAIN, &each(200), 2);
    host.sync_write(xc330::GOAL_CURRENT, &each(GOAL_CURRENT_MA), 2);
}

/// Every servo's state, by one Fast Sync Read.
fn states(host: &mut Host) -> Vec<State> {
    host.fast_sync_read(xc330::STATE_ADDR, xc330::STATE_LEN, &ALL)
        .iter()
        .map(|(_, _, d)| State::decode(d).unwrap())
        .collect()
}

/// Polls the hand at about 50 Hz for `seconds`, as a host does; the last states.
fn run(host: &mut Host, seconds: f64) -> Vec<State> {
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut last = states(host);
    while Instant::now() < end {
        std::thread::sleep(Duration::from_millis(20));
        last = states(host);
    }
    last
}

/// The index finger's flexing joints (1, 2, 3) closed near their upper limits, the rest flat.
fn close_index(host: &mut Host) -> [i32; 16] {
    let mut goals = [2048; 16];
    goals[1] = counts(2.0);
    goals[2] = counts(1.7);
    goals[3] = counts(1.8);
    goals[0] = counts(0.3);
    let values: Vec<(u8, i32)> = ALL.iter().map(|&id| (id, goals[usize::from(id)])).collect();
    host.sync_write(xc330::GOAL_POSITION, &values, 4);
    goals
}

#[test]
fn free_fingers_reach_their_goals_in_current_based_position_mode() {
    let sim = Sim::start(&["--object", "none"]);
    let mut host = sim.host(BAUD);
    bring_up(&mut host);
    let goals = close_index(&mut host);
    let s = wait_for(Duration::from_secs(20), "the goals", || {
        let s = run(&mut host, 0.1);
        s.iter()
            .zip(&goals)
            .all(|(s, g)| (s.position - g).abs() <= 10)
            .then_some(s)
    });
    for (j, st) in s.iter().enumerate() {
        assert!(
            i32::from(st.current_ma).abs() < 60,
            "joint {j} at rest needs little current: {s:?}"
        );
    }
}

#[test]
fn a_finger_closing_on_the_ball_stops_at_it_with_its_current_rising() {
    let sim = Sim::start(&["--object", "ball"]);
    let mut host = sim.host(BAUD);
    bring_up(&mut host);
    let goals = close_index(&mut host);
    let first = run(&mut host, 0.05);
    let s = run(&mut host, 2.0);
    let closure: f64 = [1, 2, 3]
        .iter()
        .map(|&j| f64::from(s[j].position - 2048) * 2.0 * PI / 4096.0)
        .sum();
    assert!(
        (1.5..1.7).contains(&closure),
        "the finger stops at the ball (closure 1.5 rad): {closure} {s:?}"
    );
    for j in [1, 2, 3] {
        assert!(
            goals[j] - s[j].position > 200,
            "joint {j} keeps its position error: {s:?}"
        );
        assert!(
            i32::from(s[j].current_ma) >= GOAL_CURRENT_MA - 20,
            "joint {j} pushes with Goal Current: {s:?}"
        );
        assert!(s[j].current_ma >= first[j].current_ma);
    }
    assert!(
        (s[0].position - goals[0]).abs() <= 10,
        "the side joint is free: {s:?}"
    );
    let stats = sim.stats();
    assert!(stats["contact"].starts_with("0.1"), "{stats:?}");
    // Taking the ball away lets the finger reach its goals.
    sim.control_ok("object none");
    wait_for(
        Duration::from_secs(20),
        "the goals without the ball",
        || {
            let s = run(&mut host, 0.1);
            [1, 2, 3]
                .iter()
                .all(|&j| (s[j].position - goals[j]).abs() <= 10)
                .then_some(())
        },
    );
}

#[test]
fn with_the_torque_off_a_joint_stays_where_it_is() {
    let sim = Sim::start(&["--object", "none"]);
    let mut host = sim.host(BAUD);
    bring_up(&mut host);
    close_index(&mut host);
    let moved = run(&mut host, 1.5);
    for id in ALL {
        host.write(id, xc330::TORQUE_ENABLE, &[0]);
    }
    let before = run(&mut host, 0.1);
    let after = run(&mut host, 0.5);
    for j in 0..16 {
        assert!(
            (after[j].position - before[j].position).abs() <= 2,
            "{after:?}"
        );
        assert_eq!(after[j].current_ma, 0);
    }
    assert!(moved[1].position > 2500);
    // Torque on again holds where it is (Goal Position = Present Position).
    host.write(1, xc330::TORQUE_ENABLE, &[1]);
    assert_eq!(
        host.read(1, xc330::GOAL_POSITION, 4).value(),
        i64::from(after[1].position)
    );
    host.send(|out| packet::ping(1, out));
    assert_eq!(host.status().error, 0);
}
