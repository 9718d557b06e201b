//! [`Sample`]: any payload of the message contract as one fixed-size value, so that both
//! sources (live subscribers and recordings) hand the content layer the same thing.

use teleop_msgs::{
    DeviceInfo, EStop, EStopAck, Episode, GloveDiagnostics, GloveForceCommand, GloveState,
    HandCommand, HandState, Message, NodeHealth, SampleHeader, Tactile,
};

/// One sample of a contract topic. Fixed size and heap free, so that it travels through the
/// live source's bounded channel without allocating.
#[allow(clippy::large_enum_variant)] // copies of fixed-size samples, by design
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sample {
    /// `glove/state`.
    GloveState(GloveState),
    /// `glove/diagnostics`.
    GloveDiagnostics(GloveDiagnostics),
    /// `glove/force_command`.
    GloveForceCommand(GloveForceCommand),
    /// `hand/command`.
    HandCommand(HandCommand),
    /// `hand/state`.
    HandState(HandState),
    /// `hand/tactile`.
    Tactile(Tactile),
    /// `health`.
    Health(NodeHealth),
    /// `estop`.
    EStop(EStop),
    /// `device/info`.
    DeviceInfo(DeviceInfo),
    /// `estop/ack`.
    EStopAck(EStopAck),
    /// `episode`.
    Episode(Episode),
}

fn decode_as<M: Message>(payload: &[u8], wrap: fn(M) -> Sample) -> Option<Sample> {
    M::from_bytes(payload).ok().map(wrap)
}

impl Sample {
    /// The payload of `topic` (raw `repr(C)` bytes, as in shared memory and behind the CDR
    /// header in recordings). `None` for a topic the viewer does not show or bytes of the
    /// wrong size.
    pub fn decode(topic: &str, payload: &[u8]) -> Option<Self> {
        match topic {
            GloveState::TOPIC => decode_as(payload, Self::GloveState),
            GloveDiagnostics::TOPIC => decode_as(payload, Self::GloveDiagnostics),
            GloveForceCommand::TOPIC => decode_as(payload, Self::GloveForceCommand),
            HandCommand::TOPIC => decode_as(payload, Self::HandCommand),
            HandState::TOPIC => decode_as(payload, Self::HandState),
            Tactile::TOPIC => decode_as(payload, Self::Tactile),
            NodeHealth::TOPIC => decode_as(payload, Self::Health),
            EStop::TOPIC => decode_as(payload, Self::EStop),
            DeviceInfo::TOPIC => decode_as(payload, Self::DeviceInfo),
            EStopAck::TOPIC => decode_as(payload, Self::EStopAck),
            Episode::TOPIC => decode_as(payload, Self::Episode),
            _ => None,
        }
    }

    /// The topic it came from.
    pub fn topic(&self) -> &'static str {
        match self {
            Self::GloveState(_) => GloveState::TOPIC,
            Self::GloveDiagnostics(_) => GloveDiagnostics::TOPIC,
            Self::GloveForceCommand(_) => GloveForceCommand::TOPIC,
            Self::HandCommand(_) => HandCommand::TOPIC,
            Self::HandState(_) => HandState::TOPIC,
            Self::Tactile(_) => Tactile::TOPIC,
            Self::Health(_) => NodeHealth::TOPIC,
            Self::EStop(_) => EStop::TOPIC,
            Self::DeviceInfo(_) => DeviceInfo::TOPIC,
            Self::EStopAck(_) => EStopAck::TOPIC,
            Self::Episode(_) => Episode::TOPIC,
        }
    }

    /// The common header.
    pub fn header(&self) -> &SampleHeader {
        match self {
            Self::GloveState(m) => m.header(),
            Self::GloveDiagnostics(m) => m.header(),
            Self::GloveForceCommand(m) => m.header(),
            Self::HandCommand(m) => m.header(),
            Self::HandState(m) => m.header(),
            Self::Tactile(m) => m.header(),
            Self::Health(m) => m.header(),
            Self::EStop(m) => m.header(),
            Self::DeviceInfo(m) => m.header(),
            Self::EStopAck(m) => m.header(),
            Self::Episode(m) => m.header(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_contract_topic_decodes() {
        for t in teleop_msgs::topics() {
            let zeros = vec![0u8; t.size];
            let s = Sample::decode(t.name, &zeros).expect(t.name);
            assert_eq!(s.topic(), t.name);
            assert_eq!(s.header().seq, 0);
        }
        assert_eq!(Sample::decode("glove/state", &[0u8; 3]), None);
        assert_eq!(Sample::decode("no/such", &[]), None);
    }
}
