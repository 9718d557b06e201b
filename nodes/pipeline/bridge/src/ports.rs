//! The bridge's iceoryx2 side for any contract topic: an outgoing port takes the newest local
//! sample, an incoming port publishes a sample from the peer with its header kept (sequence and
//! source, so the pipeline counts drops across the link) and its stamps moved into this
//! station's clock.

use teleop_msgs::{Message, SampleHeader, TopicVisitor};
use teleop_runtime::{NodeRuntime, Publisher, RuntimeError, Service, Subscriber};

use crate::link::PeerClock;

/// A local topic whose samples go to the peer.
pub trait OutPort {
    /// The topic (without namespace).
    fn topic(&self) -> &'static str;
    /// The event port that wakes the bridge.
    fn listener(&self) -> &iceoryx2::port::listener::Listener<Service>;
    /// Takes every queued sample and calls `send` with the newest one's bytes and how many
    /// older ones it superseded (last value wins: superseded samples never cross). False when
    /// nothing was queued.
    fn send_newest(&self, send: &mut dyn FnMut(&[u8], u16)) -> bool;
}

/// What became of a sample from the peer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Arrival {
    /// Published here; its header as published.
    Published(SampleHeader),
    /// Older than the topic's `max_age_ms` on arrival: not published.
    Stale(SampleHeader, u64),
}

/// Why a sample from the peer could not be published.
#[derive(Debug, thiserror::Error)]
pub enum InError {
    /// Its bytes are not the topic's payload.
    #[error("{topic}: {detail}")]
    Payload {
        /// The topic.
        topic: &'static str,
        /// The decoder's message.
        detail: String,
    },
    /// iceoryx2 refused it.
    #[error(transparent)]
    Ipc(#[from] RuntimeError),
}

/// A topic whose samples come from the peer.
pub trait InPort {
    /// The topic (without namespace).
    fn topic(&self) -> &'static str;
    /// Publishes `payload` here unless it is older than `max_age_ns` at `now_ns`.
    fn publish(
        &mut self,
        payload: &[u8],
        clock: &PeerClock,
        now_ns: u64,
        max_age_ns: Option<u64>,
    ) -> Result<Arrival, InError>;
}

struct Out<M: Message>(Subscriber<M>);

impl<M: Message> OutPort for Out<M> {
    fn topic(&self) -> &'static str {
        M::TOPIC
    }
    fn listener(&self) -> &iceoryx2::port::listener::Listener<Service> {
        self.0.listener()
    }
    fn send_newest(&self, send: &mut dyn FnMut(&[u8], u16)) -> bool {
        let mut newest = None;
        let taken = self.0.drain(|m| newest = Some(*m));
        match newest {
            Some(m) => {
                send(m.as_bytes(), u16::try_from(taken - 1).unwrap_or(u16::MAX));
                true
            }
            None => false,
        }
    }
}

struct In<M: Message>(Publisher<M>);

impl<M: Message> InPort for In<M> {
    fn topic(&self) -> &'static str {
        M::TOPIC
    }
    fn publish(
        &mut self,
        payload: &[u8],
        clock: &PeerClock,
        now_ns: u64,
        max_age_ns: Option<u64>,
    ) -> Result<Arrival, InError> {
        let mut msg = M::from_bytes(payload).map_err(|e| InError::Payload {
            topic: M::TOPIC,
            detail: e.to_string(),
        })?;
        let header = msg.header_mut();
        header.stamp_ns = clock.to_local(header.stamp_ns);
        header.origin_ns = clock.to_local(header.origin_ns);
        let header = *header;
        if let Some(max_age) = max_age_ns {
            let age = now_ns.saturating_sub(header.stamp_ns);
            if age > max_age {
                return Ok(Arrival::Stale(header, age));
            }
        }
        self.0.send_as_is(&msg)?;
        Ok(Arrival::Published(header))
    }
}

/// Makes the outgoing port of a topic.
pub struct MakeOut<'a>(pub &'a NodeRuntime);

impl TopicVisitor for MakeOut<'_> {
    type Output = Result<Box<dyn OutPort>, RuntimeError>;
    fn visit<M: Message>(self) -> Self::Output {
        Ok(Box::new(Out(self.0.subscriber::<M>()?)))
    }
}

/// Makes the incoming port of a topic.
pub struct MakeIn<'a>(pub &'a NodeRuntime);

impl TopicVisitor for MakeIn<'_> {
    type Output = Result<Box<dyn InPort>, RuntimeError>;
    fn visit<M: Message>(self) -> Self::Output {
        Ok(Box::new(In(self.0.publisher::<M>()?)))
    }
}
