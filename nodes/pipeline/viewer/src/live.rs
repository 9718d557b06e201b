//! The live source: subscribes to every topic of the running pipeline and streams it to rerun
//! without ever holding anyone up.
//!
//! Two threads. The subscriber (the caller's thread) sleeps in an [`EventLoop`] until a topic
//! has data, drains it, thins 1 kHz streams to [`SceneConfig::scalar_hz`] and hands each
//! sample to a bounded channel with `try_send`: when the logging side lags, samples are dropped
//! and counted, never waited for ([`Forwarder`]). The logger thread turns samples into frames
//! ([`Scene`]) and logs them; once a second it logs the drop counts as scalars
//! (`health/viewer/...`) and warns when they grew. iceoryx2 itself never blocks a publisher: a
//! subscriber that falls behind loses its oldest queued samples, which show as sequence gaps
//! (counted as `missed`).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use teleop_msgs::{topics, visit_topic, Message, TopicVisitor};
use teleop_runtime::{
    now_ns, EventLoop, Flow, Input, NodeRuntime, Service, StopReason, Subscriber, Wake,
};

use crate::content::{Decimator, Scene, SceneConfig};
use crate::kinematics::RobotHand;
use crate::logger::RerunLogger;
use crate::sample::Sample;

/// A sample and when the viewer took it (CLOCK_MONOTONIC ns).
#[derive(Debug, Clone, Copy)]
pub struct Received {
    /// The sample.
    pub sample: Sample,
    /// When it was taken from its topic.
    pub received_ns: u64,
}

/// Counters shared by the two threads.
#[derive(Debug, Default)]
pub struct LiveCounters {
    /// Samples handed to the logger.
    pub forwarded: AtomicU64,
    /// Samples dropped because the logger's queue was full.
    pub queue_full: AtomicU64,
    /// Samples lost before the viewer received them (sequence gaps).
    pub missed: AtomicU64,
    /// Samples skipped by decimation (by design, not a loss).
    pub decimated: AtomicU64,
}

/// What happened to an offered sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Offer {
    /// Queued for the logger.
    Sent,
    /// Skipped by decimation.
    Decimated,
    /// Dropped: the queue was full.
    Dropped,
    /// The logger is gone.
    Closed,
}

/// The subscriber side's hand-off: decimation, then a non-blocking send that drops and counts
/// when the queue is full.
pub struct Forwarder {
    tx: SyncSender<Received>,
    gate: Decimator,
    counters: Arc<LiveCounters>,
}

impl Forwarder {
    /// Sends into `tx`, at most `max_hz` samples per second per topic and publisher.
    pub fn new(tx: SyncSender<Received>, max_hz: f64, counters: Arc<LiveCounters>) -> Self {
        Self {
            tx,
            gate: Decimator::new(max_hz),
            counters,
        }
    }

    /// Offers a sample; never blocks.
    pub fn offer(&mut self, sample: Sample, received_ns: u64) -> Offer {
        let h = sample.header();
        if !self.gate.admit(sample.topic(), h.source_id, h.stamp_ns) {
            self.counters.decimated.fetch_add(1, Ordering::Relaxed);
            return Offer::Decimated;
        }
        match self.tx.try_send(Received {
            sample,
            received_ns,
        }) {
            Ok(()) => {
                self.counters.forwarded.fetch_add(1, Ordering::Relaxed);
                Offer::Sent
            }
            Err(TrySendError::Full(_)) => {
                self.counters.queue_full.fetch_add(1, Ordering::Relaxed);
                Offer::Dropped
            }
            Err(TrySendError::Disconnected(_)) => Offer::Closed,
        }
    }
}

/// Live options.
#[derive(Debug, Clone, Copy)]
pub struct LiveOptions {
    /// Decimation and the time origin.
    pub scene: SceneConfig,
    /// Capacity of the queue between the threads, samples.
    pub queue: usize,
    /// How often the drop counts are logged (and warned about when they grew).
    pub report_every: Duration,
    /// Stop after this long (`None`: until SIGINT/SIGTERM).
    pub duration: Option<Duration>,
}

impl Default for LiveOptions {
    fn default() -> Self {
        Self {
            scene: SceneConfig::default(),
            queue: 4096,
            report_every: Duration::from_secs(1),
            duration: None,
        }
    }
}

/// What a live session saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LiveSummary {
    /// Samples handed to the logger.
    pub forwarded: u64,
    /// Samples dropped because the logger lagged.
    pub queue_full: u64,
    /// Samples lost before the viewer received them.
    pub missed: u64,
    /// Samples skipped by decimation.
    pub decimated: u64,
    /// Frames logged.
    pub frames: u64,
}

/// One subscribed topic.
trait Tap {
    fn listener(&self) -> &Listener<Service>;
    /// Offers every queued sample; false once the logger is gone.
    fn drain(&self, out: &mut Forwarder) -> bool;
    fn missed(&self) -> u64;
}

struct TopicTap<M: Message> {
    sub: Subscriber<M>,
}

impl<M: Message> Tap for TopicTap<M> {
    fn listener(&self) -> &Listener<Service> {
        self.sub.listener()
    }
    fn drain(&self, out: &mut Forwarder) -> bool {
        let mut open = true;
        self.sub.drain(|m| {
            if let Some(sample) = Sample::decode(M::TOPIC, m.as_bytes()) {
                open &= out.offer(sample, now_ns()) != Offer::Closed;
            }
        });
        open
    }
    fn missed(&self) -> u64 {
        self.sub.dropped()
    }
}

struct MakeTap<'a>(&'a NodeRuntime);

impl TopicVisitor for MakeTap<'_> {
    type Output = anyhow::Result<Box<dyn Tap>>;
    fn visit<M: Message>(self) -> Self::Output {
        Ok(Box::new(TopicTap::<M> {
            sub: self.0.subscriber()?,
        }))
    }
}

/// The logger thread's loop: frames from samples until the channel closes.
pub fn log_loop(
    rx: &Receiver<Received>,
    logger: &RerunLogger,
    scene: &mut Scene,
    counters: &LiveCounters,
    report_every: Duration,
) -> u64 {
    let mut frames = 0u64;
    let mut failed = false;
    let mut last_report = Instant::now();
    let mut reported = (0u64, 0u64);
    let report = |reported: &mut (u64, u64)| {
        let now = (
            counters.queue_full.load(Ordering::Relaxed),
            counters.missed.load(Ordering::Relaxed),
        );
        if now.0 > reported.0 || now.1 > reported.1 {
            tracing::warn!(
                dropped_queue_full = now.0 - reported.0,
                missed = now.1 - reported.1,
                total_dropped = now.0,
                total_missed = now.1,
                "the viewer fell behind; samples dropped (the pipeline is not affected)"
            );
        }
        *reported = now;
        now
    };
    loop {
        match rx.recv_timeout(report_every) {
            Ok(r) => {
                if let Some(frame) = scene.frame(&r.sample, r.received_ns) {
                    match logger.log_frame(&frame) {
                        Ok(()) => frames += 1,
                        Err(e) if !failed => {
                            failed = true;
                            tracing::error!("logging to rerun failed: {e}");
                        }
                        Err(_) => {}
                    }
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if last_report.elapsed() >= report_every {
            last_report = Instant::now();
            let (queue_full, missed) = report(&mut reported);
            let _ = logger.log_frame(&scene.viewer_stats(now_ns(), queue_full, missed));
        }
    }
    let (queue_full, missed) = report(&mut reported);
    let _ = logger.log_frame(&scene.viewer_stats(now_ns(), queue_full, missed));
    frames
}

/// Streams the live pipeline to `logger` until SIGINT/SIGTERM (or `options.duration`), drawing
/// `robot`, or (`None`) the builtin profile of the first hand sample's model.
pub fn run_live(
    runtime: &NodeRuntime,
    logger: RerunLogger,
    options: &LiveOptions,
    robot: Option<RobotHand>,
) -> anyhow::Result<LiveSummary> {
    let mut taps: Vec<Box<dyn Tap>> = Vec::new();
    for t in topics() {
        if let Some(tap) = visit_topic(t.name, MakeTap(runtime)) {
            taps.push(tap?);
        }
    }
    let counters = Arc::new(LiveCounters::default());
    let (tx, rx) = std::sync::mpsc::sync_channel::<Received>(options.queue.max(1));
    let mut forwarder = Forwarder::new(tx, options.scene.scalar_hz, Arc::clone(&counters));

    let mut scene = Scene::new(options.scene, robot);
    logger.log_scene(&scene)?;
    let logging = {
        let counters = Arc::clone(&counters);
        let report_every = options.report_every;
        std::thread::Builder::new()
            .name("viewer-log".into())
            .spawn(move || log_loop(&rx, &logger, &mut scene, &counters, report_every))?
    };

    tracing::info!(topics = taps.len(), "viewing the live pipeline");
    let start = Instant::now();
    let inputs: Vec<Input> = taps.iter().map(|t| Input::new(t.listener())).collect();
    let mut logger_gone = false;
    let stop = EventLoop::new(Duration::from_millis(100)).run(&inputs, |wake| {
        match wake {
            Wake::Input(i) => logger_gone |= !taps[i].drain(&mut forwarder),
            Wake::Timeout(_) | Wake::Tick => {
                let missed: u64 = taps.iter().map(|t| t.missed()).sum();
                counters.missed.store(missed, Ordering::Relaxed);
            }
        }
        if logger_gone || options.duration.is_some_and(|d| start.elapsed() >= d) {
            Flow::Break(())
        } else {
            Flow::Continue(())
        }
    })?;
    let missed: u64 = taps.iter().map(|t| t.missed()).sum();
    counters.missed.store(missed, Ordering::Relaxed);
    drop(forwarder); // closes the channel: the logger drains what is queued and returns
    let frames = logging
        .join()
        .map_err(|_| anyhow::anyhow!("the viewer's logging thread panicked"))?;
    if logger_gone {
        anyhow::bail!("the viewer's logging thread stopped early");
    }
    tracing::info!(
        reason = match stop {
            StopReason::Interrupt => "Ctrl-C",
            StopReason::Terminate => "SIGTERM",
            StopReason::Requested => "duration elapsed",
        },
        "stopped viewing"
    );
    Ok(LiveSummary {
        forwarded: counters.forwarded.load(Ordering::Relaxed),
        queue_full: counters.queue_full.load(Ordering::Relaxed),
        missed,
        decimated: counters.decimated.load(Ordering::Relaxed),
        frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use teleop_msgs::{HandState, SampleHeader};

    fn hand_state(stamp_ns: u64) -> Sample {
        Sample::HandState(HandState {
            header: SampleHeader {
                seq: stamp_ns,
                stamp_ns,
                origin_ns: stamp_ns,
                source_id: 1,
                reserved: 0,
            },
            ..Default::default()
        })
    }

    #[test]
    fn a_full_queue_drops_and_counts_instead_of_blocking() {
        let counters = Arc::new(LiveCounters::default());
        let (tx, rx) = std::sync::mpsc::sync_channel(2);
        let mut f = Forwarder::new(tx, 100.0, Arc::clone(&counters));
        let ms = 1_000_000;
        let offers: Vec<Offer> = (1..=5)
            .map(|i| f.offer(hand_state(i * 20 * ms), 0))
            .collect();
        assert_eq!(
            offers,
            [
                Offer::Sent,
                Offer::Sent,
                Offer::Dropped,
                Offer::Dropped,
                Offer::Dropped
            ]
        );
        // 1 kHz samples in between are decimated, not dropped.
        assert_eq!(f.offer(hand_state(100 * ms + ms), 0), Offer::Decimated);
        assert_eq!(counters.queue_full.load(Ordering::Relaxed), 3);
        assert_eq!(counters.forwarded.load(Ordering::Relaxed), 2);
        assert_eq!(counters.decimated.load(Ordering::Relaxed), 1);
        drop(rx);
        assert_eq!(f.offer(hand_state(200 * ms), 0), Offer::Closed);
    }
}
