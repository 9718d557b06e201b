//! The bridge's frames on the zenoh key expressions: a fixed little-endian header (format,
//! kind, contract version and schema fingerprint, the sending station's name, the bridge's send
//! stamp), then either one contract sample (its bytes as in shared memory) or a heartbeat.
//!
//! Pure and total: [`decode`] takes any bytes and returns a frame or a [`FrameError`].
//!
//! ```text
//! offset size
//!  0      4   magic "TLBR"
//!  4      1   format (1)
//!  5      1   kind: 0 sample, 1 heartbeat
//!  6      2   superseded: samples the sender skipped since its previous frame on this key
//!             (last value wins), so the receiver tells them from losses (0 for heartbeats)
//!  8      4   contract version (teleop_msgs::CONTRACT_VERSION)
//! 12      8   schema fingerprint (every topic's name, schema and size)
//! 20      8   send stamp: the sending bridge's CLOCK_MONOTONIC, ns
//! 28      1   station name length (1..=32)
//! 29     32   station name, zero padded
//! 61      3   zero
//! 64          sample: u32 length, then the payload
//!             heartbeat: u64 seq, u64 echoed send stamp (the peer's newest heartbeat, 0: none),
//!             u64 hold (ns between receiving that heartbeat and sending this one),
//!             u8 e-stop (0 released, 1 engaged, 2 this station does not send it), 7 zero
//! ```

/// Every frame starts with these four bytes.
pub const MAGIC: [u8; 4] = *b"TLBR";
/// The frame format this code reads and writes.
pub const FORMAT: u8 = 1;
/// Size of the fixed header.
pub const HEADER_LEN: usize = 64;
/// Longest station name.
pub const MAX_STATION: usize = 32;
/// Longest frame a bridge sends or takes (zenoh's `max_message_size`; larger is dropped before
/// it is queued): the header, the length and the largest contract payload fit with room.
pub const MAX_FRAME_LEN: usize = 64 * 1024;
const HEARTBEAT_LEN: usize = 32;

/// What a frame is about: where it came from and which contract it speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Origin {
    /// The sender's contract version.
    pub contract: u32,
    /// The sender's schema fingerprint ([`crate::schema_fingerprint`]).
    pub fingerprint: u64,
    /// When the sending bridge sent it (its CLOCK_MONOTONIC, ns).
    pub send_ns: u64,
    /// Samples the sender skipped (superseded by this one) since its previous frame on the key.
    pub superseded: u16,
    station: [u8; MAX_STATION],
    station_len: u8,
}

impl Origin {
    /// An origin for `station` (at most [`MAX_STATION`] bytes; longer is cut).
    pub fn new(station: &str, contract: u32, fingerprint: u64, send_ns: u64) -> Self {
        let bytes = station.as_bytes();
        let len = bytes.len().min(MAX_STATION);
        let mut name = [0u8; MAX_STATION];
        name[..len].copy_from_slice(&bytes[..len]);
        Self {
            contract,
            fingerprint,
            send_ns,
            superseded: 0,
            station: name,
            station_len: len as u8,
        }
    }

    /// The sending station's name (invalid UTF-8 shows as `?`).
    pub fn station(&self) -> &str {
        core::str::from_utf8(&self.station[..usize::from(self.station_len)]).unwrap_or("?")
    }
}

/// A heartbeat: link liveness, the round trip, the clock offset, and the e-stop state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Heartbeat {
    /// Counts up from 1 per bridge start.
    pub seq: u64,
    /// The send stamp of the newest heartbeat received from the peer (0: none yet).
    pub echo_send_ns: u64,
    /// Time between receiving that heartbeat and sending this one, ns.
    pub hold_ns: u64,
    /// The sending station's e-stop latch.
    pub estop: EStopState,
}

/// The e-stop state a heartbeat carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EStopState {
    /// Released at the sending station.
    Released,
    /// Engaged at the sending station.
    Engaged,
    /// The sending station is not the e-stop's authority.
    #[default]
    NotSent,
}

/// A decoded frame; a sample borrows its payload from the input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame<'a> {
    /// One contract sample's bytes.
    Sample(Origin, &'a [u8]),
    /// A heartbeat.
    Heartbeat(Origin, Heartbeat),
}

/// Why bytes are not a frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Fewer bytes than the frame needs.
    #[error("frame too short: {got} bytes, needs {need}")]
    TooShort {
        /// Bytes needed.
        need: usize,
        /// Bytes given.
        got: usize,
    },
    /// Not a bridge frame.
    #[error("not a teleop-bridge frame (magic {0:02x?})")]
    BadMagic([u8; 4]),
    /// A frame format this bridge does not read.
    #[error("frame format {0}, this bridge reads format {FORMAT}")]
    Format(u8),
    /// An unknown kind.
    #[error("unknown frame kind {0}")]
    Kind(u8),
    /// The station name is empty or too long.
    #[error("bad station name length {0}")]
    Station(u8),
    /// A sample whose length field disagrees with the bytes after it.
    #[error("sample length {declared}, {actual} bytes follow")]
    Length {
        /// The length field.
        declared: u32,
        /// Bytes after it.
        actual: usize,
    },
    /// An unknown e-stop state.
    #[error("unknown e-stop state {0}")]
    EStop(u8),
}

/// Why a well-formed frame from the peer's keys is not accepted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// Sent by another station than the configured peer.
    #[error("a frame from station {from:?}, expected {expected:?}")]
    Station {
        /// The sender's name.
        from: String,
        /// The configured peer.
        expected: String,
    },
    /// The sender speaks another contract.
    #[error(
        "station {station:?} speaks contract v{contract} (schema {fingerprint:016x}), this \
         station v{our_contract} ({our_fingerprint:016x}); build both stations from the same \
         contract"
    )]
    Contract {
        /// The sender's name.
        station: String,
        /// Its contract version.
        contract: u32,
        /// Its schema fingerprint.
        fingerprint: u64,
        /// Ours.
        our_contract: u32,
        /// Ours.
        our_fingerprint: u64,
    },
}

/// Accepts a frame's origin only from `peer` speaking this contract (`contract`, `fingerprint`).
/// The peer is the station the link is bound to: zenoh's access control lets only a link whose
/// certificate names `peer` put on the peer's keys ([`crate::config::BridgeConfig::access_control`]),
/// so a frame that names another station came from the authenticated peer and is refused.
pub fn accept(origin: &Origin, peer: &str, contract: u32, fingerprint: u64) -> Result<(), Refusal> {
    if origin.station() != peer {
        return Err(Refusal::Station {
            from: origin.station().to_string(),
            expected: peer.to_string(),
        });
    }
    if origin.contract != contract || origin.fingerprint != fingerprint {
        return Err(Refusal::Contract {
            station: origin.station().to_string(),
            contract: origin.contract,
            fingerprint: origin.fingerprint,
            our_contract: contract,
            our_fingerprint: fingerprint,
        });
    }
    Ok(())
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut v = [0u8; 4];
    v.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(v)
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut v = [0u8; 8];
    v.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(v)
}

/// Reads one frame from any bytes.
pub fn decode(bytes: &[u8]) -> Result<Frame<'_>, FrameError> {
    if bytes.len() < HEADER_LEN {
        return Err(FrameError::TooShort {
            need: HEADER_LEN,
            got: bytes.len(),
        });
    }
    let magic = [bytes[0], bytes[1], bytes[2], bytes[3]];
    if magic != MAGIC {
        return Err(FrameError::BadMagic(magic));
    }
    if bytes[4] != FORMAT {
        return Err(FrameError::Format(bytes[4]));
    }
    let station_len = bytes[28];
    if station_len == 0 || usize::from(station_len) > MAX_STATION {
        return Err(FrameError::Station(station_len));
    }
    let mut station = [0u8; MAX_STATION];
    station[..usize::from(station_len)].copy_from_slice(&bytes[29..29 + usize::from(station_len)]);
    let origin = Origin {
        contract: u32_at(bytes, 8),
        fingerprint: u64_at(bytes, 12),
        send_ns: u64_at(bytes, 20),
        superseded: u16::from_le_bytes([bytes[6], bytes[7]]),
        station,
        station_len,
    };
    let body = &bytes[HEADER_LEN..];
    match bytes[5] {
        0 => {
            if body.len() < 4 {
                return Err(FrameError::TooShort {
                    need: HEADER_LEN + 4,
                    got: bytes.len(),
                });
            }
            let declared = u32_at(body, 0);
            let payload = &body[4..];
            if usize::try_from(declared).ok() != Some(payload.len()) {
                return Err(FrameError::Length {
                    declared,
                    actual: payload.len(),
                });
            }
            Ok(Frame::Sample(origin, payload))
        }
        1 => {
            if body.len() < HEARTBEAT_LEN {
                return Err(FrameError::TooShort {
                    need: HEADER_LEN + HEARTBEAT_LEN,
                    got: bytes.len(),
                });
            }
            let estop = match body[24] {
                0 => EStopState::Released,
                1 => EStopState::Engaged,
                2 => EStopState::NotSent,
                other => return Err(FrameError::EStop(other)),
            };
            Ok(Frame::Heartbeat(
                origin,
                Heartbeat {
                    seq: u64_at(body, 0),
                    echo_send_ns: u64_at(body, 8),
                    hold_ns: u64_at(body, 16),
                    estop,
                },
            ))
        }
        kind => Err(FrameError::Kind(kind)),
    }
}

fn header(out: &mut Vec<u8>, origin: &Origin, kind: u8) {
    out.clear();
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&[FORMAT, kind]);
    out.extend_from_slice(&origin.superseded.to_le_bytes());
    out.extend_from_slice(&origin.contract.to_le_bytes());
    out.extend_from_slice(&origin.fingerprint.to_le_bytes());
    out.extend_from_slice(&origin.send_ns.to_le_bytes());
    out.push(origin.station_len);
    out.extend_from_slice(&origin.station);
    out.extend_from_slice(&[0; 3]);
}

/// Writes a sample frame into `out` (cleared first; its capacity is reused).
pub fn encode_sample(out: &mut Vec<u8>, origin: &Origin, payload: &[u8]) {
    header(out, origin, 0);
    out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    out.extend_from_slice(payload);
}

/// Writes a heartbeat frame into `out` (cleared first).
pub fn encode_heartbeat(out: &mut Vec<u8>, origin: &Origin, beat: &Heartbeat) {
    header(out, origin, 1);
    out.extend_from_slice(&beat.seq.to_le_bytes());
    out.extend_from_slice(&beat.echo_send_ns.to_le_bytes());
    out.extend_from_slice(&beat.hold_ns.to_le_bytes());
    out.push(match beat.estop {
        EStopState::Released => 0,
        EStopState::Engaged => 1,
        EStopState::NotSent => 2,
    });
    out.extend_from_slice(&[0; 7]);
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use proptest::prelude::*;

    fn origin() -> Origin {
        Origin::new("operator", 2, 0x1122_3344_5566_7788, 1_000_000_007)
    }

    #[test]
    fn sample_bytes_by_hand() {
        let mut out = Vec::new();
        encode_sample(&mut out, &origin(), &[0xaa, 0xbb]);
        assert_eq!(&out[..8], b"TLBR\x01\x00\x00\x00");
        let mut skipping = origin();
        skipping.superseded = 0x0102;
        let mut other = Vec::new();
        encode_sample(&mut other, &skipping, &[]);
        assert_eq!(&other[6..8], &[0x02, 0x01]);
        assert!(matches!(decode(&other), Ok(Frame::Sample(o, _)) if o.superseded == 0x0102));
        assert_eq!(&out[8..12], &[2, 0, 0, 0]);
        assert_eq!(
            &out[12..20],
            &[0x88, 0x77, 0x66, 0x55, 0x44, 0x33, 0x22, 0x11]
        );
        assert_eq!(&out[20..28], &1_000_000_007u64.to_le_bytes());
        assert_eq!(out[28], 8);
        assert_eq!(&out[29..37], b"operator");
        assert!(out[37..64].iter().all(|b| *b == 0));
        assert_eq!(&out[64..], &[2, 0, 0, 0, 0xaa, 0xbb]);
        match decode(&out).unwrap() {
            Frame::Sample(o, payload) => {
                assert_eq!((o, payload), (origin(), &[0xaa, 0xbb][..]));
                assert_eq!(o.station(), "operator");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn heartbeat_round_trip() {
        let beat = Heartbeat {
            seq: 9,
            echo_send_ns: 77,
            hold_ns: 5,
            estop: EStopState::Engaged,
        };
        let mut out = Vec::new();
        encode_heartbeat(&mut out, &origin(), &beat);
        assert_eq!(out.len(), HEADER_LEN + 32);
        assert_eq!(out[HEADER_LEN + 24], 1);
        assert_eq!(decode(&out).unwrap(), Frame::Heartbeat(origin(), beat));
    }

    #[test]
    fn refusals_say_what() {
        let mut out = Vec::new();
        encode_sample(&mut out, &origin(), &[1, 2, 3]);
        assert_eq!(
            decode(&out[..10]),
            Err(FrameError::TooShort { need: 64, got: 10 })
        );
        let mut bad = out.clone();
        bad[0] = b'X';
        assert!(matches!(decode(&bad), Err(FrameError::BadMagic(_))));
        let mut bad = out.clone();
        bad[4] = 2;
        assert_eq!(decode(&bad), Err(FrameError::Format(2)));
        let mut bad = out.clone();
        bad[5] = 7;
        assert_eq!(decode(&bad), Err(FrameError::Kind(7)));
        let mut bad = out.clone();
        bad[28] = 0;
        assert_eq!(decode(&bad), Err(FrameError::Station(0)));
        assert_eq!(
            decode(&out[..out.len() - 1]),
            Err(FrameError::Length {
                declared: 3,
                actual: 2
            })
        );
    }

    #[test]
    fn only_the_peer_speaking_this_contract_is_accepted() {
        let o = origin();
        assert_eq!(accept(&o, "operator", 2, o.fingerprint), Ok(()));
        let e = accept(&o, "robot", 2, o.fingerprint).unwrap_err();
        assert_eq!(
            e.to_string(),
            "a frame from station \"operator\", expected \"robot\""
        );
        let e = accept(&o, "operator", 3, o.fingerprint).unwrap_err();
        assert!(
            e.to_string().starts_with("station \"operator\" speaks contract v2 (schema 1122334455667788), this station v3"),
            "{e}"
        );
        assert!(matches!(
            accept(&o, "operator", 2, 1),
            Err(Refusal::Contract { .. })
        ));
    }

    #[test]
    fn every_contract_topic_fits_in_a_frame() {
        for topic in teleop_msgs::topics() {
            assert!(
                HEADER_LEN + 4 + topic.size <= MAX_FRAME_LEN,
                "{}",
                topic.name
            );
        }
    }

    proptest! {
        #[test]
        fn decode_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let _ = decode(&bytes);
        }

        #[test]
        fn decode_never_panics_on_a_valid_header(
            kind in 0u8..3, len in 0u8..40, tail in proptest::collection::vec(any::<u8>(), 0..80)
        ) {
            let mut out = Vec::new();
            encode_sample(&mut out, &origin(), &[]);
            out.truncate(HEADER_LEN);
            out[5] = kind;
            out[28] = len;
            out.extend_from_slice(&tail);
            let _ = decode(&out);
        }

        #[test]
        fn samples_round_trip(payload in proptest::collection::vec(any::<u8>(), 0..300)) {
            let mut out = Vec::new();
            encode_sample(&mut out, &origin(), &payload);
            prop_assert_eq!(decode(&out), Ok(Frame::Sample(origin(), &payload[..])));
        }
    }
}
