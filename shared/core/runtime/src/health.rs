//! Health counters and the periodic [`NodeHealth`] report.

use std::time::{Duration, Instant};

use teleop_msgs::{NodeHealth, MAX_HEALTH_DETAILS};

use crate::ipc::{NodeRuntime, RuntimeError};
use crate::ports::Publisher;

/// A node's safety and error counters, published on the `health` topic.
///
/// Every counted event is also logged by the node that counts it; this only aggregates.
pub struct Health {
    publisher: Publisher<NodeHealth>,
    report: NodeHealth,
    loops: u64,
    window_start: Instant,
    /// A detail was refused because all entries were taken (logged once).
    details_full_logged: bool,
}

impl Health {
    /// Creates the health publisher for `runtime`'s node.
    pub fn new(runtime: &NodeRuntime) -> Result<Self, RuntimeError> {
        let mut report = NodeHealth::default();
        report.set_name(runtime.name());
        Ok(Self {
            publisher: runtime.publisher()?,
            report,
            loops: 0,
            window_start: Instant::now(),
            details_full_logged: false,
        })
    }

    /// Counts one pass through the node's main step (for the loop rate).
    pub fn count_loop(&mut self) {
        self.loops += 1;
    }

    /// Counts input watchdog timeouts.
    pub fn count_timeout(&mut self) {
        self.report.timeouts += 1;
    }

    /// Counts values clamped to configured limits.
    pub fn count_clamps(&mut self, n: u64) {
        self.report.clamps += n;
    }

    /// Counts an error.
    pub fn count_error(&mut self) {
        self.count_errors(1);
    }

    /// Counts `n` errors.
    pub fn count_errors(&mut self, n: u64) {
        self.report.errors += n;
    }

    /// Sets the total of samples lost on inputs.
    pub fn set_dropped(&mut self, total: u64) {
        self.report.dropped = total;
    }

    /// Sets the node-specific value called `name` (`[a-z0-9_]`, at most 24 bytes, the unit
    /// in the name: `rtt_ms`), shown by name by `teleop stats` and the viewer. A node has at
    /// most [`MAX_HEALTH_DETAILS`] of them: one more is not stored, and logged once.
    pub fn set_detail(&mut self, name: &str, value: f64) {
        if !self.report.set_detail(name, value) && !self.details_full_logged {
            self.details_full_logged = true;
            tracing::warn!(
                "health detail {name} not reported: a node reports at most {MAX_HEALTH_DETAILS}"
            );
        }
    }

    /// The counters so far.
    pub fn counters(&self) -> &NodeHealth {
        &self.report
    }

    /// Publishes the report with the given input ages (`None` = never received) and starts a
    /// new loop-rate window.
    pub fn publish(&mut self, input_ages: &[Option<Duration>]) -> Result<(), RuntimeError> {
        let now = Instant::now();
        let window = now.duration_since(self.window_start).as_secs_f32();
        self.report.loop_rate_hz = if window > 0.0 {
            self.loops as f32 / window
        } else {
            0.0
        };
        self.loops = 0;
        self.window_start = now;
        let n = input_ages.len().min(self.report.input_age_ms.len());
        self.report.input_count = n as u8;
        self.report.input_age_ms = [-1.0; 5];
        for (slot, age) in self.report.input_age_ms.iter_mut().zip(input_ages) {
            *slot = age.map_or(-1.0, |a| a.as_secs_f32() * 1000.0);
        }
        self.report.header = Default::default();
        self.publisher.publish(&self.report)?;
        Ok(())
    }
}
