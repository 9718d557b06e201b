//! Property and layout tests of the codecs: the decoders are total, encodings round-trip, and
//! the bytes are those of ETG.1000.4 (mailbox header) and ETG.1000.6 (FoE).
#![allow(clippy::unwrap_used)]

use proptest::collection::vec;
use proptest::prelude::*;
use teleop_foe::mailbox::{self, MailboxError, MailboxHeader};
use teleop_foe::packet::{self, opcode, ErrorCode, Packet, PacketDecodeError};

#[test]
fn packet_layouts() {
    assert_eq!(
        Packet::WriteRequest {
            password: 0x0102_0304,
            name: b"fw.bin"
        }
        .to_vec(),
        [2, 0, 4, 3, 2, 1, b'f', b'w', b'.', b'b', b'i', b'n']
    );
    assert_eq!(
        Packet::ReadRequest {
            password: 0,
            name: b"x"
        }
        .to_vec(),
        [1, 0, 0, 0, 0, 0, b'x']
    );
    assert_eq!(
        Packet::Data {
            packet: 0x0000_0102,
            data: &[0xAA, 0xBB]
        }
        .to_vec(),
        [3, 0, 2, 1, 0, 0, 0xAA, 0xBB]
    );
    assert_eq!(Packet::Ack { packet: 1 }.to_vec(), [4, 0, 1, 0, 0, 0]);
    assert_eq!(
        Packet::Error {
            code: ErrorCode::PACKET_NUMBER,
            text: b"n"
        }
        .to_vec(),
        [5, 0, 0x05, 0x80, 0, 0, b'n']
    );
    assert_eq!(
        Packet::Busy {
            done: 3,
            entire: 100,
            text: b""
        }
        .to_vec(),
        [6, 0, 3, 0, 100, 0]
    );
}

#[test]
fn decoding_edge_cases() {
    assert_eq!(Packet::decode(&[]), Err(PacketDecodeError::TooShort(0)));
    assert_eq!(
        Packet::decode(&[4, 0, 1, 0, 0]),
        Err(PacketDecodeError::TooShort(5))
    );
    assert_eq!(
        Packet::decode(&[7, 0, 0, 0, 0, 0]),
        Err(PacketDecodeError::UnknownOpcode(7))
    );
    assert_eq!(
        Packet::decode(&[0, 0, 0, 0, 0, 0]),
        Err(PacketDecodeError::UnknownOpcode(0))
    );
    // Reserved byte and bytes after an ACK are ignored.
    assert_eq!(
        Packet::decode(&[4, 0xFF, 9, 0, 0, 0, 1, 2]),
        Ok(Packet::Ack { packet: 9 })
    );
    assert_eq!(packet::text(b"bad file\0\0junk"), "bad file");
    assert_eq!(packet::text(&[0xFF, b'a']), "\u{FFFD}a");
}

#[test]
fn error_codes_are_named() {
    assert_eq!(
        ErrorCode::NOT_FOUND.to_string(),
        "0x8001 (not found)",
        "ETG.1000.6 FoE error codes"
    );
    for (code, value) in [
        (ErrorCode::NOT_DEFINED, 0x8000),
        (ErrorCode::ACCESS_DENIED, 0x8002),
        (ErrorCode::DISK_FULL, 0x8003),
        (ErrorCode::ILLEGAL, 0x8004),
        (ErrorCode::PACKET_NUMBER, 0x8005),
        (ErrorCode::ALREADY_EXISTS, 0x8006),
        (ErrorCode::NO_USER, 0x8007),
        (ErrorCode::BOOTSTRAP_ONLY, 0x8008),
        (ErrorCode::NOT_IN_BOOTSTRAP, 0x8009),
        (ErrorCode::NO_RIGHTS, 0x800A),
        (ErrorCode::PROGRAM_ERROR, 0x800B),
        (ErrorCode::INVALID_CHECKSUM, 0x800C),
        (ErrorCode::INVALID_FIRMWARE, 0x800D),
        (ErrorCode::NO_FILE, 0x800F),
    ] {
        assert_eq!(code.0, value);
        assert!(code.description().is_some());
    }
    assert_eq!(ErrorCode(0x1234).to_string(), "0x1234");
}

#[test]
fn a_whole_request_message() {
    let body = Packet::Ack { packet: 2 }.to_vec();
    let m = mailbox::request(mailbox::mailbox_type::FOE, 5, &body).unwrap();
    assert_eq!(m, [6, 0, 0, 0, 0, 0x54, 4, 0, 2, 0, 0, 0]);
    let mut padded = m.clone();
    padded.resize(128, 0);
    let (h, data) = MailboxHeader::decode(&padded).unwrap();
    assert_eq!((h.mailbox_type, h.counter, h.length), (4, 5, 6));
    assert_eq!(Packet::decode(data), Ok(Packet::Ack { packet: 2 }));
    assert!(mailbox::request(4, 1, &vec![0; 70_000]).is_none());
}

fn arb_packet() -> impl Strategy<Value = (u8, u32, u16, u16, Vec<u8>)> {
    (
        1u8..=6,
        any::<u32>(),
        any::<u16>(),
        any::<u16>(),
        vec(any::<u8>(), 0..300),
    )
}

fn build(parts: &(u8, u32, u16, u16, Vec<u8>)) -> Packet<'_> {
    let (op, field, done, entire, bytes) = parts;
    match *op {
        opcode::RRQ => Packet::ReadRequest {
            password: *field,
            name: bytes,
        },
        opcode::WRQ => Packet::WriteRequest {
            password: *field,
            name: bytes,
        },
        opcode::DATA => Packet::Data {
            packet: *field,
            data: bytes,
        },
        opcode::ACK => Packet::Ack { packet: *field },
        opcode::ERR => Packet::Error {
            code: ErrorCode(*field),
            text: bytes,
        },
        _ => Packet::Busy {
            done: *done,
            entire: *entire,
            text: bytes,
        },
    }
}

proptest! {
    #[test]
    fn packet_decoder_is_total(bytes in vec(any::<u8>(), 0..400)) {
        match Packet::decode(&bytes) {
            Ok(p) => {
                prop_assert!(bytes.len() >= packet::HEADER_LEN);
                prop_assert_eq!(p.opcode(), bytes[0]);
                // Re-encoding gives the bytes back, up to the reserved byte and ACK padding.
                let again = p.to_vec();
                prop_assert_eq!(&again[2..], &bytes[2..again.len()]);
            }
            Err(PacketDecodeError::TooShort(n)) => {
                prop_assert_eq!(n, bytes.len());
                prop_assert!(n < packet::HEADER_LEN);
            }
            Err(PacketDecodeError::UnknownOpcode(op)) => prop_assert!(!(1..=6).contains(&op)),
        }
    }

    #[test]
    fn packets_round_trip(parts in arb_packet()) {
        let p = build(&parts);
        let bytes = p.to_vec();
        prop_assert_eq!(bytes.len(), p.encoded_len());
        prop_assert_eq!(Packet::decode(&bytes), Ok(p));
    }

    #[test]
    fn mailbox_decoder_is_total(bytes in vec(any::<u8>(), 0..300)) {
        match MailboxHeader::decode(&bytes) {
            Ok((h, data)) => {
                prop_assert_eq!(data.len(), usize::from(h.length));
                prop_assert!(h.channel < 64 && h.priority < 4 && h.mailbox_type < 16 && h.counter < 8);
                prop_assert_eq!(&h.encode()[..5], &bytes[..5]);
                prop_assert_eq!(h.encode()[5], bytes[5] & 0x7F);
            }
            Err(mailbox::MailboxDecodeError::TooShort(n)) => prop_assert!(n < mailbox::HEADER_LEN),
            Err(mailbox::MailboxDecodeError::Length { length, available }) => {
                prop_assert!(usize::from(length) > available);
            }
        }
        let _ = MailboxError::decode(&bytes);
    }

    #[test]
    fn mailbox_headers_round_trip(
        length in any::<u16>(), address in any::<u16>(), channel in 0u8..64, priority in 0u8..4,
        mailbox_type in 0u8..16, counter in 0u8..8,
    ) {
        let h = MailboxHeader { length, address, channel, priority, mailbox_type, counter };
        let mut bytes = h.encode().to_vec();
        bytes.resize(mailbox::HEADER_LEN + usize::from(length), 0);
        let (back, data) = MailboxHeader::decode(&bytes).unwrap();
        prop_assert_eq!(back, h);
        prop_assert_eq!(data.len(), usize::from(length));
    }
}
