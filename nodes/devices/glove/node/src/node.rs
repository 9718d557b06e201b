//! The glove node's loop: one exchange per cycle, as fast as the line allows.
//!
//! Each cycle sends a force-control frame with the latest glove force command (zero when that
//! command is stale or the latched e-stop is engaged: the glove node obeys the e-stop itself,
//! so a second writer of `glove/force_command` cannot push the operator while it is engaged),
//! reads the 6-DoF answer and publishes `glove/state`. At a low configured
//! rate a register read (actual forces, currents, error codes, temperatures, voltage) takes the
//! place of one force exchange; a complete set is published as `glove/diagnostics`. Timeouts and
//! bad frames are counted and the exchange retried; a port that disappears or stops answering
//! is published as link down and reopened with backoff, without a process restart. On stop the
//! glove gets a zero-force frame before the port closes.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use teleop_glove_protocol::{reg, ErrorBits, Register, Request, Response};
use teleop_msgs::{
    device_model, fixed_text, link_kind, DeviceInfo, GloveDiagnostics, GloveForceCommand,
    GloveState,
};
use teleop_runtime::{EStopInput, Health, NodeRuntime, Publisher, Subscriber};

use crate::link::{GloveLink, LinkError, LinkStats};

/// The node's configuration file.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GloveConfig {
    /// Serial port: USB serial, Bluetooth SPP (e.g. /dev/rfcomm0) or a pseudo-terminal path.
    pub port: PathBuf,
    /// 115200, 57600 or 19200 (what the glove is set to).
    pub baud: u32,
    /// The glove's device id (1..=254).
    pub id: u8,
    /// Complete diagnostic register sets read per second (each set is 5 reads).
    pub diagnostics_hz: f32,
    /// Time to wait for an answer.
    pub answer_timeout_ms: u64,
    /// Consecutive timeouts after which the link counts as down and the port is reopened.
    pub max_consecutive_timeouts: u32,
    /// A force command older than this is stale: the glove gets zero force.
    pub force_timeout_ms: u64,
    /// Largest force magnitude sent to the glove (glove units, at most 1000).
    pub max_force: i16,
    /// First and longest pause between reopen attempts.
    pub reopen_backoff_ms: [u64; 2],
    /// Actuator temperature that raises a warning, degrees Celsius.
    pub warn_temperature_c: u8,
    /// Health report period.
    pub health_period_ms: u64,
}

impl Default for GloveConfig {
    fn default() -> Self {
        Self {
            port: PathBuf::from("/dev/ttyUSB0"),
            baud: 115_200,
            id: 1,
            diagnostics_hz: 2.0,
            answer_timeout_ms: 30,
            max_consecutive_timeouts: 10,
            force_timeout_ms: 100,
            max_force: 1000,
            reopen_backoff_ms: [100, 2000],
            warn_temperature_c: 65,
            health_period_ms: 500,
        }
    }
}

impl GloveConfig {
    /// Checks values a file may get wrong; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        if teleop_glove_protocol::BaudRate::from_bps(self.baud).is_none() {
            return Err(format!(
                "baud = {}: the glove supports 115200, 57600 and 19200",
                self.baud
            ));
        }
        if !(1..=254).contains(&self.id) {
            return Err(format!("id = {}: must be 1..=254", self.id));
        }
        if !(0..=1000).contains(&self.max_force) {
            return Err(format!("max_force = {}: must be 0..=1000", self.max_force));
        }
        if !(self.diagnostics_hz >= 0.0 && self.diagnostics_hz <= 50.0) {
            return Err(format!(
                "diagnostics_hz = {}: must be 0..=50",
                self.diagnostics_hz
            ));
        }
        if self.max_consecutive_timeouts == 0 {
            return Err("max_consecutive_timeouts must be > 0".into());
        }
        teleop_runtime::check_ms("answer_timeout_ms", self.answer_timeout_ms)?;
        teleop_runtime::check_ms("force_timeout_ms", self.force_timeout_ms)?;
        teleop_runtime::check_ms("health_period_ms", self.health_period_ms)?;
        if self.reopen_backoff_ms[0] == 0 || self.reopen_backoff_ms[0] > self.reopen_backoff_ms[1] {
            return Err("reopen_backoff_ms = [first, longest] with 0 < first <= longest".into());
        }
        Ok(())
    }
}

/// The diagnostic registers, read one per diagnostic slot.
const DIAGNOSTICS: [Register; 5] = [
    reg::FORCE_ACTUAL,
    reg::CURRENT,
    reg::ERROR_CODE,
    reg::TEMPERATURE,
    reg::VOLTAGE,
];

struct Ports {
    device: Publisher<DeviceInfo>,
    state: Publisher<GloveState>,
    diagnostics: Publisher<GloveDiagnostics>,
    forces: Subscriber<GloveForceCommand>,
    estop: EStopInput,
    health: Health,
}

/// Link state across reopens.
struct Loop<'a> {
    config: &'a GloveConfig,
    ports: Ports,
    state: GloveState,
    diag: GloveDiagnostics,
    diag_next: usize,
    diag_due: Instant,
    force_stale: bool,
    last_errors: [u8; 5],
    hot: [bool; 5],
    /// Link counters of closed links, so health totals survive reopens.
    errors_before: u64,
    /// Link counters at the last health report of the open link.
    reported: LinkStats,
    /// The connected device, published with every health report (a late subscriber such as the
    /// recorder gets it within one period).
    connected: Option<DeviceInfo>,
    /// `glove/force_command`'s writer changes at the last health report.
    writer_changes: u64,
}

/// Runs until SIGINT/SIGTERM.
pub fn run(runtime: &NodeRuntime, config: &GloveConfig) -> anyhow::Result<()> {
    let ports = Ports {
        device: runtime.publisher()?,
        state: runtime.publisher()?,
        diagnostics: runtime.publisher()?,
        forces: runtime.subscriber()?,
        estop: EStopInput::new(runtime)?,
        health: Health::new(runtime)?,
    };
    let mut l = Loop {
        config,
        ports,
        state: GloveState {
            glove_id: config.id,
            ..Default::default()
        },
        diag: GloveDiagnostics::default(),
        diag_next: 0,
        diag_due: Instant::now(),
        force_stale: true,
        last_errors: [0; 5],
        hot: [false; 5],
        errors_before: 0,
        reported: LinkStats::default(),
        connected: None,
        writer_changes: 0,
    };
    teleop_runtime::install_stop_handlers();
    let port = config.port.display().to_string();
    let timeout = Duration::from_millis(config.answer_timeout_ms);
    let mut backoff = Duration::from_millis(config.reopen_backoff_ms[0]);
    let mut last_health = Instant::now();
    tracing::info!(%port, baud = config.baud, id = config.id, "glove node starting");
    // This thread is the exchange loop: it runs at the real-time priority launch.toml names.
    teleop_runtime::realtime::enter_realtime();
    while teleop_runtime::stop_signal().is_none() {
        match GloveLink::open(&port, config.baud, config.id, timeout) {
            Ok(mut link) => {
                tracing::info!(%port, "port open");
                l.connected = Some(DeviceInfo {
                    device_model: device_model::GLOVE,
                    link_kind: link_kind::SERIAL,
                    bus_address: u32::from(config.id),
                    model_name: fixed_text("EH55BF1"),
                    link: fixed_text(&port),
                    ..Default::default()
                });
                l.reported = LinkStats::default();
                backoff = Duration::from_millis(config.reopen_backoff_ms[0]);
                let why = l.serve(&mut link, &mut last_health);
                let stats = link.stats();
                l.errors_before += stats.errors();
                match why {
                    Ok(()) => {
                        // Stopping: leave the operator's hand unloaded.
                        match link.exchange(&Request::ForceControl { forces: [0; 5] }) {
                            Ok(_) => tracing::info!("sent zero force; closing the port"),
                            Err(e) => {
                                tracing::warn!("could not send zero force before closing: {e}")
                            }
                        }
                        break;
                    }
                    Err(e) => {
                        tracing::warn!(%port, "link down: {e}; reopening");
                        l.ports.health.count_error();
                        l.publish_link_down()?;
                    }
                }
            }
            Err(e) => {
                tracing::warn!("{e}; retrying in {} ms", backoff.as_millis());
                l.publish_link_down()?;
                let until = Instant::now() + backoff;
                while Instant::now() < until && teleop_runtime::stop_signal().is_none() {
                    std::thread::sleep(Duration::from_millis(10));
                    l.follow_estop();
                }
                backoff = (backoff * 2).min(Duration::from_millis(config.reopen_backoff_ms[1]));
            }
        }
        if last_health.elapsed() >= Duration::from_millis(config.health_period_ms) {
            last_health = Instant::now();
            l.publish_health()?;
        }
    }
    tracing::info!("stopped");
    Ok(())
}

impl Loop<'_> {
    /// Exchanges until stop (`Ok`) or until the link is lost (`Err`).
    fn serve(
        &mut self,
        link: &mut GloveLink,
        last_health: &mut Instant,
    ) -> Result<(), anyhow::Error> {
        let diag_period = if self.config.diagnostics_hz > 0.0 {
            Some(Duration::from_secs_f32(
                1.0 / (self.config.diagnostics_hz * DIAGNOSTICS.len() as f32),
            ))
        } else {
            None
        };
        let health_period = Duration::from_millis(self.config.health_period_ms);
        let mut consecutive = 0u32;
        while teleop_runtime::stop_signal().is_none() {
            let diag = diag_period.filter(|_| Instant::now() >= self.diag_due);
            let result = match diag {
                Some(period) => {
                    self.diag_due = Instant::now() + period;
                    self.read_diagnostic(link)
                }
                None => self.force_exchange(link),
            };
            match result {
                Ok(()) => consecutive = 0,
                Err(LinkError::Timeout(_)) => {
                    consecutive += 1;
                    if consecutive >= self.config.max_consecutive_timeouts {
                        anyhow::bail!("{consecutive} answers in a row timed out");
                    }
                }
                Err(LinkError::Refused(what)) => {
                    tracing::warn!("glove refused {what}");
                    self.ports.health.count_error();
                }
                Err(e @ (LinkError::Io { .. } | LinkError::Open { .. })) => return Err(e.into()),
                Err(e) => {
                    tracing::warn!("exchange failed: {e}");
                    self.ports.health.count_error();
                }
            }
            if last_health.elapsed() >= health_period {
                *last_health = Instant::now();
                self.report_line_errors(link.stats());
                self.publish_health()?;
            }
        }
        Ok(())
    }

    fn force_exchange(&mut self, link: &mut GloveLink) -> Result<(), LinkError> {
        let forces = self.force_to_send();
        let (answer, received_ns) = link.exchange(&Request::ForceControl { forces })?;
        if let Response::ForceControl { positions } = answer {
            let stats = link.stats();
            self.state.raw_position = positions;
            self.state.position = positions.map(|p| (f32::from(p) / 1000.0).clamp(0.0, 1.0));
            self.state.link_up = 1;
            self.state.exchanges = stats.exchanges.min(u64::from(u32::MAX)) as u32;
            self.state.errors =
                (self.errors_before + stats.errors()).min(u64::from(u32::MAX)) as u32;
            // The device sampled its positions just before answering; the receive time is the
            // earliest stamp we can give it.
            self.state.header = Default::default();
            self.state.header.origin_ns = received_ns;
            self.ports.health.count_loop();
            if let Err(e) = self.ports.state.publish(&self.state) {
                tracing::warn!("cannot publish glove state: {e}");
            }
        }
        Ok(())
    }

    /// The force for this cycle: the latest command if fresh and the e-stop released, zero
    /// otherwise; clamped.
    fn force_to_send(&mut self) -> [i16; 5] {
        self.follow_estop();
        if self.ports.estop.engaged() {
            // Keep the subscriber drained, so what was sent during the e-stop is not applied
            // after it unless it is still fresh.
            self.ports.forces.poll_latest();
            return [0; 5];
        }
        let now = Instant::now();
        let cmd = self.ports.forces.poll_latest();
        let fresh = self
            .ports
            .forces
            .is_fresh(now, Duration::from_millis(self.config.force_timeout_ms));
        match cmd.filter(|_| fresh) {
            Some(cmd) => {
                if self.force_stale {
                    tracing::info!("force commands fresh: applying them");
                    self.force_stale = false;
                }
                let max = self.config.max_force;
                let clamped = cmd.force.map(|f| f.clamp(-max, max));
                let n = clamped
                    .iter()
                    .zip(&cmd.force)
                    .filter(|(a, b)| a != b)
                    .count();
                if n > 0 {
                    self.ports.health.count_clamps(n as u64);
                    tracing::debug!(fingers = n, max, "force clamped");
                }
                clamped
            }
            None => {
                if !self.force_stale {
                    tracing::warn!(
                        timeout_ms = self.config.force_timeout_ms,
                        "force command stale: glove force zero"
                    );
                    self.force_stale = true;
                    self.ports.health.count_timeout();
                }
                [0; 5]
            }
        }
    }

    fn read_diagnostic(&mut self, link: &mut GloveLink) -> Result<(), LinkError> {
        let register = DIAGNOSTICS[self.diag_next];
        let values = link.read_register(&register)?;
        let v = values.as_slice();
        let at = |i: usize| v.get(i).copied().unwrap_or(0);
        match register.address {
            a if a == reg::FORCE_ACTUAL.address => {
                self.diag.force = core::array::from_fn(|i| at(i) as i16);
                self.state.force = self.diag.force;
            }
            a if a == reg::CURRENT.address => {
                self.diag.current_ma = core::array::from_fn(|i| at(i) as u16);
            }
            a if a == reg::ERROR_CODE.address => {
                self.diag.error_bits = core::array::from_fn(|i| at(i) as u8);
                self.warn_errors();
            }
            a if a == reg::TEMPERATURE.address => {
                self.diag.temperature_c = core::array::from_fn(|i| at(i) as u8);
                self.warn_temperatures();
            }
            _ => {
                self.diag.voltage_raw = at(0) as u16;
            }
        }
        self.diag_next = (self.diag_next + 1) % DIAGNOSTICS.len();
        if self.diag_next == 0 {
            self.diag.header = Default::default();
            if let Err(e) = self.ports.diagnostics.publish(&self.diag) {
                tracing::warn!("cannot publish glove diagnostics: {e}");
            }
        }
        Ok(())
    }

    fn warn_errors(&mut self) {
        for (f, (&now, last)) in self
            .diag
            .error_bits
            .iter()
            .zip(self.last_errors.iter_mut())
            .enumerate()
        {
            if now != *last {
                let finger = teleop_msgs::GLOVE_FINGERS[f];
                if now == 0 {
                    tracing::info!(finger, "actuator errors cleared");
                } else {
                    tracing::warn!(finger, errors = %ErrorBits(now), "actuator error");
                    self.ports.health.count_error();
                }
                *last = now;
            }
        }
    }

    fn warn_temperatures(&mut self) {
        let limit = self.config.warn_temperature_c;
        for (f, (&t, hot)) in self
            .diag
            .temperature_c
            .iter()
            .zip(self.hot.iter_mut())
            .enumerate()
        {
            let finger = teleop_msgs::GLOVE_FINGERS[f];
            match hot_change(t, limit, *hot) {
                Some(true) => tracing::warn!(finger, temperature_c = t, limit, "actuator hot"),
                Some(false) => tracing::info!(finger, temperature_c = t, "actuator cooled down"),
                None => continue,
            }
            *hot = !*hot;
        }
    }

    /// Logs the line errors since the last report (one line per report period, not per error).
    fn report_line_errors(&mut self, now: LinkStats) {
        let last = self.reported;
        if now.errors() > last.errors() {
            self.ports.health.count_errors(now.errors() - last.errors());
            tracing::warn!(
                timeouts = now.timeouts - last.timeouts,
                bad_frames = now.bad_frames - last.bad_frames,
                garbage = now.garbage - last.garbage,
                other_id = now.other_id - last.other_id,
                unexpected = now.unexpected - last.unexpected,
                late = now.late - last.late,
                "line errors since the last report (exchanges go on)"
            );
        }
        self.reported = now;
    }

    /// Reads the e-stop (its doorbell, or the latch every `LATCH_POLL`) and acknowledges a
    /// change: every force exchange, and while the link is down.
    fn follow_estop(&mut self) {
        match self.ports.estop.update() {
            Ok(Some(true)) => tracing::warn!("e-stop engaged: glove force zero"),
            Ok(Some(false)) => tracing::info!("e-stop released: applying force commands"),
            Ok(None) => {}
            Err(e) => {
                self.ports.health.count_error();
                tracing::warn!("e-stop acknowledgement: {e}");
            }
        }
    }

    fn publish_link_down(&mut self) -> anyhow::Result<()> {
        self.follow_estop();
        self.state.link_up = 0;
        self.state.header = Default::default();
        self.ports.state.publish(&self.state)?;
        Ok(())
    }

    fn publish_health(&mut self) -> anyhow::Result<()> {
        if let Some(device) = &self.connected {
            self.ports.device.publish(device)?;
        }
        let age = self.ports.forces.age(Instant::now());
        self.ports.health.set_dropped(self.ports.forces.dropped());
        let changes = self.ports.forces.writer_changes();
        if changes > self.writer_changes {
            tracing::warn!(
                changes = changes - self.writer_changes,
                "glove/force_command came from more than one writer"
            );
            self.ports.health.count_error();
            self.writer_changes = changes;
        }
        self.ports.health.publish(&[age])?;
        Ok(())
    }
}

/// Degrees below the warning limit an actuator must cool to before it counts as cool again.
const COOL_HYSTERESIS_C: u8 = 5;

/// Whether an actuator at `t` degrees becomes hot (`Some(true)`) or cool again (`Some(false)`),
/// given the warning `limit` and whether it was `hot`. Any byte the glove sends is a
/// temperature here, up to 255 (the register's range is 0..=100).
fn hot_change(t: u8, limit: u8, hot: bool) -> Option<bool> {
    if !hot && t >= limit {
        Some(true)
    } else if hot && t.saturating_add(COOL_HYSTERESIS_C) < limit {
        Some(false)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_temperature_byte_gives_a_hysteresis_decision() {
        for limit in 0..=u8::MAX {
            for t in 0..=u8::MAX {
                let cool = u16::from(t) + u16::from(COOL_HYSTERESIS_C) < u16::from(limit);
                assert_eq!(hot_change(t, limit, false), (t >= limit).then_some(true));
                assert_eq!(hot_change(t, limit, true), cool.then_some(false));
            }
        }
        // The glove's 255 (out of the register's range) is hot, and stays hot.
        assert_eq!(hot_change(255, 65, false), Some(true));
        assert_eq!(hot_change(255, 65, true), None);
        assert_eq!(hot_change(59, 65, true), Some(false));
    }
}
