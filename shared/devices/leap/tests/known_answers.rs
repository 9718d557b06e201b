//! Known answers from the ROBOTIS e-manual, Protocol 2.0 (every example packet re-checked): the
//! CRC, the encoders byte for byte, the decoders back, and the Fast Sync Read example.

use teleop_leap_protocol::crc::crc16;
use teleop_leap_protocol::packet::{
    self, instruction, parse, scan, ErrorByte, FastSyncReply, Request, Scan, Status, BROADCAST_ID,
    MAX_LEN,
};
use teleop_leap_protocol::DecodeError;

/// Parses bytes that must be one whole packet.
fn parsed<'s>(raw: &[u8], scratch: &'s mut [u8]) -> packet::Packet<'s> {
    assert_eq!(scan(raw), Scan::Packet(raw.len()), "{raw:02X?}");
    parse(raw, scratch).expect("a known-good packet")
}

/// The e-manual's example packets (E-P2), CRC in the last two bytes.
const PING_1: &[u8] = &[0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x03, 0x00, 0x01, 0x19, 0x4E];
const PING_STATUS: &[u8] = &[
    0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x07, 0x00, 0x55, 0x00, 0x06, 0x04, 0x26, 0x65, 0x5D,
];
const PING_BROADCAST: &[u8] = &[0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x03, 0x00, 0x01, 0x31, 0x42];
const READ_132: &[u8] = &[
    0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x07, 0x00, 0x02, 0x84, 0x00, 0x04, 0x00, 0x1D, 0x15,
];
const READ_STATUS: &[u8] = &[
    0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x08, 0x00, 0x55, 0x00, 0xA6, 0x00, 0x00, 0x00, 0x8C, 0xC0,
];
const WRITE_116: &[u8] = &[
    0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x09, 0x00, 0x03, 0x74, 0x00, 0x00, 0x02, 0x00, 0x00, 0xCA, 0x89,
];
const EMPTY_STATUS: &[u8] = &[
    0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x04, 0x00, 0x55, 0x00, 0xA1, 0x0C,
];
const REBOOT_1: &[u8] = &[0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x03, 0x00, 0x08, 0x2F, 0x4E];
const SYNC_READ: &[u8] = &[
    0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x09, 0x00, 0x82, 0x84, 0x00, 0x04, 0x00, 0x01, 0x02, 0xCE, 0xFA,
];
const SYNC_WRITE: &[u8] = &[
    0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x11, 0x00, 0x83, 0x74, 0x00, 0x04, 0x00, 0x01, 0x96, 0x00, 0x00,
    0x00, 0x02, 0xAA, 0x00, 0x00, 0x00, 0x82, 0x87,
];
const FAST_SYNC_READ: &[u8] = &[
    0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x0A, 0x00, 0x8A, 0x84, 0x00, 0x04, 0x00, 0x03, 0x07, 0x04, 0x20,
    0xF2,
];
const FAST_SYNC_REPLY: &[u8] = &[
    0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x19, 0x00, 0x55, //
    0x00, 0x03, 0xA6, 0x00, 0x00, 0x00, 0x84, 0x08, //
    0x00, 0x07, 0x1F, 0x08, 0x00, 0x00, 0x16, 0xCA, //
    0x00, 0x04, 0xFF, 0x03, 0x00, 0x00, 0xD1, 0x9E,
];

const ALL: [&[u8]; 12] = [
    PING_1,
    PING_STATUS,
    PING_BROADCAST,
    READ_132,
    READ_STATUS,
    WRITE_116,
    EMPTY_STATUS,
    REBOOT_1,
    SYNC_READ,
    SYNC_WRITE,
    FAST_SYNC_READ,
    FAST_SYNC_REPLY,
];

#[test]
fn crc_check_value() {
    assert_eq!(crc16(0, b"123456789"), 0xFEE8);
    assert_eq!(crc16(0, b""), 0);
}

#[test]
fn crc_of_every_example() {
    for raw in ALL {
        let n = raw.len();
        let printed = u16::from_le_bytes([raw[n - 2], raw[n - 1]]);
        assert_eq!(crc16(0, &raw[..n - 2]), printed, "{raw:02X?}");
    }
}

#[test]
fn crc_runs_on() {
    let (a, b) = FAST_SYNC_REPLY.split_at(13);
    assert_eq!(crc16(crc16(0, a), b), crc16(0, FAST_SYNC_REPLY));
}

#[test]
fn encoders_write_the_examples() {
    let mut out = [0u8; 64];
    let check = |n: Result<usize, _>, expected: &[u8], out: &[u8]| {
        let n = n.expect("encodes");
        assert_eq!(&out[..n], expected);
    };
    let n = packet::ping(1, &mut out);
    check(n, PING_1, &out);
    let n = packet::ping(BROADCAST_ID, &mut out);
    check(n, PING_BROADCAST, &out);
    let n = packet::read(1, 132, 4, &mut out);
    check(n, READ_132, &out);
    let n = packet::write(1, 116, &512u32.to_le_bytes(), &mut out);
    check(n, WRITE_116, &out);
    let n = packet::reboot(1, &mut out);
    check(n, REBOOT_1, &out);
    let n = packet::sync_read(132, 4, &[1, 2], &mut out);
    check(n, SYNC_READ, &out);
    let n = packet::fast_sync_read(132, 4, &[3, 7, 4], &mut out);
    check(n, FAST_SYNC_READ, &out);
    let (a, b) = (150u32.to_le_bytes(), 170u32.to_le_bytes());
    let n = packet::sync_write(116, 4, [(1, &a[..]), (2, &b[..])], &mut out);
    check(n, SYNC_WRITE, &out);
    let n = packet::status(1, 0, &[0x06, 0x04, 0x26], &mut out);
    check(n, PING_STATUS, &out);
    let n = packet::status(1, 0, &166u32.to_le_bytes(), &mut out);
    check(n, READ_STATUS, &out);
    let n = packet::status(1, 0, &[], &mut out);
    check(n, EMPTY_STATUS, &out);
    let blocks = [
        (3, 0, &0x0000_00A6u32.to_le_bytes()[..]),
        (7, 0, &0x0000_081Fu32.to_le_bytes()[..]),
        (4, 0, &0x0000_03FFu32.to_le_bytes()[..]),
    ];
    let n = packet::fast_sync_status(blocks, &mut out);
    check(n, FAST_SYNC_REPLY, &out);
}

#[test]
fn requests_decode() {
    let mut scratch = [0u8; MAX_LEN];
    let p = parsed(PING_1, &mut scratch);
    assert_eq!((p.id, Request::from_packet(&p)), (1, Ok(Request::Ping)));
    let p = parsed(READ_132, &mut scratch);
    assert_eq!(
        Request::from_packet(&p),
        Ok(Request::Read { addr: 132, len: 4 })
    );
    let p = parsed(WRITE_116, &mut scratch);
    assert_eq!(
        Request::from_packet(&p),
        Ok(Request::Write {
            addr: 116,
            data: &[0x00, 0x02, 0x00, 0x00]
        })
    );
    let p = parsed(REBOOT_1, &mut scratch);
    assert_eq!(Request::from_packet(&p), Ok(Request::Reboot));
    let p = parsed(SYNC_READ, &mut scratch);
    assert_eq!(
        Request::from_packet(&p),
        Ok(Request::SyncRead {
            addr: 132,
            len: 4,
            ids: &[1, 2]
        })
    );
    let p = parsed(FAST_SYNC_READ, &mut scratch);
    assert_eq!(
        Request::from_packet(&p),
        Ok(Request::FastSyncRead {
            addr: 132,
            len: 4,
            ids: &[3, 7, 4]
        })
    );
    let p = parsed(SYNC_WRITE, &mut scratch);
    let Ok(Request::SyncWrite { addr, len, items }) = Request::from_packet(&p) else {
        panic!("not a Sync Write: {p:?}");
    };
    assert_eq!((addr, len, items.len()), (116, 4, 2));
    let items: Vec<_> = items.iter().collect();
    assert_eq!(
        items,
        [(1, &[0x96, 0, 0, 0][..]), (2, &[0xAA, 0, 0, 0][..])]
    );
    let p = parsed(EMPTY_STATUS, &mut scratch);
    assert_eq!(Request::from_packet(&p), Err(DecodeError::NotInstruction));
}

#[test]
fn statuses_decode() {
    let mut scratch = [0u8; MAX_LEN];
    let p = parsed(PING_STATUS, &mut scratch);
    let s = Status::from_packet(&p).expect("a status");
    assert_eq!(
        (s.id, s.error, s.params),
        (1, ErrorByte::OK, &[6, 4, 0x26][..])
    );
    let p = parsed(READ_STATUS, &mut scratch);
    let s = Status::from_packet(&p).expect("a status");
    assert_eq!(s.params, 166u32.to_le_bytes());
    let p = parsed(EMPTY_STATUS, &mut scratch);
    let s = Status::from_packet(&p).expect("a status");
    assert!(s.error.is_ok() && s.params.is_empty());
    let p = parsed(PING_1, &mut scratch);
    assert_eq!(
        Status::from_packet(&p),
        Err(DecodeError::NotStatus(instruction::PING))
    );
}

#[test]
fn fast_sync_reply_example() {
    let mut scratch = [0u8; MAX_LEN];
    let p = parsed(FAST_SYNC_REPLY, &mut scratch);
    let reply = FastSyncReply::new(&p, 4).expect("the example reply");
    let blocks: Vec<_> = reply
        .blocks()
        .map(|b| {
            (
                b.id,
                b.error,
                u32::from_le_bytes(b.data.try_into().expect("4 bytes")),
            )
        })
        .collect();
    assert_eq!(
        blocks,
        [
            (3, ErrorByte::OK, 0xA6),
            (7, ErrorByte::OK, 0x081F),
            (4, ErrorByte::OK, 0x03FF)
        ]
    );
}

#[test]
fn the_good_blocks_of_a_fast_sync_reply_cut_short_or_damaged() {
    let ids = |raw: &[u8]| -> Vec<u8> {
        FastSyncReply::prefix(raw, 4)
            .blocks()
            .map(|b| b.id)
            .collect()
    };
    // Whole: every block; cut anywhere: the blocks whose CRC arrived.
    assert_eq!(ids(FAST_SYNC_REPLY), [3, 7, 4]);
    for (cut, want) in [
        (0, &[][..]),
        (8, &[]),
        (15, &[]),
        (16, &[3]),
        (23, &[3]),
        (24, &[3, 7]),
        (31, &[3, 7]),
    ] {
        assert_eq!(ids(&FAST_SYNC_REPLY[..cut]), want, "cut at {cut}");
    }
    // A damaged byte: the blocks before it (block 0 ends at byte 15, block 1 at 23).
    for (at, want) in [
        (4, &[][..]),
        (9, &[]),
        (16, &[3]),
        (20, &[3]),
        (24, &[3, 7]),
        (31, &[3, 7]),
    ] {
        let mut bad = FAST_SYNC_REPLY.to_vec();
        bad[at] ^= 0x10;
        assert_eq!(ids(&bad), want, "byte {at}");
    }
    // Bytes after the announced length are not another block.
    let mut longer = FAST_SYNC_REPLY.to_vec();
    longer.extend_from_slice(&FAST_SYNC_REPLY[8..16]);
    assert_eq!(ids(&longer), [3, 7, 4]);
    let block = FastSyncReply::prefix(&FAST_SYNC_REPLY[..20], 4)
        .block(0)
        .expect("block 0");
    assert_eq!(
        (block.error, block.data),
        (ErrorByte::OK, &[0xA6, 0, 0, 0][..])
    );
}
