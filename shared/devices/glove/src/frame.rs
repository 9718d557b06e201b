//! Frame layout, command bodies, the checksum and the two encoders.
//!
//! ```text
//! request  (host -> glove): EB 90 | ID | LEN | CMD | data... | CHK
//! response (glove -> host): 90 EB | ID | LEN | CMD | data... | CHK
//! ```

use core::fmt;

/// First two bytes of every request (host -> glove) frame.
pub const REQUEST_HEADER: [u8; 2] = [0xEB, 0x90];

/// First two bytes of every response (glove -> host) frame.
pub const RESPONSE_HEADER: [u8; 2] = [0x90, 0xEB];

/// Bytes of a frame that LEN does not count: header (2) + ID + LEN + CHK.
pub const FRAME_OVERHEAD: usize = 5;

/// Longest possible frame on the wire: [`FRAME_OVERHEAD`] + the largest LEN
/// (255, a `u8`) = 260 bytes.
pub const MAX_FRAME: usize = FRAME_OVERHEAD + u8::MAX as usize;

/// Most register bytes one read answer or write request can carry: LEN
/// counts CMD (1) + address (2) + data, and LEN is at most 255, so 252.
pub const MAX_DATA: usize = u8::MAX as usize - 3;

/// Length on the wire of a force-control request (LEN 0x0B): 16 bytes.
pub const FORCE_FRAME_LEN: usize = FRAME_OVERHEAD + 11;

/// Length on the wire of the answer to a force-control request (6-DoF
/// positions, LEN 0x0D): 18 bytes.
pub const POSITION_ANSWER_LEN: usize = FRAME_OVERHEAD + 13;

/// Length on the wire of a position-control request and of its answer (five
/// forces, LEN 0x0B): 16 bytes.
pub const POSITION_FRAME_LEN: usize = FRAME_OVERHEAD + 11;

/// Smallest device ID a request may address (section 2.3.1: range 1-254).
pub const MIN_ID: u8 = 1;
/// Largest device ID a request may address (section 2.3.1: range 1-254).
pub const MAX_ID: u8 = 254;
/// Factory-default device ID.
pub const DEFAULT_ID: u8 = 1;

/// Smallest force set-point / reading in device units (about -3 N).
pub const FORCE_MIN: i16 = -1000;
/// Largest force set-point / reading in device units (about +3 N). Positive
/// set-points push the operator's hand open.
pub const FORCE_MAX: i16 = 1000;
/// Largest position in device units: 1000 = finger fully open (thumb
/// rotation: outermost); 0 = fully bent (thumb rotation: innermost).
pub const POSITION_MAX: u16 = 1000;

/// Status byte of a write answer that means the write was accepted.
///
/// Ambiguity: section 2.2.4 only ever shows `0x01` in this byte and never
/// says what else it can hold. Our reading: `0x01` = accepted, any other
/// value (the simulator uses `0x00`, e.g. for a read-only register) =
/// refused.
pub const WRITE_ACCEPTED: u8 = 0x01;
/// Status byte our simulator answers for a refused write (see
/// [`WRITE_ACCEPTED`]); decoders treat every value but `0x01` as refused.
pub const WRITE_REFUSED: u8 = 0x00;

/// Finger order of every 5-element field: little, ring, middle, index, thumb.
pub const FINGERS: [&str; 5] = ["little", "ring", "middle", "index", "thumb"];
/// Degree-of-freedom order of the 6-element position answer / register.
pub const DOFS: [&str; 6] = [
    "little",
    "ring",
    "middle",
    "index",
    "thumb",
    "thumb rotation",
];

// The LEN values printed in the manual.
const _: () = assert!(FORCE_FRAME_LEN == 16 && POSITION_ANSWER_LEN == 18);
const _: () = assert!(MAX_FRAME == 260 && MAX_DATA == 252);

/// Low byte of the sum of `bytes_after_header`, i.e. of ID, LEN, CMD and
/// the data bytes (everything between the 2-byte header and CHK).
///
/// The manual says "the sum of all bytes except the packet header"; it
/// obviously does not include the checksum byte itself.
pub fn checksum(bytes_after_header: &[u8]) -> u8 {
    bytes_after_header
        .iter()
        .fold(0u8, |sum, &b| sum.wrapping_add(b))
}

/// Command byte (CMD) of a frame; a response repeats its request's command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Command {
    /// 0x31: set five finger forces; answered with the six actual positions.
    ForceControl = 0x31,
    /// 0x32: set five finger positions; answered with the five actual forces.
    PositionControl = 0x32,
    /// 0x11: read N register bytes from an address.
    ReadRegister = 0x11,
    /// 0x12: write register bytes from an address; answered with a status.
    WriteRegister = 0x12,
}

impl Command {
    /// The command for a CMD byte, `None` for a byte the manual does not list.
    pub fn from_u8(v: u8) -> Option<Self> {
        match v {
            0x31 => Some(Self::ForceControl),
            0x32 => Some(Self::PositionControl),
            0x11 => Some(Self::ReadRegister),
            0x12 => Some(Self::WriteRegister),
            _ => None,
        }
    }
}

/// Register bytes carried by a read answer or a write request (fixed
/// capacity [`MAX_DATA`], `Copy`, no heap).
///
/// Unused capacity is always zero, and equality compares only the used bytes.
#[derive(Clone, Copy)]
pub struct Data {
    bytes: [u8; MAX_DATA],
    len: u8,
}

impl Data {
    /// No bytes.
    pub const EMPTY: Self = Self {
        bytes: [0; MAX_DATA],
        len: 0,
    };

    /// Copies `bytes`; fails with [`EncodeError::TooMuchData`] beyond
    /// [`MAX_DATA`] bytes.
    pub fn new(bytes: &[u8]) -> Result<Self, EncodeError> {
        let mut data = Self::EMPTY;
        let dst = data
            .bytes
            .get_mut(..bytes.len())
            .ok_or(EncodeError::TooMuchData(bytes.len()))?;
        dst.copy_from_slice(bytes);
        // bytes.len() <= MAX_DATA (252) here, so it fits a u8.
        data.len = bytes.len() as u8;
        Ok(data)
    }

    /// The used bytes.
    pub fn as_slice(&self) -> &[u8] {
        &self.bytes[..usize::from(self.len)]
    }

    /// Number of used bytes.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Whether no byte is used.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl Default for Data {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl AsRef<[u8]> for Data {
    fn as_ref(&self) -> &[u8] {
        self.as_slice()
    }
}

impl PartialEq for Data {
    fn eq(&self, other: &Self) -> bool {
        self.as_slice() == other.as_slice()
    }
}

impl Eq for Data {}

impl fmt::Debug for Data {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_tuple("Data").field(&self.as_slice()).finish()
    }
}

/// Body of a host -> glove frame.
// `Copy` and heap-free by design (decoders and control loops pass bodies by
// value); the register variant makes it ~256 bytes, which is fine on a stack.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    /// 0x31: force set-points `[little, ring, middle, index, thumb]`, each
    /// `-1000..=1000`; positive pushes the operator's hand open, negative
    /// pushes it closed.
    ForceControl {
        /// Per-finger force set-points in device units.
        forces: [i16; 5],
    },
    /// 0x32: position set-points `[little, ring, middle, index, thumb]`,
    /// each `0..=1000` (0 = bent, 1000 = open).
    PositionControl {
        /// Per-finger position set-points in device units.
        positions: [u16; 5],
    },
    /// 0x11: read `len` bytes starting at register `address`.
    ReadRegister {
        /// First register address.
        address: u16,
        /// Number of bytes to read (N), `1..=MAX_DATA` for the encoder.
        len: u8,
    },
    /// 0x12: write `data` starting at register `address`.
    WriteRegister {
        /// First register address.
        address: u16,
        /// Bytes to write (16-bit registers little-endian).
        data: Data,
    },
}

impl Request {
    /// The CMD byte of this request.
    pub fn command(&self) -> Command {
        match self {
            Self::ForceControl { .. } => Command::ForceControl,
            Self::PositionControl { .. } => Command::PositionControl,
            Self::ReadRegister { .. } => Command::ReadRegister,
            Self::WriteRegister { .. } => Command::WriteRegister,
        }
    }

    /// Length of this request on the wire (header to checksum).
    pub fn encoded_len(&self) -> usize {
        FRAME_OVERHEAD + 1 + request_payload(self).len()
    }

    /// Length on the wire of the answer the glove sends to this request
    /// (for timeouts and [`crate::wire_time`]).
    pub fn answer_len(&self) -> usize {
        let payload = match self {
            Self::ForceControl { .. } => 12,
            Self::PositionControl { .. } => 10,
            Self::ReadRegister { len, .. } => 2 + usize::from(*len),
            Self::WriteRegister { .. } => 3,
        };
        FRAME_OVERHEAD + 1 + payload
    }
}

/// Body of a glove -> host frame.
// `Copy` and heap-free by design (decoders and control loops pass bodies by
// value); the register variant makes it ~256 bytes, which is fine on a stack.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Response {
    /// Answer to 0x31: actual positions `[little, ring, middle, index,
    /// thumb, thumb rotation]`, nominally `0..=1000` (decoded raw).
    ForceControl {
        /// Per-DoF actual positions in device units.
        positions: [u16; 6],
    },
    /// Answer to 0x32: actual forces `[little, ring, middle, index, thumb]`,
    /// nominally `-1000..=1000` (decoded raw). The manual's note: positive
    /// means the operator's finger pushes the glove towards a fist.
    PositionControl {
        /// Per-finger actual forces in device units.
        forces: [i16; 5],
    },
    /// Answer to 0x11: the register bytes read from `address`.
    ReadRegister {
        /// First register address (echoed).
        address: u16,
        /// The bytes read (N = LEN - 3).
        data: Data,
    },
    /// Answer to 0x12: `status` is [`WRITE_ACCEPTED`] (0x01) when the write
    /// was accepted, anything else means refused (our reading, see there).
    WriteRegister {
        /// First register address (echoed).
        address: u16,
        /// Status byte.
        status: u8,
    },
}

impl Response {
    /// The CMD byte of this response.
    pub fn command(&self) -> Command {
        match self {
            Self::ForceControl { .. } => Command::ForceControl,
            Self::PositionControl { .. } => Command::PositionControl,
            Self::ReadRegister { .. } => Command::ReadRegister,
            Self::WriteRegister { .. } => Command::WriteRegister,
        }
    }

    /// Length of this response on the wire (header to checksum).
    pub fn encoded_len(&self) -> usize {
        FRAME_OVERHEAD + 1 + response_payload(self).len()
    }

    /// For a write answer: whether the glove accepted the write (status
    /// [`WRITE_ACCEPTED`]); `None` for the other responses.
    pub fn write_accepted(&self) -> Option<bool> {
        match self {
            Self::WriteRegister { status, .. } => Some(*status == WRITE_ACCEPTED),
            _ => None,
        }
    }
}

/// A frame: the device ID and the body ([`Request`] or [`Response`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<B> {
    /// Device ID (byte 2).
    pub id: u8,
    /// Decoded command and data.
    pub body: B,
}

/// Why a frame or a register write could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// A force set-point outside `-1000..=1000`.
    #[error("force of finger {finger} is {value}, outside -1000..=1000")]
    ForceOutOfRange {
        /// Finger index (little = 0 .. thumb = 4).
        finger: usize,
        /// The refused value.
        value: i16,
    },
    /// A position set-point outside `0..=1000`.
    #[error("position of finger {finger} is {value}, outside 0..=1000")]
    PositionOutOfRange {
        /// Finger index (little = 0 .. thumb = 4).
        finger: usize,
        /// The refused value.
        value: u16,
    },
    /// A request addressed to ID 0 or 255.
    ///
    /// Section 2.3.1 gives the ID range as 1-254 and never mentions a
    /// broadcast ID; 0 and 255 are the usual "unset"/"broadcast" values on
    /// such buses, so requests to them are refused rather than guessed at.
    #[error("device id {0} is outside 1..=254")]
    IdOutOfRange(u8),
    /// More register bytes than one frame can carry ([`MAX_DATA`]), in
    /// [`Data::new`] or as a read length.
    #[error("{0} register bytes do not fit one frame (at most 252)")]
    TooMuchData(usize),
    /// A register read of zero bytes.
    #[error("a register read must ask for at least one byte")]
    ReadLengthZero,
    /// A register write of zero bytes.
    #[error("a register write must carry at least one byte")]
    WriteLengthZero,
    /// The output buffer is shorter than the frame.
    #[error("output buffer too small: {needed} bytes needed")]
    BufferTooSmall {
        /// Bytes the frame needs.
        needed: usize,
    },
    /// A register value outside its range (and not its special value).
    #[error("value {value} for element {index} of register {register} is out of range")]
    ValueOutOfRange {
        /// Register name.
        register: &'static str,
        /// Element index within the register.
        index: usize,
        /// The refused value.
        value: i32,
    },
    /// A write to a read-only register.
    #[error("register {0} is read-only")]
    ReadOnly(&'static str),
    /// A write with a number of values other than the register's count.
    #[error("register {register} takes {expected} values, got {got}")]
    WrongCount {
        /// Register name.
        register: &'static str,
        /// The register's element count.
        expected: usize,
        /// Values given.
        got: usize,
    },
}

/// Largest payload after CMD: address (2) + [`MAX_DATA`].
const MAX_PAYLOAD: usize = 2 + MAX_DATA;

/// The bytes between CMD and CHK, built on the stack.
struct Payload {
    bytes: [u8; MAX_PAYLOAD],
    len: usize,
}

impl Payload {
    fn new() -> Self {
        Self {
            bytes: [0; MAX_PAYLOAD],
            len: 0,
        }
    }

    /// Appends `bytes`; every caller stays within [`MAX_PAYLOAD`] by
    /// construction (at most 2 + [`MAX_DATA`]), extra bytes would be dropped.
    fn put(&mut self, bytes: &[u8]) {
        let end = (self.len + bytes.len()).min(MAX_PAYLOAD);
        let n = end - self.len;
        self.bytes[self.len..end].copy_from_slice(&bytes[..n]);
        self.len = end;
    }

    fn as_slice(&self) -> &[u8] {
        &self.bytes[..self.len]
    }

    fn len(&self) -> usize {
        self.len
    }
}

fn request_payload(request: &Request) -> Payload {
    let mut p = Payload::new();
    match request {
        Request::ForceControl { forces } => forces.iter().for_each(|f| p.put(&f.to_le_bytes())),
        Request::PositionControl { positions } => {
            positions.iter().for_each(|v| p.put(&v.to_le_bytes()));
        }
        Request::ReadRegister { address, len } => {
            p.put(&address.to_le_bytes());
            p.put(&[*len]);
        }
        Request::WriteRegister { address, data } => {
            p.put(&address.to_le_bytes());
            p.put(data.as_slice());
        }
    }
    p
}

fn response_payload(response: &Response) -> Payload {
    let mut p = Payload::new();
    match response {
        Response::ForceControl { positions } => {
            positions.iter().for_each(|v| p.put(&v.to_le_bytes()));
        }
        Response::PositionControl { forces } => forces.iter().for_each(|f| p.put(&f.to_le_bytes())),
        Response::ReadRegister { address, data } => {
            p.put(&address.to_le_bytes());
            p.put(data.as_slice());
        }
        Response::WriteRegister { address, status } => {
            p.put(&address.to_le_bytes());
            p.put(&[*status]);
        }
    }
    p
}

/// Writes `header | id | LEN | command | payload | CHK` into `out`.
fn write_frame(
    header: [u8; 2],
    id: u8,
    command: Command,
    payload: &Payload,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let total = FRAME_OVERHEAD + 1 + payload.len();
    let out = out
        .get_mut(..total)
        .ok_or(EncodeError::BufferTooSmall { needed: total })?;
    out[..2].copy_from_slice(&header);
    out[2] = id;
    // payload.len() <= MAX_PAYLOAD (254), so LEN = 1 + payload.len() <= 255.
    out[3] = (1 + payload.len()) as u8;
    out[4] = command as u8;
    out[5..total - 1].copy_from_slice(payload.as_slice());
    out[total - 1] = checksum(&out[2..total - 1]);
    Ok(total)
}

/// Checks a request against the manual's ranges.
fn validate_request(id: u8, request: &Request) -> Result<(), EncodeError> {
    if !(MIN_ID..=MAX_ID).contains(&id) {
        return Err(EncodeError::IdOutOfRange(id));
    }
    match request {
        Request::ForceControl { forces } => {
            if let Some((finger, &value)) = forces
                .iter()
                .enumerate()
                .find(|(_, f)| !(FORCE_MIN..=FORCE_MAX).contains(*f))
            {
                return Err(EncodeError::ForceOutOfRange { finger, value });
            }
        }
        Request::PositionControl { positions } => {
            if let Some((finger, &value)) = positions
                .iter()
                .enumerate()
                .find(|(_, p)| **p > POSITION_MAX)
            {
                return Err(EncodeError::PositionOutOfRange { finger, value });
            }
        }
        Request::ReadRegister { len, .. } => {
            if *len == 0 {
                return Err(EncodeError::ReadLengthZero);
            }
            // The answer carries LEN = 3 + N <= 255, so N <= 252: a longer
            // read could not be answered in one frame.
            if usize::from(*len) > MAX_DATA {
                return Err(EncodeError::TooMuchData(usize::from(*len)));
            }
        }
        Request::WriteRegister { data, .. } => {
            // LEN = 3 would be a legal frame, but a write of nothing is never
            // what a caller means and the manual does not say how the glove
            // answers it.
            if data.is_empty() {
                return Err(EncodeError::WriteLengthZero);
            }
        }
    }
    Ok(())
}

/// Encodes a request frame into `out`, returns the bytes written.
///
/// Validates the ID (`1..=254`), forces (`-1000..=1000`), positions
/// (`0..=1000`), read lengths (`1..=252`) and that a write carries data;
/// then that `out` is long enough. Never allocates.
pub fn encode_request(id: u8, request: &Request, out: &mut [u8]) -> Result<usize, EncodeError> {
    validate_request(id, request)?;
    write_frame(
        REQUEST_HEADER,
        id,
        request.command(),
        &request_payload(request),
        out,
    )
}

/// Encodes a response frame (for the simulator) into `out`, returns the
/// bytes written. No range checks: every [`Response`] value fits the wire,
/// any ID is allowed; the only error is [`EncodeError::BufferTooSmall`].
pub fn encode_response(id: u8, response: &Response, out: &mut [u8]) -> Result<usize, EncodeError> {
    write_frame(
        RESPONSE_HEADER,
        id,
        response.command(),
        &response_payload(response),
        out,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(id: u8, r: &Request) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode_request(id, r, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    fn resp(id: u8, r: &Response) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode_response(id, r, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn force_request_known_answer_zero() {
        let bytes = req(1, &Request::ForceControl { forces: [0; 5] });
        let mut expected = vec![0xEB, 0x90, 0x01, 0x0B, 0x31];
        expected.extend([0u8; 10]);
        expected.push(0x3D); // 0x01 + 0x0B + 0x31
        assert_eq!(bytes, expected);
        assert_eq!(bytes.len(), FORCE_FRAME_LEN);
    }

    #[test]
    fn force_request_known_answer_values() {
        // forces 1000 = E8 03, -1000 = 18 FC, 500 = F4 01, -1 = FF FF, 0
        let bytes = req(
            2,
            &Request::ForceControl {
                forces: [1000, -1000, 500, -1, 0],
            },
        );
        // sum = 02 + 0B + 31 + E8 + 03 + 18 + FC + F4 + 01 + FF + FF
        //     = 0x530 -> low byte 0x30 (hand-computed)
        assert_eq!(
            bytes,
            [
                0xEB, 0x90, 0x02, 0x0B, 0x31, 0xE8, 0x03, 0x18, 0xFC, 0xF4, 0x01, 0xFF, 0xFF, 0x00,
                0x00, 0x30
            ]
        );
    }

    #[test]
    fn position_answer_known_answer() {
        let bytes = resp(
            1,
            &Response::ForceControl {
                positions: [1000, 0, 500, 1, 256, 999],
            },
        );
        // 01 + 0D + 31 + E8 + 03 + 00 + 00 + F4 + 01 + 01 + 00 + 00 + 01 + E7 + 03
        // = 0x30B -> 0x0B
        assert_eq!(
            bytes,
            [
                0x90, 0xEB, 0x01, 0x0D, 0x31, 0xE8, 0x03, 0x00, 0x00, 0xF4, 0x01, 0x01, 0x00, 0x00,
                0x01, 0xE7, 0x03, 0x0B
            ]
        );
        assert_eq!(bytes.len(), POSITION_ANSWER_LEN);
    }

    #[test]
    fn read_and_write_known_answers() {
        // Read 6 bytes of the ID register 1000 = 0x03E8.
        let bytes = req(
            1,
            &Request::ReadRegister {
                address: 1000,
                len: 6,
            },
        );
        // 01 + 04 + 11 + E8 + 03 + 06 = 0x107 -> 0x07
        assert_eq!(
            bytes,
            [0xEB, 0x90, 0x01, 0x04, 0x11, 0xE8, 0x03, 0x06, 0x07]
        );
        // Write 1 to the ID register: 01 + 04 + 12 + E8 + 03 + 01 = 0x103 -> 0x03
        let bytes = req(
            1,
            &Request::WriteRegister {
                address: 1000,
                data: Data::new(&[1]).unwrap(),
            },
        );
        assert_eq!(
            bytes,
            [0xEB, 0x90, 0x01, 0x04, 0x12, 0xE8, 0x03, 0x01, 0x03]
        );
        let bytes = resp(
            1,
            &Response::WriteRegister {
                address: 1000,
                status: WRITE_ACCEPTED,
            },
        );
        assert_eq!(
            bytes,
            [0x90, 0xEB, 0x01, 0x04, 0x12, 0xE8, 0x03, 0x01, 0x03]
        );
    }

    #[test]
    fn range_refusals() {
        let mut buf = [0u8; MAX_FRAME];
        assert_eq!(
            encode_request(
                1,
                &Request::ForceControl {
                    forces: [0, 0, 1001, 0, -2000]
                },
                &mut buf
            ),
            Err(EncodeError::ForceOutOfRange {
                finger: 2,
                value: 1001
            })
        );
        assert_eq!(
            encode_request(
                1,
                &Request::ForceControl {
                    forces: [-1001, 0, 0, 0, 0]
                },
                &mut buf
            ),
            Err(EncodeError::ForceOutOfRange {
                finger: 0,
                value: -1001
            })
        );
        assert_eq!(
            encode_request(
                1,
                &Request::PositionControl {
                    positions: [0, 0, 0, 0, 1001]
                },
                &mut buf
            ),
            Err(EncodeError::PositionOutOfRange {
                finger: 4,
                value: 1001
            })
        );
        for id in [0, 255] {
            assert_eq!(
                encode_request(id, &Request::ForceControl { forces: [0; 5] }, &mut buf),
                Err(EncodeError::IdOutOfRange(id))
            );
        }
        assert_eq!(
            encode_request(
                1,
                &Request::ReadRegister {
                    address: 1000,
                    len: 0
                },
                &mut buf
            ),
            Err(EncodeError::ReadLengthZero)
        );
        assert_eq!(
            encode_request(
                1,
                &Request::ReadRegister {
                    address: 1000,
                    len: 253
                },
                &mut buf
            ),
            Err(EncodeError::TooMuchData(253))
        );
        assert_eq!(
            encode_request(
                1,
                &Request::WriteRegister {
                    address: 1000,
                    data: Data::EMPTY
                },
                &mut buf
            ),
            Err(EncodeError::WriteLengthZero)
        );
        assert_eq!(Data::new(&[0; 253]), Err(EncodeError::TooMuchData(253)));
        assert_eq!(Data::new(&[7; 252]).map(|d| d.len()), Ok(252));
    }

    #[test]
    fn boundaries_accepted() {
        let mut buf = [0u8; MAX_FRAME];
        for forces in [[-1000; 5], [1000; 5]] {
            assert!(encode_request(254, &Request::ForceControl { forces }, &mut buf).is_ok());
        }
        for positions in [[0; 5], [1000; 5]] {
            assert!(encode_request(1, &Request::PositionControl { positions }, &mut buf).is_ok());
        }
        // Largest frames: LEN 255.
        let data = Data::new(&[0xAB; MAX_DATA]).unwrap();
        let r = Request::WriteRegister { address: 1, data };
        assert_eq!(encode_request(1, &r, &mut buf), Ok(MAX_FRAME));
        assert_eq!(buf[3], 0xFF);
        let r = Response::ReadRegister { address: 1, data };
        assert_eq!(encode_response(0, &r, &mut buf), Ok(MAX_FRAME));
        assert_eq!(r.encoded_len(), MAX_FRAME);
        let r = Request::ReadRegister {
            address: 1,
            len: MAX_DATA as u8,
        };
        assert!(encode_request(1, &r, &mut buf).is_ok());
        assert_eq!(r.answer_len(), MAX_FRAME);
    }

    #[test]
    fn buffer_too_small() {
        let mut buf = [0u8; FORCE_FRAME_LEN - 1];
        assert_eq!(
            encode_request(1, &Request::ForceControl { forces: [0; 5] }, &mut buf),
            Err(EncodeError::BufferTooSmall {
                needed: FORCE_FRAME_LEN
            })
        );
        assert_eq!(
            encode_response(1, &Response::ForceControl { positions: [0; 6] }, &mut buf),
            Err(EncodeError::BufferTooSmall {
                needed: POSITION_ANSWER_LEN
            })
        );
        let mut exact = [0u8; FORCE_FRAME_LEN];
        assert_eq!(
            encode_request(1, &Request::ForceControl { forces: [0; 5] }, &mut exact),
            Ok(FORCE_FRAME_LEN)
        );
    }

    #[test]
    fn lengths_and_commands() {
        let f = Request::ForceControl { forces: [0; 5] };
        assert_eq!(f.encoded_len(), FORCE_FRAME_LEN);
        assert_eq!(f.answer_len(), POSITION_ANSWER_LEN);
        let p = Request::PositionControl { positions: [0; 5] };
        assert_eq!(p.encoded_len(), POSITION_FRAME_LEN);
        assert_eq!(p.answer_len(), POSITION_FRAME_LEN);
        for c in [
            Command::ForceControl,
            Command::PositionControl,
            Command::ReadRegister,
            Command::WriteRegister,
        ] {
            assert_eq!(Command::from_u8(c as u8), Some(c));
        }
        assert_eq!(Command::from_u8(0x33), None);
        assert_eq!(
            Response::WriteRegister {
                address: 0,
                status: 0
            }
            .write_accepted(),
            Some(false)
        );
        assert_eq!(checksum(&[0xFF, 0x02]), 0x01);
        assert_eq!(format!("{:?}", Data::new(&[1, 2]).unwrap()), "Data([1, 2])");
    }
}
