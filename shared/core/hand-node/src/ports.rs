//! The ports and the safety policy of every hand node: `hand/command` in, followed only while
//! fresh by its own stamp (less the link's measured delay when it crossed from another station:
//! the station's bridge reports it in `health`, see [`teleop_runtime::link`]), while the latched
//! e-stop is released and when [`Admission`] takes it; after any hold (stale, e-stop, refused, a device brought up again) position targets ramp
//! back to the operator's pose with [`Resume`]. `hand/state` and `hand/tactile` out, device
//! info and health published periodically, also while the hand is away.
//!
//! What is counted in health, and how often: a command going stale, once per loss
//! (`timeouts`); a refused command, once per command sample (`errors`, logged when the reason
//! changes and at most every [`REFUSAL_LOG_PERIOD`] otherwise); values clamped or stopped at a
//! limit, once per command sample (`clamps`); an e-stop acknowledgement that failed (`errors`).

use std::time::{Duration, Instant};

use teleop_msgs::{DeviceInfo, HandCommand, HandState, NodeHealth, Tactile, MAX_JOINTS};
use teleop_runtime::link::{LinkDelay, DEFAULT_MAX_LINK_DELAY_NS};
use teleop_runtime::{
    now_ns, EStopInput, Health, NodeRuntime, Publisher, RuntimeError, Subscriber,
};

use crate::admission::{Admission, Refusal};
use crate::resume::Resume;

/// A refusal for the same reason as the last logged one is logged again at most this often.
pub const REFUSAL_LOG_PERIOD: Duration = Duration::from_secs(10);

/// How a hand node's commands age and its reports come.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// A command older than this (by its stamp) is not followed: the hand holds.
    pub stale_after: Duration,
    /// Health (and device info) report period.
    pub health_period: Duration,
    /// After a hold, position targets move back to the commanded ones at most this much per
    /// second per joint (the commands' units: rad/s, or travel per second).
    pub resume_speed: f64,
}

/// What a hand that takes joint angles should do this cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target<const N: usize> {
    /// Hold the last target followed (where the hand was at bring-up when there was none).
    Hold,
    /// Go to these joint angles (the commands' units, joint order) this cycle, as they are:
    /// whoever gives them has admitted them and ramps them after a hold ([`HandPorts`], or a
    /// service command's [`RampedMove`](crate::RampedMove)).
    Follow([f64; N]),
}

/// A hand node's ports and policy (see the module documentation).
pub struct HandPorts {
    admission: Admission,
    device: Publisher<DeviceInfo>,
    connected: Option<DeviceInfo>,
    commands: Subscriber<HandCommand>,
    /// Health reports, for the station's bridge's report of the link.
    reports: Subscriber<NodeHealth>,
    link: LinkDelay,
    estop: EStopInput,
    state: Publisher<HandState>,
    tactile: Publisher<Tactile>,
    health: Health,
    timing: Timing,
    last_health: Instant,
    /// [`Subscriber::writer_changes`] of the commands at the last health report.
    writer_changes: u64,
    resume: Resume,
    last_command: Instant,
    /// True while fresh commands come (followed or refused): their loss is counted once.
    receiving: bool,
    /// True while commands are followed (logged when it starts).
    following: bool,
    /// `(seq, stamp_ns)` of the last command sample counted (clamps or refusal).
    counted: Option<(u64, u64)>,
    /// The last refusal logged, and when.
    logged: Option<(Refusal, Instant)>,
    /// The latest measured positions (the first `measured_len`, in the commands' units).
    measured: [f32; MAX_JOINTS],
    measured_len: usize,
}

impl HandPorts {
    /// The ports of `runtime` for the hand `admission` describes.
    pub fn new(
        runtime: &NodeRuntime,
        admission: Admission,
        timing: Timing,
    ) -> Result<Self, RuntimeError> {
        Ok(Self {
            admission,
            device: runtime.publisher()?,
            connected: None,
            commands: runtime.subscriber()?,
            reports: runtime.subscriber()?,
            link: LinkDelay::new(DEFAULT_MAX_LINK_DELAY_NS),
            estop: EStopInput::new(runtime)?,
            state: runtime.publisher()?,
            tactile: runtime.publisher()?,
            health: Health::new(runtime)?,
            timing,
            last_health: Instant::now(),
            writer_changes: 0,
            resume: Resume::new(timing.resume_speed),
            last_command: Instant::now(),
            receiving: false,
            following: false,
            counted: None,
            logged: None,
            measured: [0.0; MAX_JOINTS],
            measured_len: 0,
        })
    }

    /// The admission rule in use.
    pub fn admission(&self) -> &Admission {
        &self.admission
    }

    /// The command to follow now, admitted (targets within the profile's limits) and ramped:
    /// the latest one if it is fresh (by its stamp: one from the topic's history, sent before
    /// this node (re)started, is stale), the e-stop is released and [`Admission`] takes it;
    /// `None`: the hand holds. Call once per cycle.
    pub fn command(&mut self) -> Option<HandCommand> {
        match self.estop.update() {
            Ok(Some(true)) => tracing::warn!("e-stop engaged: the hand holds its last target"),
            Ok(Some(false)) => tracing::info!("e-stop released: following hand commands"),
            Ok(None) => {}
            Err(e) => {
                self.health.count_error();
                tracing::warn!("e-stop acknowledgement: {e}");
            }
        }
        let cmd = self.commands.poll_latest();
        let now = Instant::now();
        let stamp_now = now_ns();
        let link = &mut self.link;
        self.reports.drain(|h| {
            link.report(h, stamp_now);
        });
        let fresh = self.commands.is_fresh_over_link(
            now,
            self.timing.stale_after,
            self.link.allowance_ns(stamp_now),
        );
        let dt = now.duration_since(self.last_command).as_secs_f64();
        self.last_command = now;
        let Some(mut cmd) = cmd.filter(|_| fresh && !self.estop.engaged()) else {
            if self.receiving {
                self.health.count_timeout();
                tracing::warn!("no fresh hand command: the hand holds its last target");
            }
            self.receiving = false;
            self.following = false;
            self.resume.hold();
            return None;
        };
        self.receiving = true;
        let sample = (cmd.header.seq, cmd.header.stamp_ns);
        let new = self.counted != Some(sample);
        self.counted = Some(sample);
        let measured = (self.measured_len > 0).then_some(&self.measured[..self.measured_len]);
        match self.admission.admit(&mut cmd, measured) {
            Ok(clamped) => {
                if new {
                    self.health.count_clamps(u64::from(clamped));
                }
                if !self.following {
                    self.following = true;
                    self.logged = None;
                    tracing::info!("hand commands fresh: following them");
                }
                self.resume.follow_command(&mut cmd, dt);
                Some(cmd)
            }
            Err(why) => {
                if new {
                    self.health.count_error();
                }
                self.log_refusal(why, now);
                self.following = false;
                self.refused();
                None
            }
        }
    }

    /// [`command`](Self::command) as the targets of a hand that takes `N` joint angles: the
    /// command's first `N` joint targets to follow, or [`Target::Hold`]. Call once per cycle.
    pub fn target<const N: usize>(&mut self) -> Target<N> {
        match self.command() {
            Some(cmd) => {
                let mut t = [0.0; N];
                for (t, j) in t.iter_mut().zip(&cmd.joints) {
                    *t = f64::from(j.target);
                }
                Target::Follow(t)
            }
            None => Target::Hold,
        }
    }

    /// Logs a refusal when its reason differs from the last logged, or that one is older than
    /// [`REFUSAL_LOG_PERIOD`].
    fn log_refusal(&mut self, why: Refusal, now: Instant) {
        let again = self
            .logged
            .is_some_and(|(last, at)| last == why && now.duration_since(at) < REFUSAL_LOG_PERIOD);
        if !again {
            tracing::warn!("hand command refused: {why}; the hand holds its last target");
            self.logged = Some((why, now));
        }
    }

    /// The target the hand holds (the last one followed, or where it was when none was), in the
    /// commands' units, when known.
    pub fn held(&self) -> Option<&[f64]> {
        self.resume.held()
    }

    /// The device could not take the command it was given this cycle: it holds, and the ramp
    /// starts again from where it is.
    pub fn refused(&mut self) {
        self.resume.forget();
        self.resume.hold();
    }

    /// The device that connected: published now and with every health report from now on. A
    /// device brought up (again) holds where it is: the ramp starts there.
    pub fn connected(&mut self, device: DeviceInfo) -> Result<(), RuntimeError> {
        self.device.publish(&device)?;
        self.connected = Some(device);
        self.measured_len = 0;
        self.refused();
        Ok(())
    }

    /// One cycle's outputs: the state (in the profile's joint order) and the tactile sample (if
    /// any); counts the loop and publishes health and device info when their period has passed.
    pub fn publish(
        &mut self,
        state: &HandState,
        tactile: Option<&Tactile>,
    ) -> Result<(), RuntimeError> {
        self.state.publish(state)?;
        if let Some(t) = tactile {
            self.tactile.publish(t)?;
        }
        if state.units == self.admission.units() {
            let n = usize::from(state.joint_count).min(MAX_JOINTS);
            let mut at = [0.0f64; MAX_JOINTS];
            for ((m, a), j) in self
                .measured
                .iter_mut()
                .zip(&mut at)
                .zip(&state.joints[..n])
            {
                *m = j.position;
                *a = f64::from(j.position);
            }
            self.measured_len = n;
            // Where a hold without a known target holds (ignored while the target is known).
            self.resume.held_at(&at[..n]);
        }
        self.health.count_loop();
        self.health_due()
    }

    /// The state while the hand is away (link down): `state`'s link fields, with the profile's
    /// model, joint count and units; health and device info when due, so that a supervisor does
    /// not take the node for hung while it waits for the hand.
    pub fn publish_down(&mut self, state: &HandState) -> Result<(), RuntimeError> {
        self.measured_len = 0;
        self.connected = None;
        let state = HandState {
            hand_model: self.admission.model(),
            joint_count: self.admission.joints() as u8,
            units: self.admission.units(),
            link_up: 0,
            ..*state
        };
        self.state.publish(&state)?;
        self.health_due()
    }

    /// Publishes health (and device info) when their period has passed.
    fn health_due(&mut self) -> Result<(), RuntimeError> {
        if self.last_health.elapsed() >= self.timing.health_period {
            self.last_health = Instant::now();
            self.health.set_dropped(self.commands.dropped());
            let changes = self.commands.writer_changes();
            if changes > self.writer_changes {
                // Refused at publisher creation; seen here when a writer got past that (a
                // `teleop replay --allow-live`) or wrote with a forged source.
                tracing::warn!(
                    changes = changes - self.writer_changes,
                    "hand/command came from more than one writer"
                );
                self.health.count_error();
                self.writer_changes = changes;
            }
            self.health.publish(&[self.commands.age(Instant::now())])?;
            if let Some(d) = &self.connected {
                self.device.publish(d)?;
            }
        }
        Ok(())
    }

    /// The counters of the health report.
    pub fn health(&mut self) -> &mut Health {
        &mut self.health
    }
}
