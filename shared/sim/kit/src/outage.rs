//! A fault that lasts a while (a link down, a bus off): on now, off again after its time on a
//! timer thread; a later outage replaces the end time of one still running.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Outages of one kind (e.g. the link); clone it into whoever starts them.
#[derive(Debug, Clone, Default)]
pub struct Outage {
    epoch: Arc<AtomicU64>,
}

impl Outage {
    /// A kind of outage, none running.
    pub fn new() -> Self {
        Self::default()
    }

    /// Runs `on` now and `off` after `duration` on a thread named `name`, unless another
    /// outage started meanwhile (its own `off` ends it). Without a thread, `off` runs at once
    /// (the fault is not left on for good).
    pub fn start(
        &self,
        name: &str,
        duration: Duration,
        on: impl FnOnce(),
        off: impl FnOnce() + Send + 'static,
    ) {
        let epoch = self.epoch.fetch_add(1, Ordering::SeqCst) + 1;
        on();
        let current = Arc::clone(&self.epoch);
        let off = Arc::new(std::sync::Mutex::new(Some(off)));
        let timed = Arc::clone(&off);
        let spawned = std::thread::Builder::new()
            .name(name.to_string())
            .spawn(move || {
                std::thread::sleep(duration);
                if current.load(Ordering::SeqCst) == epoch {
                    if let Some(off) = crate::lock(&timed).take() {
                        off();
                    }
                }
            });
        if spawned.is_err() {
            if let Some(off) = crate::lock(&off).take() {
                off();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use std::sync::atomic::AtomicBool;

    #[test]
    fn an_outage_ends_after_its_time_and_a_later_one_replaces_the_end() {
        let down = Arc::new(AtomicBool::new(false));
        let outage = Outage::new();
        let set = |v: bool| {
            let down = Arc::clone(&down);
            move || down.store(v, Ordering::SeqCst)
        };
        outage.start("test-up", Duration::from_millis(50), set(true), set(false));
        assert!(down.load(Ordering::SeqCst));
        outage.start("test-up", Duration::from_secs(600), set(true), set(false));
        // Long enough for the first timer to end: it finds itself replaced.
        std::thread::sleep(Duration::from_millis(300));
        assert!(down.load(Ordering::SeqCst), "the first end was replaced");
        outage.start("test-up", Duration::from_millis(10), set(true), set(false));
        let until = std::time::Instant::now() + Duration::from_secs(30);
        while down.load(Ordering::SeqCst) && std::time::Instant::now() < until {
            std::thread::sleep(Duration::from_millis(10));
        }
        assert!(!down.load(Ordering::SeqCst), "the second ends it");
    }
}
