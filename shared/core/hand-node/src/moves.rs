//! A service command's move (`teleop <hand> home`, `teleop <hand> move J DEG`): the hand's
//! own loop driven for a while toward an aim, ramped there with [`Resume`] at the node's
//! `resume_speed` from where the hand was first seen (as the node ramps after a hold), and
//! the report of where it got.
//!
//! Pure but for the report's writer: the caller gives the times and the hand's positions.

use std::io::Write;
use std::time::{Duration, Instant};

use teleop_hand_profile::HandProfile;

use crate::ports::Target;
use crate::resume::Resume;

/// What a move aims at (rad, joint order).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Aim<const N: usize> {
    /// Every joint.
    Pose([f64; N]),
    /// One joint; the others stay where they were when the hand was first seen.
    Joint(usize, f64),
}

/// A ramped move toward an [`Aim`] that ends a while after the hand came up.
#[derive(Debug, Clone)]
pub struct RampedMove<const N: usize> {
    resume: Resume,
    period_s: f64,
    aim: Aim<N>,
    limits: [(f64, f64); N],
    lasts: Duration,
    until: Option<Instant>,
    /// True once the hand was seen (the start and the goal fixed).
    seen: bool,
    goal: [f64; N],
}

impl<const N: usize> RampedMove<N> {
    /// A move toward `aim`, clamped into `profile`'s joint limits (joints the profile lacks:
    /// unclamped), ramped at `speed` per second in steps of `period`, lasting `lasts` from
    /// [`started`](Self::started).
    pub fn new(
        profile: &HandProfile,
        aim: Aim<N>,
        speed: f64,
        period: Duration,
        lasts: Duration,
    ) -> Self {
        let mut limits = [(f64::NEG_INFINITY, f64::INFINITY); N];
        for (l, j) in limits.iter_mut().zip(&profile.joints) {
            *l = (f64::from(j.lower), f64::from(j.upper));
        }
        Self {
            resume: Resume::new(speed),
            period_s: period.as_secs_f64(),
            aim,
            limits,
            lasts,
            until: None,
            seen: false,
            goal: [0.0; N],
        }
    }

    /// The hand came up at `now`: the move ends `lasts` later (a later bring-up does not
    /// extend it).
    pub fn started(&mut self, now: Instant) {
        self.until.get_or_insert(now + self.lasts);
    }

    /// True once the move's time is up at `now`.
    pub fn over(&self, now: Instant) -> bool {
        self.until.is_some_and(|t| now >= t)
    }

    /// Where the hand is this cycle, rad: the first time fixes where the ramp starts and the
    /// goal (the aim within the limits, a [`Aim::Joint`]'s other joints where they are).
    pub fn seen(&mut self, at: &[f64; N]) {
        if self.seen {
            return;
        }
        self.seen = true;
        self.resume.held_at(at);
        self.goal = match self.aim {
            Aim::Pose(p) => p,
            Aim::Joint(j, rad) => {
                let mut g = *at;
                if let Some(g) = g.get_mut(j) {
                    *g = rad;
                }
                g
            }
        };
        for (g, (lo, hi)) in self.goal.iter_mut().zip(self.limits) {
            *g = g.clamp(lo, hi);
        }
    }

    /// The target of this cycle: hold until the hand was [`seen`](Self::seen), then one ramp
    /// step further toward the goal.
    pub fn target(&mut self) -> Target<N> {
        if !self.seen {
            return Target::Hold;
        }
        let mut target = self.goal;
        self.resume.follow(&mut target, self.period_s);
        Target::Follow(target)
    }

    /// Where the move goes (known once the hand was seen).
    pub fn goal(&self) -> Option<&[f64; N]> {
        self.seen.then_some(&self.goal)
    }

    /// The joints the aim names: all for a pose, the one for a joint.
    pub fn aimed(&self) -> std::ops::Range<usize> {
        match self.aim {
            Aim::Pose(_) => 0..N,
            Aim::Joint(j, _) => j.min(N)..(j + 1).min(N),
        }
    }

    /// The aimed joint farthest from its goal at `reached`, and how far, rad (joint 0 and 0.0
    /// before the hand was seen or when every one is there).
    pub fn largest_error(&self, reached: &[f64; N]) -> (usize, f64) {
        let mut worst = (self.aimed().start.min(N.saturating_sub(1)), 0.0f64);
        if !self.seen {
            return worst;
        }
        for j in self.aimed() {
            let err = (self.goal[j] - reached[j]).abs();
            if err > worst.1 {
                worst = (j, err);
            }
        }
        worst
    }

    /// Writes one line per aimed joint (`NAME target DEG deg  reached DEG deg` and what
    /// `extra` says of it) and the largest error, the names `profile`'s.
    pub fn report(
        &self,
        out: &mut impl Write,
        profile: &HandProfile,
        reached: &[f64; N],
        extra: impl Fn(usize) -> String,
    ) -> std::io::Result<()> {
        let name = |j: usize| {
            profile
                .joints
                .get(j)
                .map_or("?", |joint| joint.name.as_str())
        };
        let width = self.aimed().map(|j| name(j).len()).max().unwrap_or(0);
        for j in self.aimed() {
            writeln!(
                out,
                "{:<width$} target {:>7.1} deg  reached {:>7.1} deg  {}",
                name(j),
                self.goal[j].to_degrees(),
                reached[j].to_degrees(),
                extra(j)
            )?;
        }
        let (j, err) = self.largest_error(reached);
        writeln!(
            out,
            "largest error {:.2} deg ({})",
            err.to_degrees(),
            name(j)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile() -> HandProfile {
        HandProfile::builtin("allegro").expect("the builtin Allegro profile")
    }

    #[test]
    fn the_move_holds_until_seen_then_ramps_from_there_to_the_goal_in_the_limits() {
        let p = profile();
        let hi = f64::from(p.joints[2].upper);
        let mut m: RampedMove<16> = RampedMove::new(
            &p,
            Aim::Joint(2, hi + 1.0),
            1.0,
            Duration::from_millis(10),
            Duration::from_secs(2),
        );
        assert_eq!(m.target(), Target::Hold, "not seen: hold");
        assert_eq!(m.goal(), None);
        // Where the hand is: each joint in the middle of its limits.
        let at: [f64; 16] =
            core::array::from_fn(|j| f64::from(p.joints[j].lower + p.joints[j].upper) / 2.0);
        m.seen(&at);
        m.seen(&[hi; 16]); // only the first look counts
        let goal = *m.goal().expect("seen");
        assert_eq!(goal[2], hi, "clamped into the limit");
        assert!(goal
            .iter()
            .zip(at)
            .enumerate()
            .all(|(j, (g, a))| j == 2 || *g == a));
        let Target::Follow(first) = m.target() else {
            panic!("seen: followed")
        };
        assert!(
            (first[2] - (at[2] + 0.01)).abs() < 1e-12,
            "one step of 0.01: {first:?}"
        );
        assert_eq!(first[0], at[0], "the others hold");
        let mut last = m.target();
        for _ in 0..1000 {
            last = m.target();
        }
        assert_eq!(last, Target::Follow(goal), "caught up");
        assert_eq!(m.aimed(), 2..3);
        let mut reached = goal;
        reached[2] -= 0.5;
        reached[3] += 2.0; // not aimed at: not counted
        let (j, err) = m.largest_error(&reached);
        assert_eq!(j, 2);
        assert!((err - 0.5).abs() < 1e-12);
    }

    #[test]
    fn the_move_ends_its_time_after_the_first_bring_up() {
        let p = profile();
        let mut m: RampedMove<16> = RampedMove::new(
            &p,
            Aim::Pose([0.0; 16]),
            1.0,
            Duration::from_millis(10),
            Duration::from_secs(2),
        );
        let t0 = Instant::now();
        assert!(!m.over(t0 + Duration::from_secs(60)), "not started");
        m.started(t0);
        m.started(t0 + Duration::from_secs(1)); // a second bring-up does not extend it
        assert!(!m.over(t0 + Duration::from_millis(1999)));
        assert!(m.over(t0 + Duration::from_secs(2)));
        assert_eq!(m.aimed(), 0..16);
    }

    #[test]
    fn the_report_names_each_aimed_joint_and_the_largest_error() {
        let p = profile();
        let mut m: RampedMove<16> = RampedMove::new(
            &p,
            Aim::Joint(5, 0.5),
            1.0,
            Duration::from_millis(10),
            Duration::from_secs(1),
        );
        m.seen(&[0.0; 16]);
        let mut reached = [0.0; 16];
        reached[5] = 0.4;
        let mut out = Vec::new();
        m.report(&mut out, &p, &reached, |j| format!("extra {j}"))
            .expect("written");
        let text = String::from_utf8(out).expect("text");
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(lines[0].starts_with(&p.joints[5].name), "{text}");
        assert!(lines[0].contains("target    28.6 deg  reached    22.9 deg  extra 5"));
        assert_eq!(
            lines[1],
            format!("largest error 5.73 deg ({})", p.joints[5].name)
        );
    }
}
