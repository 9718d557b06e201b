//! The ports every hand node has: `hand/command` in (followed only while fresh by its own stamp
//! and while the latched e-stop is released), `hand/state` and `hand/tactile` out, device info
//! and health published periodically.

use std::time::{Duration, Instant};

use teleop_msgs::{DeviceInfo, HandCommand, HandState, Tactile};

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
}

impl HandPorts {
    /// The ports of `runtime`: a command older than `stale_after` (by its stamp) is not
    /// followed; health (and device info) every `health_period`.
    pub fn new(
        runtime: &NodeRuntime,
        stale_after: Duration,
        health_period: Duration,
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
        })
    }

    /// The command to follow now: the latest one if it is fresh and the e-stop is released
    /// (e-stop changes are logged). Freshness counts from the command's stamp: one from the
    /// topic's history, sent before this node (re)started, is stale.
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
        let fresh = self.commands.is_fresh(Instant::now(), self.stale_after);
        cmd.filter(|_| fresh && !self.estop.engaged())
    }

    /// The device that connected, published with every health report from now on.
    pub fn connected(&mut self, device: DeviceInfo) {
        self.connected = Some(device);
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
        self.health.count_loop();
        if self.last_health.elapsed() >= self.health_period {
            self.last_health = Instant::now();
            self.health.set_dropped(self.commands.dropped());
            self.health.publish(&[self.commands.age(Instant::now())])?;
            if let Some(d) = &self.connected {
                self.device.publish(d)?;
            }
        }
        Ok(())
    }

    /// The state while the hand is away (link down).
    pub fn publish_down(&mut self, state: &HandState) -> Result<(), RuntimeError> {
        self.state.publish(state).map(|_| ())
    }

    /// The counters of the health report.
    pub fn health(&mut self) -> &mut Health {
        &mut self.health
    }
}
