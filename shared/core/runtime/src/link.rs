//! The link between stations as the nodes downstream of a bridge see it: the bridge's health
//! report names the link's state and its measured one-way delay (`link_state`, and
//! `latency_p50_ms`, the median of the frames' transit), and a node that judges the freshness of
//! samples that crossed it allows for that delay. A sample is then fresh while
//! `now <= min(stamp + delay, received) + timeout`: delayed but continuing samples stay fresh,
//! a link that stops is stale a timeout after its last sample, and a sample made long ago (a
//! topic's history) is stale as before. Pure: times come in as nanoseconds.

use teleop_msgs::NodeHealth;

/// The node name of a station's bridge (its process in the launch file), whose health reports
/// the link; in a namespace, `<namespace>/bridge`.
pub const LINK_NODE: &str = "bridge";

/// How long a bridge's report counts: three of its one-second health periods. Without a newer
/// one the link gives no allowance (the bridge stopped).
pub const LINK_REPORT_NS: u64 = 3_000_000_000;

/// The bridge's health detail that gives the link's delay: the one-way median of its frames'
/// transit, ms.
pub const LINK_DELAY_DETAIL: &str = "latency_p50_ms";

/// Most link delay allowed for unless configured otherwise, ns.
pub const DEFAULT_MAX_LINK_DELAY_NS: u64 = 1_000_000_000;

/// A sample's stamp as freshness judges it after it crossed a link with this measured one-way
/// delay: moved later by the delay (an unstamped sample, 0, stays as old as can be). With
/// [`sample_time`](crate::sample_time) and the receipt this is the one rule of the module's
/// documentation: `made = min(stamp + delay, received)`.
pub fn stamp_over_link(stamp_ns: u64, link_delay_ns: u64) -> u64 {
    if stamp_ns == 0 {
        0
    } else {
        stamp_ns.saturating_add(link_delay_ns)
    }
}

/// The newest link report of a station's bridge.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkDelay {
    max_ns: u64,
    /// The delay allowed for (0: the link is down) and when it was reported.
    latest: Option<(u64, u64)>,
}

impl LinkDelay {
    /// No link seen yet; delays above `max_ns` will count as `max_ns`.
    pub fn new(max_ns: u64) -> Self {
        Self {
            max_ns,
            latest: None,
        }
    }

    /// Takes a health report received at `now_ns`: only the bridge's ([`LINK_NODE`], or
    /// `<namespace>/bridge`) counts, dated when it was made (its stamp, never after its
    /// receipt: a report from a topic's history is old). Returns whether it was the bridge's.
    /// Allocates nothing: a hand node's control loop takes the reports.
    pub fn report(&mut self, health: &NodeHealth, now_ns: u64) -> bool {
        let name = health.name_bytes();
        let bridge = name == LINK_NODE.as_bytes()
            || name
                .strip_suffix(LINK_NODE.as_bytes())
                .is_some_and(|ns| ns.ends_with(b"/"));
        if !bridge {
            return false;
        }
        // A link that is down gives no allowance: nothing arrives over it anyway. An up link
        // counts at least 1 ns, so it is seen as up however short its delay. The median, not
        // the p99: the timeout covers the jitter above it, and a backlog that a stalled link
        // delivers late moves a median only when it is half the bridge's window.
        let up = health.detail("link_state") == Some(1.0);
        let delay = if up {
            let ms = health.detail(LINK_DELAY_DETAIL).unwrap_or(0.0);
            let ns = if ms.is_finite() {
                ms.max(0.0) * 1e6
            } else {
                0.0
            };
            (ns as u64).clamp(1, self.max_ns.max(1))
        } else {
            0
        };
        self.latest = Some((delay, crate::sample_time(health.header.stamp_ns, now_ns)));
        true
    }

    /// The delay to allow for at `now_ns` (ns): the bridge's newest one-way median while its
    /// reports keep coming and say the link is up, else 0.
    pub fn allowance_ns(&self, now_ns: u64) -> u64 {
        match self.latest {
            Some((delay, at)) if now_ns.saturating_sub(at) <= LINK_REPORT_NS => delay,
            _ => 0,
        }
    }

    /// Whether a link between stations is up in the path at `now_ns`.
    pub fn up(&self, now_ns: u64) -> bool {
        self.allowance_ns(now_ns) > 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bridge(name: &str, one_way_ms: f64, up: bool) -> NodeHealth {
        let mut h = NodeHealth::default();
        h.set_name(name);
        h.set_detail("link_state", if up { 1.0 } else { 0.0 });
        h.set_detail(LINK_DELAY_DETAIL, one_way_ms);
        h.header.stamp_ns = 1;
        h
    }

    #[test]
    fn only_the_bridges_report_counts_capped_while_it_keeps_coming() {
        let ms = 1_000_000;
        let mut link = LinkDelay::new(1000 * ms);
        assert!(!link.up(0));
        assert!(!link.report(&bridge("feedback", 250.0, true), 0));
        assert!(!link.report(&bridge("sidebridge", 250.0, true), 0));
        assert!(!link.up(0));
        assert!(link.report(&bridge("left/bridge", 250.0, true), 0));
        assert_eq!(link.allowance_ns(1), 250 * ms);
        assert!(link.report(&bridge("bridge", 5000.0, true), 0));
        assert_eq!(link.allowance_ns(1), 1000 * ms, "capped");
        assert_eq!(link.allowance_ns(LINK_REPORT_NS), 1000 * ms);
        assert_eq!(link.allowance_ns(LINK_REPORT_NS + 1), 0, "lapsed");
        link.report(&bridge("bridge", 0.0, true), 0);
        assert!(link.up(1), "a fast link is still a link");
        link.report(&bridge("bridge", 250.0, false), 0);
        assert!(!link.up(1), "down");
        link.report(&bridge("bridge", f64::NAN, true), 0);
        assert_eq!(link.allowance_ns(1), 1);
    }
}
