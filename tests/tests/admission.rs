//! One admission rule for every hand (ARCHITECTURE.md, "Command admission"): the same bad hand
//! commands go to each hand node (Revo2, Shadow, Allegro, LEAP) running against its simulator,
//! and every hand does what the table says. A command for another hand or none (`UNKNOWN`), in
//! the wrong units, of an unknown mode or one the hand lacks, of another joint count, or with a
//! NaN, +inf or -inf target is refused: the hand holds (`hand/state` says so, the joints stay) and the refusal is
//! counted in health (`errors`). A position target out of the profile's limits, in every
//! position mode the hand has, is clamped: followed (no hold) and counted (`clamps`).
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use teleop_e2e::hand::HandNode;
use teleop_hand_profile::{CommandUnits, HandProfile};
use teleop_msgs::{control_mode, units, HandCommand, HandState, NodeHealth};

/// A hand node against its simulator, with what its profile says commands must be.
struct Hand {
    node: HandNode,
    profile: HandProfile,
    /// The position modes the hand follows (its drive modes, if any, are the Revo2's own tests').
    position_modes: &'static [u8],
    /// A mode in the contract the hand does not follow, if there is one.
    lacks: Option<u8>,
}

impl Hand {
    /// Starts `hand`'s simulator and node (health every 100 ms) and waits until the link is up.
    fn start(hand: &str) -> Self {
        let (position_modes, lacks): (&'static [u8], Option<u8>) = match hand {
            "revo2" => (&[control_mode::POSITION, control_mode::POSITION_TIME], None),
            "shadow" => (
                &[control_mode::POSITION, control_mode::POSITION_TIME],
                Some(control_mode::VELOCITY),
            ),
            "allegro" | "leap" => (&[control_mode::POSITION], Some(control_mode::POSITION_TIME)),
            other => panic!("no hand {other}"),
        };
        let profile = HandProfile::builtin(hand).unwrap();
        let node = HandNode::simulated(hand);
        Self {
            node,
            profile,
            position_modes,
            lacks,
        }
    }

    /// The joint limits in the command's units (lower, upper).
    fn limits(&self) -> Vec<(f32, f32)> {
        self.profile
            .joints
            .iter()
            .map(|j| match self.profile.command_units {
                CommandUnits::Radians => (j.lower, j.upper),
                CommandUnits::Normalised => {
                    let (a, b) = (j.normalised(j.lower), j.normalised(j.upper));
                    (a.min(b), a.max(b))
                }
            })
            .collect()
    }

    /// A valid position command: every joint in the middle of its limits.
    fn good(&self) -> HandCommand {
        let mut c = HandCommand {
            hand_model: self.profile.model_id,
            joint_count: self.profile.joints.len() as u8,
            control_mode: control_mode::POSITION,
            units: match self.profile.command_units {
                CommandUnits::Radians => units::PHYSICAL,
                CommandUnits::Normalised => units::NORMALISED,
            },
            ..Default::default()
        };
        for (j, (lo, hi)) in c.joints.iter_mut().zip(self.limits()) {
            j.target = (lo + hi) / 2.0;
        }
        c
    }

    /// The bad commands every hand is sent, each named.
    fn bad(&self) -> Vec<(String, HandCommand)> {
        let good = self.good();
        let with = |name: &str, change: &dyn Fn(&mut HandCommand)| {
            let mut c = good;
            change(&mut c);
            (name.to_string(), c)
        };
        let other_units = if good.units == units::PHYSICAL {
            units::NORMALISED
        } else {
            units::PHYSICAL
        };
        let other_model = if good.hand_model == 1 { 2 } else { 1 };
        let mut bad = vec![
            with("NaN target", &|c| c.joints[0].target = f32::NAN),
            with("+inf target", &|c| c.joints[1].target = f32::INFINITY),
            with("-inf target", &|c| c.joints[2].target = f32::NEG_INFINITY),
            with("NaN speed limit", &|c| c.joints[0].speed_limit = f32::NAN),
            with("UNKNOWN model", &|c| c.hand_model = 0),
            with("another hand's model", &|c| c.hand_model = other_model),
            with("wrong units", &|c| c.units = other_units),
            with("one joint too few", &|c| c.joint_count -= 1),
            with("one joint too many", &|c| c.joint_count += 1),
            with("no mode", &|c| c.control_mode = 0),
            with("unknown mode", &|c| c.control_mode = 99),
        ];
        if let Some(mode) = self.lacks {
            bad.push(with("a mode the hand lacks", &|c| c.control_mode = mode));
        }
        bad
    }

    /// The node's next health report.
    fn health(&self) -> NodeHealth {
        let start = Instant::now();
        loop {
            if let Some(h) = self.node.node_health().last() {
                return *h;
            }
            assert!(
                start.elapsed() < Duration::from_secs(3),
                "no health report\n{}",
                self.node.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Sends `cmd` every 10 ms for `d` and on until a state with the link up comes (a loaded
    /// host may have the link drop for a moment), then returns that state and the health after
    /// it.
    fn send_for(&mut self, cmd: &HandCommand, d: Duration) -> (HandState, NodeHealth) {
        let start = Instant::now();
        let mut newest = None;
        loop {
            self.node.commands.publish(cmd).unwrap();
            std::thread::sleep(Duration::from_millis(10));
            self.node.states.drain(|s| newest = Some(*s));
            if start.elapsed() >= d && newest.is_some_and(|s: HandState| s.link_up == 1) {
                break;
            }
            assert!(
                start.elapsed() < d + Duration::from_secs(10),
                "no hand state with the link up\n{}",
                self.node.log()
            );
        }
        let _ = self.node.node_health();
        (newest.unwrap(), self.health())
    }

    /// [`send_for`](Self::send_for) 400 ms.
    fn send(&mut self, cmd: &HandCommand) -> (HandState, NodeHealth) {
        self.send_for(cmd, Duration::from_millis(400))
    }
}

fn positions(s: &HandState) -> Vec<f32> {
    s.active_joints().iter().map(|j| j.position).collect()
}

/// Runs the table's checks on one hand.
fn check(hand: &str) {
    let mut h = Hand::start(hand);
    let good = h.good();
    // Long enough for the ramp from where the hand starts (1 rad or travel per second).
    let (s, _) = h.send_for(&good, Duration::from_millis(2500));
    assert_eq!(
        s.holding,
        0,
        "{hand}: follows a valid command\n{}",
        h.node.log()
    );
    let (mut held, mut health) = h.send(&good);
    for (what, cmd) in h.bad() {
        let (s, after) = h.send(&cmd);
        assert_eq!(
            s.holding,
            1,
            "{hand}: {what}: refused, the hand holds\n{}",
            h.node.log()
        );
        for (j, (a, b)) in positions(&held).iter().zip(positions(&s)).enumerate() {
            assert!(
                (a - b).abs() < 0.05,
                "{hand}: {what}: joint {j} moved from {a} to {b} while holding"
            );
        }
        assert!(
            after.errors > health.errors,
            "{hand}: {what}: the refusal is counted ({} -> {} errors)",
            health.errors,
            after.errors
        );
        assert_eq!(
            after.clamps, health.clamps,
            "{hand}: {what}: nothing clamped"
        );
        (held, health) = (s, after);
    }
    assert!(
        h.node.log().contains("hand command refused"),
        "{hand}: refusals logged\n{}",
        h.node.log()
    );
    let limits = h.limits();
    for &mode in h.position_modes {
        let mut over = good;
        over.control_mode = mode;
        for (j, (_, hi)) in over.joints.iter_mut().zip(&limits) {
            j.target = hi + 1.0;
        }
        let (s, after) = h.send(&over);
        assert_eq!(
            s.holding,
            0,
            "{hand}: mode {mode}: out of range is clamped and followed, not refused\n{}",
            h.node.log()
        );
        assert!(
            after.clamps >= health.clamps + limits.len() as u64,
            "{hand}: mode {mode}: every joint's clamp counted ({} -> {})",
            health.clamps,
            after.clamps
        );
        health = after;
    }
}

#[test]
fn the_revo2_follows_the_one_admission_rule() {
    check("revo2");
}

#[test]
fn the_shadow_hand_follows_the_one_admission_rule() {
    check("shadow");
}

#[test]
fn the_allegro_hand_follows_the_one_admission_rule() {
    check("allegro");
}

#[test]
fn the_leap_hand_follows_the_one_admission_rule() {
    check("leap");
}
