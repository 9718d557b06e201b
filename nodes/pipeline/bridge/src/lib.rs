//! `teleop-bridge`: joins two stations (the operator's and the robot's machine) over zenoh.
//!
//! One bridge runs in each station's launch file. It forwards the configured contract topics
//! from local iceoryx2 to zenoh (`direction = "out"`) and from zenoh to local iceoryx2
//! (`"in"`), last value wins, with each sample's contract header kept so that the pipeline counts
//! drops across the link, and its own send stamp so that the hop is measured. Heartbeats carry
//! link liveness, the round trip, the clock offset and the operator's e-stop latch; a peer built
//! with another contract is refused by name. zenoh runs peer to peer with no router and no
//! scouting, over mutual TLS (`teleop certs` makes the certificates), or plain TCP only with
//! `insecure = true`.
//!
//! - [`frame`]: the frames on the wire (pure, total);
//! - [`link`]: clock offset, link state, latency, gaps, the fault injector (pure);
//! - [`config`]: the configuration file and the zenoh configuration made from it;
//! - [`ports`]: the iceoryx2 side for any contract topic;
//! - [`station`]: the running bridge (its threads, zenoh session, health).
//!
//! Must not depend on: any device, the control logic, or a socket protocol of its own (the wire
//! between stations is zenoh's).

pub mod config;
pub mod frame;
pub mod link;
pub mod ports;
pub mod station;

use teleop_msgs::{Message, TopicVisitor};

/// The payload size of a topic (for checks).
pub(crate) struct Size;

impl TopicVisitor for Size {
    type Output = usize;
    fn visit<M: Message>(self) -> usize {
        core::mem::size_of::<M>()
    }
}

struct Schema;

impl TopicVisitor for Schema {
    type Output = String;
    fn visit<M: Message>(self) -> String {
        M::schema()
    }
}

/// FNV-1a (64 bit) over every contract topic's name, schema name, size and schema text: two
/// stations with equal fingerprints read each other's samples the same way.
pub fn schema_fingerprint() -> u64 {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for b in bytes {
            hash ^= u64::from(*b);
            hash = hash.wrapping_mul(0x0100_0000_01b3);
        }
        hash ^= 0xff;
        hash = hash.wrapping_mul(0x0100_0000_01b3);
    };
    for topic in teleop_msgs::topics() {
        eat(topic.name.as_bytes());
        eat(topic.schema_name.as_bytes());
        eat(&(topic.size as u64).to_le_bytes());
        if let Some(schema) = teleop_msgs::visit_topic(topic.name, Schema) {
            eat(schema.as_bytes());
        }
    }
    hash
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_fingerprint_is_stable_within_a_build() {
        assert_eq!(super::schema_fingerprint(), super::schema_fingerprint());
        assert_ne!(super::schema_fingerprint(), 0);
    }
}
