//! Typed ports: a publish-subscribe port paired with an event port, so that a publisher wakes
//! its subscribers, plus the bookkeeping every node needs (stamping, freshness, drop counting).

use core::cell::{Cell, RefCell};
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use teleop_msgs::Message;

use crate::clock::now_ns;
use crate::ipc::RuntimeError;
use crate::Service;

/// Sends `M` samples and wakes every subscriber of the topic.
pub struct Publisher<M: Message> {
    publisher: iceoryx2::port::publisher::Publisher<Service, M, ()>,
    notifier: Notifier<Service>,
    source_id: u32,
    seq: u64,
}

impl<M: Message> Publisher<M> {
    pub(crate) fn new(
        publisher: iceoryx2::port::publisher::Publisher<Service, M, ()>,
        notifier: Notifier<Service>,
        source_id: u32,
    ) -> Self {
        Self {
            publisher,
            notifier,
            source_id,
            seq: 0,
        }
    }

    /// Stamps `msg` (next sequence number, `stamp_ns` = now, this node's source id; an
    /// `origin_ns` of 0 becomes the stamp, i.e. the sample is its own origin), sends it and wakes
    /// the subscribers. Returns the header as sent.
    pub fn publish(&mut self, msg: &M) -> Result<teleop_msgs::SampleHeader, RuntimeError> {
        let mut msg = *msg;
        self.seq += 1;
        let header = msg.header_mut();
        header.seq = self.seq;
        header.stamp_ns = now_ns();
        if header.origin_ns == 0 {
            header.origin_ns = header.stamp_ns;
        }
        header.source_id = self.source_id;
        let sent = *msg.header();
        self.send_as_is(&msg)?;
        Ok(sent)
    }

    /// Sends `msg` exactly as given (for replay: the recorded header is kept) and wakes the
    /// subscribers.
    pub fn send_as_is(&mut self, msg: &M) -> Result<(), RuntimeError> {
        let sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| RuntimeError::ipc("loaning sample", M::TOPIC, e))?;
        sample
            .write_payload(*msg)
            .send()
            .map_err(|e| RuntimeError::ipc("sending sample", M::TOPIC, e))?;
        self.notifier
            .notify()
            .map_err(|e| RuntimeError::ipc("notifying subscribers", M::TOPIC, e))?;
        Ok(())
    }
}

/// When a sample stamped `stamp_ns` and received at `received_ns` (both CLOCK_MONOTONIC) was
/// made, for judging its freshness: its stamp, but never later than its receipt (a stamp from
/// the future, or from another clock, counts from the receipt). Unstamped (0) is as old as can
/// be.
pub fn sample_time(stamp_ns: u64, received_ns: u64) -> u64 {
    stamp_ns.min(received_ns)
}

/// Most distinct publishers per topic whose sequence numbers are tracked for drop counting.
const TRACKED_SOURCES: usize = 16;

/// Receives `M` samples. All methods take `&self`, so a subscriber can be attached to an
/// [`EventLoop`](crate::EventLoop) and read from its callback at the same time.
pub struct Subscriber<M: Message> {
    subscriber: iceoryx2::port::subscriber::Subscriber<Service, M, ()>,
    listener: Listener<Service>,
    latest: Cell<Option<M>>,
    received_at: Cell<Option<Instant>>,
    /// When the newest sample was received, CLOCK_MONOTONIC ns.
    received_ns: Cell<u64>,
    received: Cell<u64>,
    dropped: Cell<u64>,
    errors: Cell<u64>,
    /// The source of the newest sample, and how often it changed from one sample to the next.
    last_source: Cell<Option<u32>>,
    writer_changes: Cell<u64>,
    last_seq: RefCell<[(u32, u64); TRACKED_SOURCES]>,
}

impl<M: Message> Subscriber<M> {
    pub(crate) fn new(
        subscriber: iceoryx2::port::subscriber::Subscriber<Service, M, ()>,
        listener: Listener<Service>,
    ) -> Self {
        Self {
            subscriber,
            listener,
            latest: Cell::new(None),
            received_at: Cell::new(None),
            received_ns: Cell::new(0),
            received: Cell::new(0),
            dropped: Cell::new(0),
            errors: Cell::new(0),
            last_source: Cell::new(None),
            writer_changes: Cell::new(0),
            last_seq: RefCell::new([(0, 0); TRACKED_SOURCES]),
        }
    }

    /// The event port that wakes this subscriber (for [`EventLoop`](crate::EventLoop)).
    pub fn listener(&self) -> &Listener<Service> {
        &self.listener
    }

    /// Consumes pending wake-ups and every queued sample, calling `f` for each in order.
    /// Updates [`latest`](Self::latest), the receive time and the drop count. Returns how many
    /// samples were taken.
    pub fn drain(&self, mut f: impl FnMut(&M)) -> usize {
        if self.listener.try_wait(|_| {}).is_err() {
            self.errors.set(self.errors.get() + 1);
        }
        let mut n = 0;
        loop {
            match self.subscriber.receive() {
                Ok(Some(sample)) => {
                    let msg = *sample.payload();
                    drop(sample);
                    self.account(&msg);
                    f(&msg);
                    n += 1;
                }
                Ok(None) => break,
                Err(e) => {
                    self.errors.set(self.errors.get() + 1);
                    tracing::warn!(topic = M::TOPIC, error = ?e, "receive failed");
                    break;
                }
            }
        }
        n
    }

    /// Drains the queue and returns the newest sample ever received (None if none yet).
    pub fn poll_latest(&self) -> Option<M> {
        self.drain(|_| {});
        self.latest.get()
    }

    /// The newest sample received so far, without receiving.
    pub fn latest(&self) -> Option<M> {
        self.latest.get()
    }

    /// Time since the newest sample was received, `None` if nothing was received yet.
    pub fn age(&self, now: Instant) -> Option<Duration> {
        self.received_at
            .get()
            .map(|t| now.saturating_duration_since(t))
    }

    /// True when the newest sample was made within `timeout` of `now`: its age counts from its
    /// stamp ([`sample_time`]), so a sample from the topic's history, made long before this
    /// subscriber received it, is not fresh.
    pub fn is_fresh(&self, now: Instant, timeout: Duration) -> bool {
        self.is_fresh_over_link(now, timeout, 0)
    }

    /// [`is_fresh`](Self::is_fresh) for a topic that crossed a link between stations with this
    /// measured one-way delay (ns, see [`crate::link`]): the stamp counts `link_delay_ns` later,
    /// never later than the receipt, so delayed but continuing samples are fresh and a link
    /// that stops is stale `timeout` after its last sample arrived.
    pub fn is_fresh_over_link(&self, now: Instant, timeout: Duration, link_delay_ns: u64) -> bool {
        let Some(age) = self.age(now) else {
            return false;
        };
        let received_ns = self.received_ns.get();
        let made = sample_time(
            self.latest.get().map_or(0, |m| {
                crate::link::stamp_over_link(m.header().stamp_ns, link_delay_ns)
            }),
            received_ns,
        );
        age + Duration::from_nanos(received_ns - made) <= timeout
    }

    /// Samples received since creation.
    pub fn received(&self) -> u64 {
        self.received.get()
    }

    /// Samples lost before they were received, from gaps in the publishers' sequence numbers.
    pub fn dropped(&self) -> u64 {
        self.dropped.get()
    }

    /// Receive errors since creation.
    pub fn errors(&self) -> u64 {
        self.errors.get()
    }

    /// How often a sample came from another source (`header.source_id`) than the one before:
    /// on a topic with one writer, zero; more than one writer interleaving shows here.
    pub fn writer_changes(&self) -> u64 {
        self.writer_changes.get()
    }

    fn account(&self, msg: &M) {
        let header = msg.header();
        self.latest.set(Some(*msg));
        self.received_at.set(Some(Instant::now()));
        self.received_ns.set(now_ns());
        self.received.set(self.received.get() + 1);
        if self
            .last_source
            .replace(Some(header.source_id))
            .is_some_and(|before| before != header.source_id)
        {
            self.writer_changes.set(self.writer_changes.get() + 1);
        }
        let mut table = self.last_seq.borrow_mut();
        let slot = table
            .iter()
            .position(|(id, seq)| *id == header.source_id && *seq != 0)
            .or_else(|| table.iter().position(|(_, seq)| *seq == 0));
        if let Some(i) = slot {
            let (_, last) = table[i];
            // A publisher that restarted begins at 1 again: not a loss.
            // Saturating: a sequence number at u64::MAX is followed by no gap, not an overflow.
            if last != 0 && header.seq > last.saturating_add(1) {
                self.dropped
                    .set(self.dropped.get() + (header.seq - last - 1));
            }
            table[i] = (header.source_id, header.seq);
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use teleop_msgs::HandCommand;

    #[test]
    fn samples_from_another_writer_are_counted() {
        let dir = tempfile::tempdir().unwrap();
        let settings = crate::IpcSettings::isolated(dir.path());
        let node = crate::NodeRuntime::new("writers", &settings).unwrap();
        let mut publisher = node.publisher::<HandCommand>().unwrap();
        let subscriber = node.subscriber::<HandCommand>().unwrap();
        let mut msg = HandCommand::default();
        for (seq, source) in [(1, 7), (2, 7), (1, 8), (3, 7), (4, 7)] {
            msg.header.seq = seq;
            msg.header.source_id = source;
            publisher.send_as_is(&msg).unwrap();
        }
        subscriber.drain(|_| {});
        assert_eq!(subscriber.writer_changes(), 2);
        drop((publisher, subscriber, node));
        settings.remove_shared_memory();
    }

    #[test]
    fn sequence_numbers_near_the_end_of_u64_do_not_overflow_the_drop_count() {
        let dir = tempfile::tempdir().unwrap();
        let settings = crate::IpcSettings::isolated(dir.path());
        let node = crate::NodeRuntime::new("seq-edge", &settings).unwrap();
        let mut publisher = node.publisher::<HandCommand>().unwrap();
        let subscriber = node.subscriber::<HandCommand>().unwrap();
        let mut msg = HandCommand::default();
        msg.header.source_id = 9;
        for seq in [u64::MAX - 3, u64::MAX, u64::MAX, 1] {
            msg.header.seq = seq;
            publisher.send_as_is(&msg).unwrap();
            subscriber.drain(|_| {});
        }
        assert_eq!(subscriber.received(), 4);
        assert_eq!(subscriber.dropped(), 2);
        settings.remove_shared_memory();
    }
}
