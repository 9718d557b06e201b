//! Property tests: the decoders are total, stuffing round-trips, every encoded packet parses
//! back, and a packet with one byte changed is refused.

use proptest::prelude::*;
use teleop_leap_protocol::packet::{
    self, encode, parse, scan, FastSyncReply, Request, Scan, Status, BROADCAST_ID, MAX_ID, MAX_LEN,
    MAX_PACKET,
};
use teleop_leap_protocol::xc330::{State, ITEMS};
use teleop_leap_protocol::DecodeError;

/// A device ID or broadcast.
fn any_id() -> impl Strategy<Value = u8> {
    prop_oneof![0..=MAX_ID, Just(BROADCAST_ID)]
}

/// Parameters rich in the stuffing pattern: bytes drawn mostly from FF and FD.
fn params() -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(
        prop_oneof![Just(0xFFu8), Just(0xFD), Just(0x00), any::<u8>()],
        0..300,
    )
}

/// Runs the receive path over `buf` as a node or simulator would: scan, parse, interpret;
/// asserts that every step makes progress and stays in bounds.
fn receive_all(buf: &[u8]) {
    let mut scratch = [0u8; MAX_LEN];
    let mut at = 0;
    while at < buf.len() {
        let rest = &buf[at..];
        match scan(rest) {
            Scan::Skip(n) => {
                assert!(n >= 1 && n <= rest.len(), "skip {n} of {}", rest.len());
                at += n;
            }
            Scan::Need(n) => {
                assert!(
                    n > rest.len() && n <= MAX_PACKET,
                    "need {n} with {}",
                    rest.len()
                );
                return;
            }
            Scan::Packet(n) => {
                assert!(n <= rest.len() && n <= MAX_PACKET);
                match parse(&rest[..n], &mut scratch) {
                    Ok(p) => {
                        let _ = Request::from_packet(&p);
                        let _ = Status::from_packet(&p);
                        for data_len in [0, 1, 4, 10] {
                            if let Ok(reply) = FastSyncReply::new(&p, data_len) {
                                assert!(!reply.is_empty());
                                assert_eq!(reply.blocks().count(), reply.len());
                            }
                        }
                        at += n;
                    }
                    Err(_) => at += 1,
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn any_bytes_are_received_without_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        receive_all(&bytes);
    }

    #[test]
    fn bytes_after_a_header_are_received_without_panic(
        id in any::<u8>(),
        len in any::<u16>(),
        rest in proptest::collection::vec(any::<u8>(), 0..300),
    ) {
        let mut bytes = packet::HEADER.to_vec();
        bytes.push(id);
        bytes.extend_from_slice(&len.to_le_bytes());
        bytes.extend_from_slice(&rest);
        receive_all(&bytes);
    }

    #[test]
    fn parse_of_any_bytes_is_total(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let mut scratch = [0u8; MAX_LEN];
        if let Ok(p) = parse(&bytes, &mut scratch) {
            let _ = Request::from_packet(&p);
            let _ = Status::from_packet(&p);
            let _ = FastSyncReply::new(&p, 4);
        }
        // A scratch too small is a typed error too.
        let mut small = [0u8; 3];
        let _ = parse(&bytes, &mut small);
    }

    #[test]
    fn encoded_packets_parse_back(id in any_id(), instruction in any::<u8>(), params in params()) {
        let mut out = [0u8; MAX_PACKET];
        let n = encode(id, instruction, &params, &mut out).expect("fits");
        prop_assert!(n >= packet::MIN_PACKET + params.len());
        prop_assert_eq!(scan(&out[..n]), Scan::Packet(n));
        let mut scratch = [0u8; MAX_LEN];
        let p = parse(&out[..n], &mut scratch).expect("parses");
        // A status from broadcast is the combined reply, never stuffed: unstuffing is skipped.
        if !(instruction == packet::instruction::STATUS && id == BROADCAST_ID) {
            prop_assert_eq!((p.id, p.instruction, p.params), (id, instruction, &params[..]));
        }
        // Any parameters give a request, a status or a typed error.
        let _ = Request::from_packet(&p);
        let _ = Status::from_packet(&p);
        let _ = FastSyncReply::new(&p, 10);
    }

    #[test]
    fn packets_are_found_after_garbage(
        garbage in proptest::collection::vec(0u8..0xFF, 0..100),
        id in any_id(),
        params in params(),
    ) {
        // No 0xFF in the garbage: nothing in it can start a header.
        let mut buf = garbage.clone();
        let mut out = [0u8; MAX_PACKET];
        let n = encode(id, packet::instruction::WRITE, &params, &mut out).expect("fits");
        buf.extend_from_slice(&out[..n]);
        let at = if garbage.is_empty() {
            0
        } else {
            prop_assert_eq!(scan(&buf), Scan::Skip(garbage.len()));
            garbage.len()
        };
        prop_assert_eq!(scan(&buf[at..]), Scan::Packet(n));
    }

    #[test]
    fn sync_writes_and_reads_decode_as_sent(
        addr in any::<u16>(),
        len in 0u16..8,
        ids in proptest::collection::vec(0..=MAX_ID, 0..20),
        fill in any::<u8>(),
    ) {
        let data: Vec<Vec<u8>> = ids.iter().map(|&id| vec![fill ^ id; usize::from(len)]).collect();
        let items: Vec<(u8, &[u8])> = ids.iter().copied().zip(data.iter().map(|d| &d[..])).collect();
        let mut out = [0u8; MAX_PACKET];
        let n = packet::sync_write(addr, len, items.iter().copied(), &mut out).expect("fits");
        let mut scratch = [0u8; MAX_LEN];
        let p = parse(&out[..n], &mut scratch).expect("parses");
        prop_assert_eq!(p.id, BROADCAST_ID);
        match Request::from_packet(&p) {
            Ok(Request::SyncWrite { addr: a, len: l, items: got }) => {
                prop_assert_eq!((a, l, got.len()), (addr, len, ids.len()));
                prop_assert_eq!(got.iter().collect::<Vec<_>>(), items);
            }
            other => prop_assert!(false, "{:?}", other),
        }
        let n = packet::fast_sync_read(addr, len, &ids, &mut out).expect("fits");
        let p = parse(&out[..n], &mut scratch).expect("parses");
        prop_assert_eq!(
            Request::from_packet(&p),
            Ok(Request::FastSyncRead { addr, len, ids: &ids[..] })
        );
    }

    #[test]
    fn stuffed_packets_hold_no_header_after_it(id in any_id(), params in params()) {
        let mut out = [0u8; MAX_PACKET];
        let n = encode(id, packet::instruction::WRITE, &params, &mut out).expect("fits");
        // No FF FF FD 00 (nor any FF FF FD not followed by FD) in INST..Pn.
        let body = &out[7..n - 2];
        for w in body.windows(4) {
            if w[..3] == [0xFF, 0xFF, 0xFD] {
                prop_assert_eq!(w[3], 0xFD);
            }
        }
        let patterns = params.windows(3).filter(|w| *w == [0xFF, 0xFF, 0xFD]).count();
        prop_assert_eq!(n, packet::MIN_PACKET + params.len() + patterns);
    }

    #[test]
    fn one_changed_byte_is_refused(
        id in any_id(),
        params in params(),
        at in any::<prop::sample::Index>(),
        xor in 1..=255u8,
    ) {
        let mut out = [0u8; MAX_PACKET];
        let n = encode(id, packet::instruction::WRITE, &params, &mut out).expect("fits");
        let at = at.index(n);
        out[at] ^= xor;
        let mut scratch = [0u8; MAX_LEN];
        let refused = parse(&out[..n], &mut scratch);
        prop_assert!(
            matches!(
                refused,
                Err(DecodeError::Crc { .. }
                    | DecodeError::Header
                    | DecodeError::BadId(_)
                    | DecodeError::Length { .. })
            ),
            "byte {} ^ {:02X}: {:?}", at, xor, refused
        );
        // A changed header byte is no header, a changed LEN does not fit the bytes.
        if at < 4 {
            prop_assert_eq!(refused, Err(DecodeError::Header));
        } else if (5..7).contains(&at) {
            prop_assert!(matches!(refused, Err(DecodeError::Length { .. })), "{:?}", refused);
        }
    }

    #[test]
    fn fast_sync_replies_round_trip(
        data_len in 0usize..12,
        ids in proptest::collection::vec((0..=MAX_ID, any::<u8>()), 1..20),
        seed in any::<u8>(),
    ) {
        let data: Vec<Vec<u8>> = ids
            .iter()
            .enumerate()
            .map(|(k, _)| (0..data_len).map(|j| seed.wrapping_add((k * 31 + j) as u8)).collect())
            .collect();
        let blocks = ids.iter().zip(&data).map(|(&(id, err), d)| (id, err, &d[..]));
        let mut out = [0u8; MAX_PACKET];
        let n = packet::fast_sync_status(blocks, &mut out).expect("fits");
        prop_assert_eq!(n, teleop_leap_protocol::wire::fast_sync_reply_len(ids.len(), data_len));
        let mut scratch = [0u8; MAX_LEN];
        let p = parse(&out[..n], &mut scratch).expect("parses");
        let reply = FastSyncReply::new(&p, data_len as u16).expect("a whole reply");
        prop_assert_eq!(reply.len(), ids.len());
        for (block, (&(id, err), d)) in reply.blocks().zip(ids.iter().zip(&data)) {
            prop_assert_eq!((block.id, block.error.0, block.data), (id, err, &d[..]));
        }
    }

    /// Any bytes give a prefix of whole blocks within them; a whole reply cut anywhere gives
    /// the blocks whose CRC arrived.
    #[test]
    fn fast_sync_prefixes_are_total_and_keep_the_blocks_that_arrived(
        bytes in proptest::collection::vec(any::<u8>(), 0..300),
        n in 1usize..17,
        cut in any::<prop::sample::Index>(),
    ) {
        let reply = FastSyncReply::prefix(&bytes, 10);
        prop_assert!(reply.len() * 14 <= bytes.len());
        let data = [7u8; 10];
        let blocks = (0..n as u8).map(|id| (id, 0u8, &data[..]));
        let mut out = [0u8; MAX_PACKET];
        let len = packet::fast_sync_status(blocks, &mut out).expect("fits");
        let at = cut.index(len + 1);
        let got = FastSyncReply::prefix(&out[..at], 10).len();
        prop_assert_eq!(got, (at.saturating_sub(8) / 14).min(n));
    }

    #[test]
    fn table_values_round_trip(index in any::<prop::sample::Index>(), value in any::<i32>()) {
        let item = index.get(ITEMS);
        let size = usize::from(item.size);
        let bytes = item.encode(value);
        let back = item.decode(&bytes[..size]).expect("its size");
        let bits = 8 * size as u32;
        let expected = if bits == 32 {
            value
        } else if item.signed {
            (value << (32 - bits)) >> (32 - bits)
        } else {
            value & ((1 << bits) - 1)
        };
        prop_assert_eq!(back, expected);
    }

    #[test]
    fn states_round_trip(current_ma in any::<i16>(), velocity in any::<i32>(), position in any::<i32>()) {
        let state = State { current_ma, velocity, position };
        prop_assert_eq!(State::decode(&state.encode()), Ok(state));
    }
}
