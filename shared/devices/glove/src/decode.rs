//! Streaming decoders: one generic core ([`Decoder`]) over a direction
//! ([`Requests`] for host -> glove, [`Responses`] for glove -> host).

use core::fmt;
use core::marker::PhantomData;

use crate::frame::{
    checksum, Command, Data, Frame, Request, Response, FRAME_OVERHEAD, MAX_FRAME, REQUEST_HEADER,
    RESPONSE_HEADER,
};

/// Why bytes in the stream did not decode to a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Bytes before a header were skipped (one error per run of skipped
    /// bytes, reported when a header is found or the buffer is exhausted).
    #[error("skipped {skipped} bytes before a frame header")]
    Garbage {
        /// Number of bytes skipped in this run.
        skipped: usize,
    },
    /// A frame whose checksum does not match; its first header byte was
    /// dropped and the stream rescanned.
    #[error("bad checksum in frame id {id} cmd {command:#04x}: expected {expected:#04x}, got {got:#04x}")]
    BadChecksum {
        /// ID byte of the bad frame.
        id: u8,
        /// CMD byte of the bad frame.
        command: u8,
        /// Checksum computed over the received bytes.
        expected: u8,
        /// Checksum byte received.
        got: u8,
    },
    /// A header followed by a CMD byte the manual does not list; treated like
    /// a false header (first header byte dropped, stream rescanned) because
    /// without a known command nothing says how long the frame is meant to
    /// be, and waiting for up to 255 bytes would stall real frames behind it.
    #[error("unknown command {command:#04x} (id {id})")]
    UnknownCommand {
        /// ID byte after the header.
        id: u8,
        /// The unknown CMD byte.
        command: u8,
    },
    /// A LEN byte impossible for that command in this direction (first
    /// header byte dropped, stream rescanned).
    #[error("impossible length {len} for command {command:#04x} (id {id})")]
    BadLength {
        /// ID byte after the header.
        id: u8,
        /// CMD byte (for LEN 0 this is the byte where CMD would be).
        command: u8,
        /// The LEN byte.
        len: u8,
    },
    /// A well-formed frame (checksum correct) for another device ID; it was
    /// consumed.
    #[error("frame for device id {id}, expected {expected}")]
    OtherId {
        /// ID of the frame.
        id: u8,
        /// ID this decoder expects.
        expected: u8,
    },
}

mod sealed {
    pub trait Sealed {}
}

/// One direction of the protocol: its header, which LEN each command may
/// have and how a body is read. Implemented by [`Requests`] and
/// [`Responses`] only.
pub trait Direction: sealed::Sealed {
    /// The 2-byte header of frames in this direction.
    const HEADER: [u8; 2];
    /// The decoded body type.
    type Body: Copy + fmt::Debug + PartialEq;
    /// Whether `len` (the LEN byte) is possible for `command`.
    fn len_ok(command: Command, len: u8) -> bool;
    /// Reads the body from the bytes between CMD and CHK; `None` when their
    /// count does not fit the command (never happens after [`Self::len_ok`]).
    fn parse(command: Command, payload: &[u8]) -> Option<Self::Body>;
}

/// Host -> glove frames (`EB 90`), decoded by the simulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Requests {}

/// Glove -> host frames (`90 EB`), decoded by the glove node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Responses {}

impl sealed::Sealed for Requests {}
impl sealed::Sealed for Responses {}

/// LEN of a register read request / write answer: CMD + address + N / status.
const LEN_ADDRESS_AND_BYTE: u8 = 4;
/// Smallest LEN of a frame carrying an address and register bytes.
const LEN_ADDRESS_ONLY: u8 = 3;
/// LEN of a frame carrying five 16-bit values.
const LEN_FIVE_WORDS: u8 = 11;
/// LEN of a frame carrying six 16-bit values.
const LEN_SIX_WORDS: u8 = 13;

impl Direction for Requests {
    const HEADER: [u8; 2] = REQUEST_HEADER;
    type Body = Request;

    fn len_ok(command: Command, len: u8) -> bool {
        match command {
            Command::ForceControl | Command::PositionControl => len == LEN_FIVE_WORDS,
            Command::ReadRegister => len == LEN_ADDRESS_AND_BYTE,
            // N = LEN - 3 may be 0..=252; the decoder reports what was sent
            // (a zero-byte write included) and leaves judging it to the
            // simulator.
            Command::WriteRegister => len >= LEN_ADDRESS_ONLY,
        }
    }

    fn parse(command: Command, payload: &[u8]) -> Option<Request> {
        Some(match command {
            Command::ForceControl => Request::ForceControl {
                forces: words(payload)?.map(i16::from_le_bytes),
            },
            Command::PositionControl => Request::PositionControl {
                positions: words(payload)?.map(u16::from_le_bytes),
            },
            Command::ReadRegister => match payload {
                &[lo, hi, len] => Request::ReadRegister {
                    address: u16::from_le_bytes([lo, hi]),
                    len,
                },
                _ => return None,
            },
            Command::WriteRegister => {
                let (address, data) = address_and_data(payload)?;
                Request::WriteRegister { address, data }
            }
        })
    }
}

impl Direction for Responses {
    const HEADER: [u8; 2] = RESPONSE_HEADER;
    type Body = Response;

    fn len_ok(command: Command, len: u8) -> bool {
        match command {
            Command::ForceControl => len == LEN_SIX_WORDS,
            Command::PositionControl => len == LEN_FIVE_WORDS,
            Command::ReadRegister => len >= LEN_ADDRESS_ONLY,
            Command::WriteRegister => len == LEN_ADDRESS_AND_BYTE,
        }
    }

    fn parse(command: Command, payload: &[u8]) -> Option<Response> {
        Some(match command {
            Command::ForceControl => Response::ForceControl {
                positions: words(payload)?.map(u16::from_le_bytes),
            },
            Command::PositionControl => Response::PositionControl {
                forces: words(payload)?.map(i16::from_le_bytes),
            },
            Command::ReadRegister => {
                let (address, data) = address_and_data(payload)?;
                Response::ReadRegister { address, data }
            }
            Command::WriteRegister => match payload {
                &[lo, hi, status] => Response::WriteRegister {
                    address: u16::from_le_bytes([lo, hi]),
                    status,
                },
                _ => return None,
            },
        })
    }
}

/// Exactly `N` little-endian 16-bit words, as byte pairs.
fn words<const N: usize>(payload: &[u8]) -> Option<[[u8; 2]; N]> {
    if payload.len() != 2 * N {
        return None;
    }
    let mut out = [[0u8; 2]; N];
    for (word, pair) in out.iter_mut().zip(payload.chunks_exact(2)) {
        word.copy_from_slice(pair);
    }
    Some(out)
}

/// A 16-bit address followed by register bytes.
fn address_and_data(payload: &[u8]) -> Option<(u16, Data)> {
    match payload {
        &[lo, hi, ref data @ ..] => Some((u16::from_le_bytes([lo, hi]), Data::new(data).ok()?)),
        _ => None,
    }
}

/// Buffer capacity: two maximal frames, so that after [`Decoder::next`] has
/// returned `None` (at most one partial frame, < [`MAX_FRAME`] bytes, left)
/// [`Decoder::push`] always has room for at least [`MAX_FRAME`] more bytes.
const CAPACITY: usize = 2 * MAX_FRAME;

/// Streaming decoder for one direction, generic over [`Direction`]; use
/// [`RequestDecoder`] or [`ResponseDecoder`].
///
/// Feed arbitrary chunks with [`push`](Self::push); take frames and errors,
/// in stream order, with [`next`](Self::next) (`None` = more bytes are
/// needed; decoding resumes after the next push). It resynchronises after
/// garbage (scans for the next header), after a bad checksum, an impossible
/// LEN or an unknown command (drops the first header byte and rescans, so a
/// frame hidden inside the bad one is still found), across split frames
/// (partial bytes are kept between pushes) and after frames for another ID
/// (consumed whole). The buffer is a fixed array (no heap) and no input
/// makes it panic.
///
/// Order of checks once a header is found: CMD known and LEN possible (as
/// soon as 5 bytes are there), then checksum (once the whole frame is
/// there), then ID, then the body.
///
/// A false header followed by a known command and a plausible LEN delays the
/// frames behind it until that many bytes (at most [`MAX_FRAME`]) arrived and
/// the checksum failed; it never loses them, unless [`clear`](Self::clear)
/// is called in between.
pub struct Decoder<D: Direction> {
    buf: [u8; CAPACITY],
    start: usize,
    end: usize,
    expected_id: Option<u8>,
    direction: PhantomData<D>,
}

/// Decodes host -> glove frames (for the simulator).
pub type RequestDecoder = Decoder<Requests>;

/// Decodes glove -> host frames (for the glove node).
pub type ResponseDecoder = Decoder<Responses>;

/// What one scan step found: how many bytes to drop and what to report.
type Step<B> = (usize, Option<Result<Frame<B>, DecodeError>>);

impl<D: Direction> Decoder<D> {
    /// An empty decoder; `expected_id` `None` accepts every ID, `Some(id)`
    /// reports frames for other IDs as [`DecodeError::OtherId`].
    pub fn new(expected_id: Option<u8>) -> Self {
        Self {
            buf: [0; CAPACITY],
            start: 0,
            end: 0,
            expected_id,
            direction: PhantomData,
        }
    }

    /// Changes the accepted ID (`None` = every ID); buffered bytes are kept.
    pub fn set_expected_id(&mut self, id: Option<u8>) {
        self.expected_id = id;
    }

    /// The accepted ID (`None` = every ID).
    pub fn expected_id(&self) -> Option<u8> {
        self.expected_id
    }

    /// Appends bytes; returns how many were taken. It may take fewer than
    /// given when its buffer is full: call `next` until `None` and push the
    /// rest again (after that at least [`MAX_FRAME`] bytes always fit).
    pub fn push(&mut self, bytes: &[u8]) -> usize {
        if self.start > 0 && self.end + bytes.len() > CAPACITY {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
        let n = bytes.len().min(CAPACITY - self.end);
        self.buf[self.end..self.end + n].copy_from_slice(&bytes[..n]);
        self.end += n;
        n
    }

    /// Drops every buffered byte (e.g. after a timeout or a reopen).
    pub fn clear(&mut self) {
        self.start = 0;
        self.end = 0;
    }

    /// Number of bytes buffered and not yet decoded.
    pub fn buffered(&self) -> usize {
        self.end - self.start
    }

    /// Looks at the buffered bytes; the caller drops the returned count.
    fn peek(&self) -> Step<D::Body> {
        let bytes = &self.buf[self.start..self.end];
        let [h0, h1] = D::HEADER;
        // A header, or its first byte as the very last buffered byte (the
        // second may still come).
        let skip = bytes
            .iter()
            .enumerate()
            .position(|(i, &b)| b == h0 && bytes.get(i + 1).is_none_or(|&next| next == h1))
            .unwrap_or(bytes.len());
        if skip > 0 {
            return (skip, Some(Err(DecodeError::Garbage { skipped: skip })));
        }
        let &[_, _, id, len, command, ..] = bytes else {
            return (0, None);
        };
        // Reject impossible headers early, without waiting for LEN bytes.
        let Some(cmd) = Command::from_u8(command) else {
            return (1, Some(Err(DecodeError::UnknownCommand { id, command })));
        };
        if !D::len_ok(cmd, len) {
            return (1, Some(Err(DecodeError::BadLength { id, command, len })));
        }
        let total = FRAME_OVERHEAD + usize::from(len);
        let Some(frame) = bytes.get(..total) else {
            return (0, None);
        };
        let (counted, got) = match frame {
            [_, _, counted @ .., got] => (counted, *got),
            _ => return (0, None), // unreachable: total >= 5
        };
        let expected = checksum(counted);
        if expected != got {
            let error = DecodeError::BadChecksum {
                id,
                command,
                expected,
                got,
            };
            return (1, Some(Err(error)));
        }
        if let Some(expected) = self.expected_id.filter(|&e| e != id) {
            return (total, Some(Err(DecodeError::OtherId { id, expected })));
        }
        // counted = ID, LEN, CMD, payload.
        let payload = counted.get(3..).unwrap_or_default();
        let item = match D::parse(cmd, payload) {
            Some(body) => Ok(Frame { id, body }),
            None => Err(DecodeError::BadLength { id, command, len }),
        };
        (total, Some(item))
    }

    /// The next decoded frame or error, `None` when more bytes are needed.
    ///
    /// Deliberately an inherent method and not [`Iterator::next`]: `None`
    /// only means "push more bytes", after which decoding resumes, which an
    /// iterator (and the `for` loops and adapters built on it) does not
    /// expect.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Option<Result<Frame<D::Body>, DecodeError>> {
        let (consumed, item) = self.peek();
        self.start += consumed.min(self.buffered());
        if self.start == self.end {
            self.clear();
        }
        item
    }
}

impl<D: Direction> Default for Decoder<D> {
    /// A decoder accepting every ID.
    fn default() -> Self {
        Self::new(None)
    }
}

impl<D: Direction> Clone for Decoder<D> {
    fn clone(&self) -> Self {
        Self {
            buf: self.buf,
            start: self.start,
            end: self.end,
            expected_id: self.expected_id,
            direction: PhantomData,
        }
    }
}

impl<D: Direction> fmt::Debug for Decoder<D> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Decoder")
            .field("header", &D::HEADER)
            .field("expected_id", &self.expected_id)
            .field("buffered", &self.buffered())
            .finish()
    }
}
