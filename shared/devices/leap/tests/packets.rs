//! Framing details beyond the e-manual's examples: stuffing, the scanner, refusals with their
//! typed errors, the error byte, every instruction a device reads, the Fast Sync Read reply's
//! checks.

use teleop_leap_protocol::crc::crc16;
use teleop_leap_protocol::packet::{
    self, encode, instruction, parse, scan, ErrorByte, ErrorNumber, FastSyncReply, Packet, Request,
    Scan, Status, BROADCAST_ID, HEADER, MAX_LEN,
};
use teleop_leap_protocol::xc330::State;
use teleop_leap_protocol::{DecodeError, EncodeError};

/// A packet with the given ID, instruction and raw (already stuffed, or not) INST..Pn body, LEN
/// and CRC right.
fn raw_packet(id: u8, body: &[u8]) -> Vec<u8> {
    let mut raw = HEADER.to_vec();
    raw.push(id);
    raw.extend_from_slice(&((body.len() + 2) as u16).to_le_bytes());
    raw.extend_from_slice(body);
    let crc = crc16(0, &raw);
    raw.extend_from_slice(&crc.to_le_bytes());
    raw
}

fn request(raw: &[u8]) -> Result<Request<'static>, DecodeError> {
    let scratch: &'static mut [u8] = Box::leak(vec![0u8; MAX_LEN].into_boxed_slice());
    let p = parse(raw, scratch)?;
    Request::from_packet(&p)
}

fn packet(id: u8, inst: u8, params: &[u8]) -> Vec<u8> {
    let mut out = [0u8; 2048];
    let n = encode(id, inst, params, &mut out).expect("encodes");
    out[..n].to_vec()
}

#[test]
fn stuffing_inserts_fd_after_ff_ff_fd() {
    // Write of FD 00 at 0xFFFF: the parameters hold FF FF FD 00, the would-be header.
    let mut out = [0u8; 32];
    let n = packet::write(1, 0xFFFF, &[0xFD, 0x00], &mut out).expect("encodes");
    let body = [0x03, 0xFF, 0xFF, 0xFD, 0xFD, 0x00];
    assert_eq!(&out[..n], raw_packet(1, &body));
    assert_eq!(
        u16::from_le_bytes([out[5], out[6]]),
        8,
        "LEN counts the stuffed byte"
    );
    let mut scratch = [0u8; 16];
    let p = parse(&out[..n], &mut scratch).expect("parses");
    assert_eq!(p.params, [0xFF, 0xFF, 0xFD, 0x00]);
}

#[test]
fn stuffing_covers_the_instruction_byte_and_runs() {
    // INST 0xFF then FF FD: the pattern starts at INST. Two patterns back to back.
    let params = [0xFF, 0xFD, 0xFF, 0xFF, 0xFD, 0xFD];
    let raw = packet(3, 0xFF, &params);
    assert_eq!(
        raw,
        raw_packet(3, &[0xFF, 0xFF, 0xFD, 0xFD, 0xFF, 0xFF, 0xFD, 0xFD, 0xFD])
    );
    let mut scratch = [0u8; 16];
    let p = parse(&raw, &mut scratch).expect("parses");
    assert_eq!((p.instruction, p.params), (0xFF, &params[..]));
}

#[test]
fn a_state_read_that_needs_stuffing() {
    // Present Current -1 mA (FF FF) then a velocity whose low byte is FD: an ordinary status
    // carrying the 10 state bytes holds FF FF FD and is stuffed; the state comes back whole.
    let state = State {
        current_ma: -1,
        velocity: 0xFD,
        position: 2048,
    };
    let mut out = [0u8; 32];
    let n = packet::status(4, 0, &state.encode(), &mut out).expect("encodes");
    assert_eq!(n, teleop_leap_protocol::wire::status_len(10) + 1);
    assert_eq!(&out[9..13], [0xFF, 0xFF, 0xFD, 0xFD]);
    let mut scratch = [0u8; 32];
    let p = parse(&out[..n], &mut scratch).expect("parses");
    let s = Status::from_packet(&p).expect("a status");
    assert_eq!(State::decode(s.params), Ok(state));
}

#[test]
fn a_missing_stuffing_byte_is_refused() {
    // FF FF FD 05 inside the parameters with a right CRC: the sender did not stuff.
    let raw = raw_packet(1, &[0x03, 0x10, 0x00, 0xFF, 0xFF, 0xFD, 0x05]);
    let mut scratch = [0u8; 16];
    assert_eq!(
        parse(&raw, &mut scratch),
        Err(DecodeError::Stuffing { offset: 13 })
    );
    // Also at the very end of the parameters.
    let raw = raw_packet(1, &[0x03, 0x10, 0x00, 0xFF, 0xFF, 0xFD]);
    assert!(matches!(
        parse(&raw, &mut scratch),
        Err(DecodeError::Stuffing { .. })
    ));
}

#[test]
fn fast_sync_replies_are_not_unstuffed() {
    // A block whose data holds FF FF FD FD stays as it is.
    let data = [0xFF, 0xFF, 0xFD, 0xFD];
    let mut out = [0u8; 64];
    let n = packet::fast_sync_status([(1, 0, &data[..])], &mut out).expect("encodes");
    assert_eq!(n, 8 + 8, "not stuffed");
    let mut scratch = [0u8; 64];
    let p = parse(&out[..n], &mut scratch).expect("parses");
    let reply = FastSyncReply::new(&p, 4).expect("one block");
    assert_eq!(reply.block(0).map(|b| b.data), Some(&data[..]));
    // An ordinary status with the same data is stuffed.
    let n = packet::status(1, 0, &data, &mut out).expect("encodes");
    assert_eq!(n, packet::MIN_PACKET + 1 + 4 + 1);
}

#[test]
fn scan_finds_packets_in_noise() {
    let ping = packet(1, instruction::PING, &[]);
    let mut buf = vec![0x00, 0xFF, 0x12, 0xFF, 0xFF];
    buf.extend_from_slice(&ping);
    // Garbage (FF FF FF is no header's start either) is skipped in one step.
    assert_eq!(scan(&buf), Scan::Skip(5));
    assert_eq!(scan(&buf[5..]), Scan::Packet(ping.len()));
    // A lone FF before the header.
    let mut buf = vec![0xFF];
    buf.extend_from_slice(&ping);
    assert_eq!(scan(&buf), Scan::Skip(1));
}

#[test]
fn scan_waits_for_whole_packets() {
    let ping = packet(1, instruction::PING, &[]);
    assert_eq!(scan(&[]), Scan::Need(7));
    for cut in 1..7 {
        assert_eq!(scan(&ping[..cut]), Scan::Need(7), "{cut} bytes");
    }
    for cut in 7..ping.len() {
        assert_eq!(scan(&ping[..cut]), Scan::Need(ping.len()), "{cut} bytes");
    }
    let mut two = ping.clone();
    two.extend_from_slice(&ping);
    assert_eq!(scan(&two), Scan::Packet(ping.len()));
    // A partial header after garbage: skip to it.
    assert_eq!(scan(&[0x01, 0x02, 0xFF, 0xFF, 0xFD]), Scan::Skip(2));
}

#[test]
fn scan_refuses_what_cannot_be_a_header() {
    // The stuffed FF FF FD FD is no header.
    assert_eq!(
        scan(&[0xFF, 0xFF, 0xFD, 0xFD, 0x01, 0x03, 0x00]),
        Scan::Skip(7)
    );
    // Unused IDs.
    for id in [0xFD, 0xFF] {
        let mut raw = packet(1, instruction::PING, &[]);
        raw[4] = id;
        assert!(matches!(scan(&raw), Scan::Skip(_)), "ID {id:02X}");
    }
    // LEN below 3 or above the maximum.
    for len in [0u16, 2, MAX_LEN as u16 + 1, 0xFFFF] {
        let mut raw = HEADER.to_vec();
        raw.push(1);
        raw.extend_from_slice(&len.to_le_bytes());
        raw.extend_from_slice(&[0; 8]);
        assert!(matches!(scan(&raw), Scan::Skip(_)), "LEN {len}");
    }
    let mut raw = HEADER.to_vec();
    raw.push(1);
    raw.extend_from_slice(&(MAX_LEN as u16).to_le_bytes());
    assert_eq!(scan(&raw), Scan::Need(7 + MAX_LEN));
}

#[test]
fn parse_refusals_are_typed() {
    let mut scratch = [0u8; MAX_LEN];
    let ping = packet(1, instruction::PING, &[]);
    assert_eq!(
        parse(&ping[..9], &mut scratch),
        Err(DecodeError::Short { len: 9, min: 10 })
    );
    let mut longer = ping.clone();
    longer.push(0);
    assert!(matches!(
        parse(&longer, &mut scratch),
        Err(DecodeError::Length {
            field: 3,
            bytes: 11
        })
    ));
    let mut bad = ping.clone();
    bad[8] ^= 1;
    assert!(matches!(
        parse(&bad, &mut scratch),
        Err(DecodeError::Crc { .. })
    ));
    let read = packet(1, instruction::READ, &[0x84, 0, 4, 0]);
    let mut small = [0u8; 3];
    assert_eq!(
        parse(&read, &mut small),
        Err(DecodeError::Scratch { need: 4, have: 3 })
    );
}

#[test]
fn encode_refusals_are_typed() {
    let mut out = [0u8; 64];
    assert_eq!(
        encode(0xFD, instruction::PING, &[], &mut out),
        Err(EncodeError::BadId(0xFD))
    );
    assert!(matches!(
        packet::write(1, 116, &[0; 4], &mut out[..14]),
        Err(EncodeError::BufferTooSmall { have: 14, .. })
    ));
    // Room for the unstuffed packet, not for the stuffing byte.
    assert_eq!(
        packet::write(1, 0xFFFF, &[0xFD], &mut out[..13]),
        Err(EncodeError::BufferTooSmall { need: 14, have: 13 })
    );
    assert_eq!(
        packet::sync_write(116, 4, [(1, &[0u8; 4][..]), (2, &[0u8; 2][..])], &mut out),
        Err(EncodeError::ItemLength {
            id: 2,
            expected: 4,
            got: 2
        })
    );
    assert_eq!(
        packet::fast_sync_status(std::iter::empty(), &mut out),
        Err(EncodeError::NoBlocks)
    );
    let mut big = vec![0u8; 4096];
    assert!(matches!(
        encode(1, instruction::WRITE, &[0; MAX_LEN], &mut big),
        Err(EncodeError::TooLong { .. })
    ));
}

#[test]
fn error_byte_words() {
    let access = ErrorByte(0x07);
    assert_eq!(access.number(), Some(ErrorNumber::Access));
    assert!(!access.alert());
    assert!(access.to_string().contains("access error"), "{access}");
    let alert = ErrorByte(0x80);
    assert!(alert.alert() && alert.number().is_none());
    assert!(
        alert.to_string().contains("Hardware Error Status"),
        "{alert}"
    );
    let both = ErrorByte::new(true, Some(ErrorNumber::DataRange));
    assert_eq!(both, ErrorByte(0x84));
    assert!(both.to_string().contains("data range") && both.to_string().contains("alert"));
    assert_eq!(ErrorByte(0x0C).number(), Some(ErrorNumber::Other(12)));
    assert_eq!(ErrorByte::OK.to_string(), "no error");
    for code in 1..=7 {
        let n = ErrorNumber::from_code(code).expect("an error");
        assert_eq!(n.code(), code);
        assert!(!matches!(n, ErrorNumber::Other(_)));
    }
}

#[test]
fn every_instruction_decodes() {
    let cases: [(u8, &[u8], Request<'static>); 9] = [
        (instruction::ACTION, &[], Request::Action),
        (
            instruction::FACTORY_RESET,
            &[0x01],
            Request::FactoryReset(0x01),
        ),
        (
            instruction::REG_WRITE,
            &[0x41, 0x00, 0x01],
            Request::RegWrite {
                addr: 65,
                data: &[1],
            },
        ),
        (
            instruction::CLEAR,
            &[0x01, 0x44, 0x58, 0x4C, 0x22],
            Request::Clear {
                option: 1,
                key: &[0x44, 0x58, 0x4C, 0x22],
            },
        ),
        (
            instruction::BACKUP,
            &[0x02, 0x43, 0x54, 0x52, 0x4C],
            Request::Backup {
                option: 2,
                key: &[0x43, 0x54, 0x52, 0x4C],
            },
        ),
        (0x07, &[1, 2], Request::Unknown(0x07)),
        (instruction::PING, &[], Request::Ping),
        (instruction::REBOOT, &[], Request::Reboot),
        (
            instruction::SYNC_READ,
            &[0x7E, 0x00, 0x0A, 0x00],
            Request::SyncRead {
                addr: 126,
                len: 10,
                ids: &[],
            },
        ),
    ];
    for (inst, params, expected) in cases {
        assert_eq!(request(&packet(BROADCAST_ID, inst, params)), Ok(expected));
    }
    // Bulk Read and Fast Bulk Read: (id, addr, len) per device.
    let bulk = [1, 0x84, 0, 4, 0, 2, 0x7E, 0, 2, 0];
    for inst in [instruction::BULK_READ, instruction::FAST_BULK_READ] {
        let req = request(&packet(BROADCAST_ID, inst, &bulk)).expect("decodes");
        let (Request::BulkRead(items) | Request::FastBulkRead(items)) = req else {
            panic!("{req:?}");
        };
        assert_eq!(items.iter().collect::<Vec<_>>(), [(1, 132, 4), (2, 126, 2)]);
        assert_eq!(
            std::mem::discriminant(&req),
            std::mem::discriminant(&if inst == instruction::BULK_READ {
                Request::BulkRead(items)
            } else {
                Request::FastBulkRead(items)
            })
        );
    }
    // Bulk Write: (id, addr, data) per device, each its own length.
    let bulk = [1, 0x41, 0, 1, 0, 1, 2, 0x74, 0, 4, 0, 0, 8, 0, 0];
    let Ok(Request::BulkWrite(items)) =
        request(&packet(BROADCAST_ID, instruction::BULK_WRITE, &bulk))
    else {
        panic!("not a Bulk Write");
    };
    assert_eq!(
        items.iter().collect::<Vec<_>>(),
        [(1, 65, &[1][..]), (2, 116, &[0, 8, 0, 0][..])]
    );
}

#[test]
fn misshapen_requests_are_typed_errors() {
    let cases: [(u8, &[u8]); 11] = [
        (instruction::PING, &[0]),
        (instruction::READ, &[0x84, 0, 4]),
        (instruction::READ, &[0x84, 0, 4, 0, 0]),
        (instruction::WRITE, &[0x74]),
        (instruction::ACTION, &[1]),
        (instruction::FACTORY_RESET, &[]),
        (instruction::CLEAR, &[]),
        (instruction::SYNC_READ, &[0x84, 0, 4]),
        (instruction::SYNC_WRITE, &[0x74, 0, 4, 0, 1, 0, 0, 0]),
        (instruction::BULK_READ, &[1, 0x84, 0, 4]),
        (instruction::BULK_WRITE, &[1, 0x41, 0, 2, 0, 1]),
    ];
    for (inst, params) in cases {
        assert_eq!(
            request(&packet(1, inst, params)),
            Err(DecodeError::Params {
                instruction: inst,
                len: params.len()
            }),
            "instruction {inst:02X} with {params:02X?}"
        );
    }
}

/// The e-manual's Fast Sync Read reply (IDs 3, 7, 4; 4 bytes at 132).
const REPLY: [u8; 32] = [
    0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x19, 0x00, 0x55, //
    0x00, 0x03, 0xA6, 0x00, 0x00, 0x00, 0x84, 0x08, //
    0x00, 0x07, 0x1F, 0x08, 0x00, 0x00, 0x16, 0xCA, //
    0x00, 0x04, 0xFF, 0x03, 0x00, 0x00, 0xD1, 0x9E,
];

/// `raw` with its packet CRC made right again.
fn resealed(mut raw: Vec<u8>) -> Vec<u8> {
    let n = raw.len();
    let crc = crc16(0, &raw[..n - 2]);
    raw[n - 2..].copy_from_slice(&crc.to_le_bytes());
    raw
}

fn reply(raw: &[u8], data_len: u16) -> Result<(u8, usize), DecodeError> {
    let mut scratch = [0u8; MAX_LEN];
    let p = parse(raw, &mut scratch)?;
    FastSyncReply::new(&p, data_len).map(|r| (p.id, r.len()))
}

#[test]
fn fast_sync_block_crcs_are_each_checked() {
    // The example's middle CRCs are the running CRC from the header.
    assert_eq!(crc16(0, &REPLY[..14]), 0x0884);
    assert_eq!(crc16(0, &REPLY[..22]), 0xCA16);
    assert_eq!(reply(&REPLY, 4), Ok((BROADCAST_ID, 3)));
    // A wrong first-block CRC under a right packet CRC: the SDK would take it, we do not.
    let mut bad = REPLY.to_vec();
    bad[14] ^= 0x01;
    assert_eq!(
        reply(&resealed(bad), 4),
        Err(DecodeError::BlockCrc {
            index: 0,
            id: 3,
            computed: 0x0884,
            received: 0x0885
        })
    );
    // A changed data byte in the second block: its CRC no longer matches.
    let mut bad = REPLY.to_vec();
    bad[19] ^= 0x40;
    assert!(matches!(
        reply(&resealed(bad), 4),
        Err(DecodeError::BlockCrc {
            index: 1,
            id: 7,
            ..
        })
    ));
    // The packet CRC itself is parse's.
    let mut bad = REPLY.to_vec();
    bad[31] ^= 0x01;
    assert!(matches!(reply(&bad, 4), Err(DecodeError::Crc { .. })));
}

#[test]
fn fast_sync_lengths_must_be_whole_blocks() {
    assert_eq!(
        reply(&REPLY, 3),
        Err(DecodeError::FastSyncLength {
            len: 25,
            data_len: 3
        })
    );
    assert_eq!(
        reply(&REPLY, 5),
        Err(DecodeError::FastSyncLength {
            len: 25,
            data_len: 5
        })
    );
    // Not a combined reply: a status from a device, or not a status.
    let mut scratch = [0u8; MAX_LEN];
    let status = packet(1, instruction::STATUS, &[0, 1, 2, 3, 4]);
    let p = parse(&status, &mut scratch).expect("parses");
    assert_eq!(FastSyncReply::new(&p, 4), Err(DecodeError::NotFastSync(1)));
    let p = Packet {
        id: BROADCAST_ID,
        instruction: instruction::SYNC_READ,
        params: &[],
    };
    assert_eq!(
        FastSyncReply::new(&p, 4),
        Err(DecodeError::NotStatus(instruction::SYNC_READ))
    );
}

#[test]
fn fast_sync_blocks_carry_their_error_bytes() {
    let mut out = [0u8; 64];
    let blocks = [(5, 0x80, &[1u8, 2][..]), (6, 0x07, &[3u8, 4][..])];
    let n = packet::fast_sync_status(blocks, &mut out).expect("encodes");
    let mut scratch = [0u8; 64];
    let p = parse(&out[..n], &mut scratch).expect("parses");
    let r = FastSyncReply::new(&p, 2).expect("two blocks");
    let got: Vec<_> = r
        .blocks()
        .map(|b| (b.id, b.error, b.data.to_vec()))
        .collect();
    assert_eq!(
        got,
        [
            (5, ErrorByte(0x80), vec![1, 2]),
            (6, ErrorByte(0x07), vec![3, 4])
        ]
    );
    assert!(r.block(2).is_none());
}
