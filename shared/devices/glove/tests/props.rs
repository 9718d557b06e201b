//! Property tests: the decoders are total and resynchronise, the encoders

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used)]
//! round-trip.

use proptest::collection::vec;
use proptest::prelude::*;
use teleop_glove_protocol::{
    encode_request, encode_response, Data, DecodeError, Frame, Request, RequestDecoder, Response,
    ResponseDecoder, MAX_DATA, MAX_FRAME,
};

fn arb_data(min: usize) -> impl Strategy<Value = Data> {
    vec(any::<u8>(), min..=MAX_DATA).prop_map(|b| Data::new(&b).unwrap())
}

/// Any request, in range or not.
fn arb_request() -> impl Strategy<Value = Request> {
    prop_oneof![
        any::<[i16; 5]>().prop_map(|forces| Request::ForceControl { forces }),
        any::<[u16; 5]>().prop_map(|positions| Request::PositionControl { positions }),
        (any::<u16>(), any::<u8>())
            .prop_map(|(address, len)| Request::ReadRegister { address, len }),
        (any::<u16>(), arb_data(0))
            .prop_map(|(address, data)| Request::WriteRegister { address, data }),
    ]
}

/// Requests the encoder accepts.
fn arb_valid_request() -> impl Strategy<Value = Request> {
    prop_oneof![
        proptest::array::uniform5(-1000i16..=1000)
            .prop_map(|forces| Request::ForceControl { forces }),
        proptest::array::uniform5(0u16..=1000)
            .prop_map(|positions| Request::PositionControl { positions }),
        (any::<u16>(), 1u8..=MAX_DATA as u8)
            .prop_map(|(address, len)| Request::ReadRegister { address, len }),
        (any::<u16>(), arb_data(1))
            .prop_map(|(address, data)| Request::WriteRegister { address, data }),
    ]
}

fn arb_response() -> impl Strategy<Value = Response> {
    prop_oneof![
        any::<[u16; 6]>().prop_map(|positions| Response::ForceControl { positions }),
        any::<[i16; 5]>().prop_map(|forces| Response::PositionControl { forces }),
        (any::<u16>(), arb_data(0))
            .prop_map(|(address, data)| Response::ReadRegister { address, data }),
        (any::<u16>(), any::<u8>())
            .prop_map(|(address, status)| Response::WriteRegister { address, status }),
    ]
}

/// Bytes biased towards header bytes and command bytes.
fn arb_noisy_byte() -> impl Strategy<Value = u8> {
    prop_oneof![
        4 => any::<u8>(),
        2 => Just(0xEB),
        2 => Just(0x90),
        1 => prop_oneof![Just(0x11), Just(0x12), Just(0x31), Just(0x32)],
        1 => prop_oneof![Just(0x03), Just(0x04), Just(0x0B), Just(0x0D)],
    ]
}

/// Garbage without header bytes.
fn arb_clean_garbage() -> impl Strategy<Value = Vec<u8>> {
    vec(
        any::<u8>().prop_filter("no header byte", |b| *b != 0x90 && *b != 0xEB),
        0..20,
    )
}

/// Cuts `stream` into chunks of the given sizes (cycled).
fn chunks<'a>(stream: &'a [u8], sizes: &'a [usize]) -> Vec<&'a [u8]> {
    let mut out = Vec::new();
    let mut rest = stream;
    let mut i = 0;
    while !rest.is_empty() {
        let n = sizes
            .get(i % sizes.len().max(1))
            .copied()
            .unwrap_or(1)
            .clamp(1, rest.len());
        out.push(&rest[..n]);
        rest = &rest[n..];
        i += 1;
    }
    out
}

/// Generic driver over both decoders: pushes every chunk, drains, checks
/// that each reported item consumed at least one byte and that the buffer
/// never keeps a whole frame's worth of undecoded bytes.
macro_rules! run_decoder {
    ($decoder:expr, $chunks:expr) => {{
        let mut d = $decoder;
        let mut items = Vec::new();
        let mut pushed = 0usize;
        for chunk in $chunks {
            let mut rest: &[u8] = chunk;
            while !rest.is_empty() {
                let n = d.push(rest);
                pushed += n;
                rest = &rest[n..];
                while let Some(item) = d.next() {
                    items.push(item);
                    prop_assert!(items.len() <= pushed, "more items than bytes");
                }
                prop_assert!(d.buffered() < MAX_FRAME);
            }
        }
        prop_assert_eq!(d.next(), None);
        items
    }};
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(
        stream in vec(arb_noisy_byte(), 0..2000),
        sizes in vec(1usize..300, 1..20),
        id in proptest::option::of(any::<u8>()),
    ) {
        let parts = chunks(&stream, &sizes);
        let _ = run_decoder!(ResponseDecoder::new(id), parts.iter().copied());
        let _ = run_decoder!(RequestDecoder::new(id), parts.iter().copied());
    }

    #[test]
    fn valid_requests_through_garbage_decode_in_order(
        frames in vec((1u8..=254, arb_valid_request(), arb_clean_garbage()), 0..8),
        tail in arb_clean_garbage(),
        sizes in vec(1usize..80, 1..10),
    ) {
        let mut stream = Vec::new();
        let mut buf = [0u8; MAX_FRAME];
        for (id, r, garbage) in &frames {
            stream.extend(garbage);
            let n = encode_request(*id, r, &mut buf).unwrap();
            stream.extend(&buf[..n]);
        }
        stream.extend(&tail);
        let items = run_decoder!(RequestDecoder::new(None), chunks(&stream, &sizes));
        let mut got = Vec::new();
        for item in items {
            match item {
                Ok(frame) => got.push(frame),
                Err(e) => prop_assert!(matches!(e, DecodeError::Garbage { .. }), "{:?}", e),
            }
        }
        let expected: Vec<_> = frames.iter().map(|(id, r, _)| Frame { id: *id, body: *r }).collect();
        prop_assert_eq!(got, expected);
    }

    #[test]
    fn valid_responses_through_garbage_decode_in_order(
        frames in vec((any::<u8>(), arb_response(), arb_clean_garbage()), 0..8),
        tail in arb_clean_garbage(),
        sizes in vec(1usize..80, 1..10),
    ) {
        let mut stream = Vec::new();
        let mut buf = [0u8; MAX_FRAME];
        for (id, r, garbage) in &frames {
            stream.extend(garbage);
            let n = encode_response(*id, r, &mut buf).unwrap();
            stream.extend(&buf[..n]);
        }
        stream.extend(&tail);
        let items = run_decoder!(ResponseDecoder::new(None), chunks(&stream, &sizes));
        let mut got = Vec::new();
        for item in items {
            match item {
                Ok(frame) => got.push(frame),
                Err(e) => prop_assert!(matches!(e, DecodeError::Garbage { .. }), "{:?}", e),
            }
        }
        let expected: Vec<_> = frames.iter().map(|(id, r, _)| Frame { id: *id, body: *r }).collect();
        prop_assert_eq!(got, expected);
    }

    #[test]
    fn encode_request_errors_or_round_trips(id in any::<u8>(), r in arb_request()) {
        let mut buf = [0u8; MAX_FRAME];
        if let Ok(n) = encode_request(id, &r, &mut buf) {
            prop_assert_eq!(n, r.encoded_len());
            let mut d = RequestDecoder::new(Some(id));
            prop_assert_eq!(d.push(&buf[..n]), n);
            prop_assert_eq!(d.next(), Some(Ok(Frame { id, body: r })));
            prop_assert_eq!(d.next(), None);
        }
    }

    #[test]
    fn encode_response_round_trips(id in any::<u8>(), r in arb_response()) {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode_response(id, &r, &mut buf).unwrap();
        prop_assert_eq!(n, r.encoded_len());
        let mut d = ResponseDecoder::new(Some(id));
        prop_assert_eq!(d.push(&buf[..n]), n);
        prop_assert_eq!(d.next(), Some(Ok(Frame { id, body: r })));
        prop_assert_eq!(d.next(), None);
    }

    #[test]
    fn corrupted_frame_never_hides_the_next_one(
        r in arb_response(),
        flip in any::<prop::sample::Index>(),
        mask in 1u8..=255,
    ) {
        // One corrupted byte in a frame followed by a good frame: the good
        // one always comes out (corruption can make the first one a frame for
        // another body, but never swallows the second).
        let mut buf = [0u8; MAX_FRAME];
        let n = encode_response(1, &r, &mut buf).unwrap();
        let mut bad = buf[..n].to_vec();
        let i = flip.index(n);
        bad[i] ^= mask;
        let good = Response::WriteRegister { address: 1000, status: 1 };
        let m = encode_response(1, &good, &mut buf).unwrap();
        let mut stream = bad;
        stream.extend(&buf[..m]);
        // Pad so a corrupted LEN that claims more bytes is resolved.
        stream.extend([0u8; MAX_FRAME]);
        let items = run_decoder!(ResponseDecoder::new(None), std::iter::once(&stream[..]));
        prop_assert!(items.contains(&Ok(Frame { id: 1, body: good })), "{:?}", items);
    }
}
