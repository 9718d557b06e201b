//! The ports every hand node has: `hand/command` in (followed only while fresh by its own stamp
//! and while the latched e-stop is released; after a hold, position targets ramp back to the
//! operator's pose with [`Resume`]), `hand/state` and `hand/tactile` out, device info and health
//! published periodically, also while the hand is away.

use std::time::{Duration, Instant};

use teleop_msgs::{control_mode, DeviceInfo, HandCommand, HandState, Tactile, MAX_JOINTS};

use crate::resume::Resume;
use crate::{EStopInput, Health, NodeRuntime, Publisher, RuntimeError, Subscriber};

/// A hand node's ports.
pub struct HandPorts {
    device: Publisher<DeviceInfo>,
    connected: Option<DeviceInfo>,
    commands: Subscriber<HandCommand>,
    estop: EStopInput,
    state: Publisher<HandState>,
    tactile: Publisher<Tactile>,
    health: Health,
    stale_after: Duration,
    health_period: Duration,
    last_health: Instant,
    /// [`Subscriber::writer_changes`] of the commands at the last health report.
    writer_changes: u64,
    resume: Resume,
    last_command: Instant,
    /// The latest measured positions (the first `measured_len`, in `measured_units`), where the
    /// ramp starts when the held target is not known.
    measured: [f64; MAX_JOINTS],
    measured_len: usize,
    measured_units: u8,
}

impl HandPorts {
    /// The ports of `runtime`: a command older than `stale_after` (by its stamp) is not
    /// followed; after a hold, position targets move back to the commanded ones at most
    /// `resume_speed` per second per joint (the commands' units: rad/s, or travel per second);
    /// health (and device info) every `health_period`.
    pub fn new(
        runtime: &NodeRuntime,
        stale_after: Duration,
        health_period: Duration,
        resume_speed: f64,
    ) -> Result<Self, RuntimeError> {
        Ok(Self {
            device: runtime.publisher()?,
            connected: None,
            commands: runtime.subscriber()?,
            estop: EStopInput::new(runtime)?,
            state: runtime.publisher()?,
            tactile: runtime.publisher()?,
            health: Health::new(runtime)?,
            stale_after,
            health_period,
            last_health: Instant::now(),
            writer_changes: 0,
            resume: Resume::new(resume_speed),
            last_command: Instant::now(),
            measured: [0.0; MAX_JOINTS],
            measured_len: 0,
            measured_units: 0,
        })
    }

    /// The command to follow now: the latest one if it is fresh and the e-stop is released
    /// (e-stop changes are logged). Freshness counts from the command's stamp: one from the
    /// topic's history, sent before this node (re)started, is stale. Call once per cycle: after
    /// a cycle without a command (the hand holds), position targets ramp from the held ones
    /// (see [`Resume`]).
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
        let fresh = self.commands.is_fresh(now, self.stale_after);
        let dt = now.duration_since(self.last_command).as_secs_f64();
        self.last_command = now;
        match cmd.filter(|_| fresh && !self.estop.engaged()) {
            Some(mut cmd) => {
                self.resume_toward(&mut cmd, dt);
                Some(cmd)
            }
            None => {
                self.resume.hold();
                None
            }
        }
    }

    /// Limits the position targets of `cmd` by the ramp after a hold.
    fn resume_toward(&mut self, cmd: &mut HandCommand, dt: f64) {
        if !matches!(
            cmd.control_mode,
            control_mode::POSITION | control_mode::POSITION_TIME
        ) {
            // No position target: the hand moves freely, and a later hold is where it is.
            self.resume.forget();
            self.resume.hold();
            return;
        }
        let n = usize::from(cmd.joint_count).min(MAX_JOINTS);
        if self.resume.held().is_none()
            && self.measured_units == cmd.units
            && self.measured_len >= n
        {
            self.resume.held_at(&self.measured[..n]);
        }
        let mut targets = [0.0f64; MAX_JOINTS];
        for (t, j) in targets.iter_mut().zip(&cmd.joints[..n]) {
            *t = f64::from(j.target);
        }
        if self.resume.follow(&mut targets[..n], dt) {
            for (j, t) in cmd.joints[..n].iter_mut().zip(&targets) {
                if j.target.is_finite() {
                    j.target = *t as f32;
                }
            }
        }
    }

    /// The device refused the command it was given this cycle (not for it, or not a valid
    /// command): it holds, and the ramp starts again from where it is.
    pub fn refused(&mut self) {
        self.resume.forget();
        self.resume.hold();
    }

    /// The device that connected, published with every health report from now on. A device
    /// brought up (again) holds where it is: the ramp starts there.
    pub fn connected(&mut self, device: DeviceInfo) {
        self.connected = Some(device);
        self.resume.forget();
        self.resume.hold();
    }

    /// One cycle's outputs: the state and the tactile sample (if any); counts the loop and
    /// publishes health and device info when their period has passed.
    pub fn publish(
        &mut self,
        state: &HandState,
        tactile: Option<&Tactile>,
    ) -> Result<(), RuntimeError> {
        self.state.publish(state)?;
        if let Some(t) = tactile {
            self.tactile.publish(t)?;
        }
        let n = usize::from(state.joint_count).min(MAX_JOINTS);
        for (m, j) in self.measured.iter_mut().zip(&state.joints[..n]) {
            *m = f64::from(j.position);
        }
        self.measured_len = n;
        self.measured_units = state.units;
        self.health.count_loop();
        self.health_due()
    }

    /// The state while the hand is away (link down); health and device info when due, so that
    /// a supervisor does not take the node for hung while it waits for the hand.
    pub fn publish_down(&mut self, state: &HandState) -> Result<(), RuntimeError> {
        self.measured_len = 0;
        self.connected = None;
        self.state.publish(state)?;
        self.health_due()
    }

    /// Publishes health (and device info) when their period has passed.
    fn health_due(&mut self) -> Result<(), RuntimeError> {
        if self.last_health.elapsed() >= self.health_period {
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
