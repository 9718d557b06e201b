//! Resuming after a hold: the ramp from where a hand holds to the operator's pose.
//!
//! A hand holds while it has no command to follow (the command went stale, the e-stop is
//! engaged, a command was refused). When commands come back, the operator's pose may be far
//! from the held one; [`Resume`] moves the target from the held position toward the commanded
//! one at a bounded joint speed (rad/s for physical units, travel per second for normalised
//! ones), and lets the commands through unchanged once it has caught up.
//!
//! Pure: no clock, no I/O, no allocation (the caller gives the time step): every hand node
//! ramps through [`HandPorts`](crate::HandPorts), and a device's service command that moves
//! the hand (`home` and `move`) ramps the same way through [`RampedMove`](crate::RampedMove).

/// Most joints a [`Resume`] ramps (the contract's `MAX_JOINTS`).
pub const MAX_JOINTS: usize = teleop_msgs::MAX_JOINTS;

/// The longest time step a [`Resume::follow`] counts, seconds: after a stall of the loop the
/// ramp goes on from where it was instead of jumping by the whole stall (a loop slower than
/// 50 Hz ramps more slowly than its speed, never faster).
pub const MAX_STEP_S: f64 = 0.02;

/// The ramp back to the operator's pose after a hold (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resume {
    /// Most joint motion per second while resuming.
    speed: f64,
    /// The target the hand holds or was last sent, per joint (the first `len`).
    at: [f64; MAX_JOINTS],
    /// Joints in `at`; 0 when the held target is not known.
    len: usize,
    /// True from a hold until the ramp has caught up with the commands.
    resuming: bool,
}

impl Resume {
    /// A ramp of at most `speed` per second per joint (a positive number; infinity: no ramp).
    /// Until a target is followed or [`held_at`](Self::held_at) says where the hand is, there
    /// is nothing to ramp from.
    pub fn new(speed: f64) -> Self {
        Self {
            speed: if speed.is_nan() { 0.0 } else { speed.max(0.0) },
            at: [0.0; MAX_JOINTS],
            len: 0,
            resuming: true,
        }
    }

    /// The most joint motion per second while resuming.
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// The hand holds (no command followed this cycle): the next [`follow`](Self::follow) ramps
    /// from the target it holds.
    pub fn hold(&mut self) {
        self.resuming = true;
    }

    /// The held target is no longer known (the hand was brought up again, moved in a mode
    /// without a position target, or refused the last targets): the ramp then starts where
    /// [`held_at`](Self::held_at) says the hand is.
    pub fn forget(&mut self) {
        self.len = 0;
    }

    /// Where the hand is, for a hold without a known target (before the first target, after
    /// [`forget`](Self::forget)); ignored while the held target is known.
    pub fn held_at(&mut self, at: &[f64]) {
        if self.len == 0 {
            let n = at.len().min(MAX_JOINTS);
            self.at[..n].copy_from_slice(&at[..n]);
            self.len = n;
        }
    }

    /// The target the hand holds or was last sent, when known.
    pub fn held(&self) -> Option<&[f64]> {
        (self.len > 0).then(|| &self.at[..self.len])
    }

    /// True from a hold until the ramp has caught up with the commands.
    pub fn resuming(&self) -> bool {
        self.resuming
    }

    /// Takes the targets to follow this cycle, `dt` seconds after the previous one, and limits
    /// them in place: while resuming, each joint moves at most `speed * dt` (`dt` at most
    /// [`MAX_STEP_S`]) from the target of the previous cycle (or the held one); once every joint
    /// has caught up, the targets pass unchanged. Returns true while resuming.
    ///
    /// Targets with a non-finite value are no valid command: they are left as they are (whoever
    /// refuses them holds) and the next valid targets ramp from the held ones. Targets of
    /// another joint count than the held ones have nothing to ramp from and pass unchanged.
    pub fn follow(&mut self, target: &mut [f64], dt: f64) -> bool {
        let n = target.len().min(MAX_JOINTS);
        let target = &mut target[..n];
        if target.iter().any(|t| !t.is_finite()) {
            self.resuming = true;
            return true;
        }
        if self.resuming && self.len == n {
            let step = if dt.is_finite() && dt > 0.0 {
                self.speed * dt.min(MAX_STEP_S)
            } else {
                0.0
            };
            let mut caught_up = true;
            for (t, at) in target.iter_mut().zip(&self.at) {
                let d = *t - *at;
                if d.abs() > step {
                    *t = *at + step.copysign(d);
                    caught_up = false;
                }
            }
            self.resuming = !caught_up;
        } else {
            self.resuming = false;
        }
        self.at[..n].copy_from_slice(target);
        self.len = n;
        self.resuming
    }

    /// [`follow`](Self::follow) for a hand command: its position targets (modes position and
    /// position + time) limited in place; a command of another mode has no position target to
    /// ramp, so the hand moves freely and a later hold is where it is.
    pub fn follow_command(&mut self, cmd: &mut teleop_msgs::HandCommand, dt: f64) {
        use teleop_msgs::control_mode;
        if !matches!(
            cmd.control_mode,
            control_mode::POSITION | control_mode::POSITION_TIME
        ) {
            self.forget();
            self.hold();
            return;
        }
        let n = usize::from(cmd.joint_count).min(MAX_JOINTS);
        let mut targets = [0.0f64; MAX_JOINTS];
        for (t, j) in targets.iter_mut().zip(&cmd.joints[..n]) {
            *t = f64::from(j.target);
        }
        if self.follow(&mut targets[..n], dt) {
            for (j, t) in cmd.joints[..n].iter_mut().zip(&targets) {
                j.target = *t as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Follows `target` every `dt` until caught up; the targets sent.
    fn run(r: &mut Resume, target: &[f64], dt: f64, cycles: usize) -> Vec<Vec<f64>> {
        (0..cycles)
            .map(|_| {
                let mut t = target.to_vec();
                r.follow(&mut t, dt);
                t
            })
            .collect()
    }

    #[test]
    fn after_a_hold_the_target_ramps_at_the_speed_then_tracks() {
        let mut r = Resume::new(1.0);
        let mut first = [0.1, 0.5];
        r.follow(&mut first, 0.001);
        r.follow(&mut first, 0.001);
        assert_eq!(first, [0.1, 0.5], "nothing held before: followed as is");
        assert!(!r.resuming());
        r.hold();
        // Far pose: 0.8 away on joint 0, 0.05 on joint 1, at 1 per second in 10 ms steps.
        let sent = run(&mut r, &[0.9, 0.45], 0.01, 100);
        for w in sent.windows(2) {
            for j in 0..2 {
                assert!((w[1][j] - w[0][j]).abs() <= 0.01 + 1e-12, "{w:?}");
            }
        }
        assert!((sent[0][0] - 0.11).abs() < 1e-12 && (sent[0][1] - 0.49).abs() < 1e-12);
        assert!((sent[4][1] - 0.45).abs() < 1e-12, "joint 1 caught up first");
        assert!((sent[78][0] - 0.89).abs() < 1e-9, "{:?}", sent[78]);
        assert_eq!(sent[79], vec![0.9, 0.45], "caught up after 0.8 s");
        assert!(!r.resuming());
        // Then it tracks: a jump of the operator passes unchanged.
        let mut t = [0.2, 0.2];
        assert!(!r.follow(&mut t, 0.01));
        assert_eq!(t, [0.2, 0.2]);
    }

    #[test]
    fn a_moving_target_is_caught_up_and_a_hold_while_ramping_starts_from_the_ramp() {
        let mut r = Resume::new(2.0);
        r.held_at(&[0.0]);
        let mut target = 1.0;
        let mut last = 0.0;
        let mut cycles = 0;
        loop {
            target += 0.005; // the operator moves at 0.5 per second
            let mut t = [target];
            let resuming = r.follow(&mut t, 0.01);
            assert!(t[0] - last <= 0.02 + 1e-12);
            last = t[0];
            cycles += 1;
            if !resuming {
                assert_eq!(t[0], target);
                break;
            }
            assert!(cycles < 1000);
        }
        assert!(
            (60..=70).contains(&cycles),
            "caught up after {cycles} cycles"
        );
        // A hold in the middle of a ramp: the next ramp starts where the last one was.
        let mut r = Resume::new(10.0);
        r.held_at(&[0.0]);
        run(&mut r, &[1.0], 0.01, 3);
        r.hold();
        assert!((r.held().unwrap()[0] - 0.3).abs() < 1e-12, "{:?}", r.held());
        let sent = run(&mut r, &[-1.0], 0.01, 1);
        assert!((sent[0][0] - 0.2).abs() < 1e-12, "{sent:?}");
    }

    #[test]
    fn non_finite_targets_pass_untouched_and_the_next_valid_ones_ramp() {
        let mut r = Resume::new(1.0);
        let mut t = [0.5, 0.5];
        r.follow(&mut t, 0.01);
        for bad in [f64::NAN, f64::INFINITY] {
            let mut t = [bad, 0.9];
            assert!(r.follow(&mut t, 0.01));
            assert!(!t[0].is_finite() && t[1] == 0.9, "left as they are");
        }
        assert_eq!(r.held(), Some(&[0.5, 0.5][..]), "the held target stays");
        let mut t = [0.9, 0.9];
        assert!(r.follow(&mut t, 0.01));
        assert_eq!(t, [0.51, 0.51]);
        // A stall counts as MAX_STEP_S; a bad time step moves nothing; another joint count has
        // nothing to ramp from.
        let mut t = [0.9, 0.9];
        r.follow(&mut t, 5.0);
        assert!(t.iter().all(|t| (t - 0.53).abs() < 1e-12), "{t:?}");
        let mut bad_dt = [0.9, 0.9];
        r.follow(&mut bad_dt, f64::NAN);
        assert_eq!(bad_dt, t);
        let mut t = [0.9; 3];
        assert!(!r.follow(&mut t, 0.01));
        assert_eq!(t, [0.9; 3]);
    }

    #[test]
    fn forget_ramps_from_where_the_hand_is() {
        let mut r = Resume::new(5.0);
        let mut t = [1.0];
        r.follow(&mut t, 0.01);
        r.forget();
        r.hold();
        r.held_at(&[0.2]);
        r.held_at(&[0.7]); // already known: ignored
        let mut t = [1.0];
        r.follow(&mut t, 0.01);
        assert!((t[0] - 0.25).abs() < 1e-12, "{t:?}");
        assert_eq!(Resume::new(f64::NAN).speed(), 0.0);
        let mut r = Resume::new(f64::INFINITY);
        r.held_at(&[0.0]);
        let mut t = [1.0];
        assert!(!r.follow(&mut t, 0.01), "infinite speed: no ramp");
        assert_eq!(t, [1.0]);
    }
}
