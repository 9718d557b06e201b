//! Wire protocol and register map of the EH55BF1-BL/BR exoskeleton glove
//! (RS232 115200 8N1, or Bluetooth SPP carrying the same frames).
//!
//! "Section N" is the manual's, restated by number in docs/devices/glove.md.
//!
//! # What this crate owns
//!
//! * The frames of section 2.2 ([`Request`], [`Response`], [`Frame`]), their
//!   checksum ([`checksum`]) and encoders ([`encode_request`],
//!   [`encode_response`]) writing into caller buffers.
//! * Streaming, resynchronising decoders for both directions
//!   ([`ResponseDecoder`] for the glove node, [`RequestDecoder`] for the
//!   simulator), one generic core ([`Decoder`]) over a [`Direction`].
//! * The register map of section 2.3 ([`reg`], [`REGISTERS`],
//!   [`write_request`], [`read_request`], [`decode_values`]), the error
//!   bits ([`ErrorBits`]), baud rates ([`BaudRate`], [`wire_time`]) and the
//!   calibration steps ([`CALIBRATION_STEPS`]).
//!
//! It is pure: no I/O, no clock, no threads, no heap in the codec (the
//! decoders use a fixed `[u8; 2 * MAX_FRAME]` buffer). Every decoder is
//! total: any bytes give a value or a typed error, never a panic.
//!
//! # What it must not depend on
//!
//! No serial-port crate, no iceoryx2, no message/IPC crate (`teleop-msgs`),
//! no runtime crate, no logging. Opening the port, timing the question and
//! answer, and converting to wire messages is the glove node's job (and the
//! simulator's on the other side).
//!
//! # Frames
//!
//! ```text
//! request  (host -> glove): EB 90 | ID | LEN | CMD | data... | CHK
//! response (glove -> host): 90 EB | ID | LEN | CMD | data... | CHK
//! ```
//!
//! Multi-byte values are little-endian. Finger order is always little, ring,
//! middle, index, thumb (+ thumb rotation for the 6-DoF positions).
//!
//! ```
//! use teleop_glove_protocol::{encode_request, Request, ResponseDecoder, MAX_FRAME};
//!
//! let mut buf = [0u8; MAX_FRAME];
//! let n = encode_request(1, &Request::ForceControl { forces: [0, 0, 0, 0, 0] }, &mut buf)?;
//! assert_eq!(buf[..n], [0xEB, 0x90, 0x01, 0x0B, 0x31, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x3D]);
//!
//! let mut decoder = ResponseDecoder::new(Some(1));
//! decoder.push(&[0x90, 0xEB, 0x01, 0x04, 0x12, 0xE8, 0x03, 0x01, 0x03]);
//! let frame = decoder.next().expect("a frame").expect("no error");
//! assert_eq!(frame.body.write_accepted(), Some(true));
//! assert!(decoder.next().is_none());
//! # Ok::<(), teleop_glove_protocol::EncodeError>(())
//! ```
//!
//! # Ambiguities of the manual, and what we chose
//!
//! 1. **LEN** counts CMD + data bytes, not header, ID, LEN or CHK (the
//!    manual only says "data length of this frame"; its examples 0x0B, 0x0D
//!    and 0x04 fix it).
//! 2. **Checksum**: "low-order byte of the sum of all bytes except the
//!    packet header" — read as ID, LEN, CMD and data, without CHK itself.
//! 3. **Write answer status**: the manual only shows `0x01`. We take
//!    [`WRITE_ACCEPTED`] (`0x01`) = accepted and any other value = refused;
//!    the simulator answers [`WRITE_REFUSED`] (`0x00`) for writes to
//!    read-only registers.
//! 4. **Write request layout**: its table puts CHK at "Byte8", true only for
//!    N = 1; CHK follows the N data bytes (byte 7 + N), as in the read answer.
//!    The section also says "after receiving the instruction frame of Read
//!    Register" where it means Write Register.
//! 5. **Factory reset** (2.3.5) has no address in the register table; we use
//!    1006 as in the Inspire RH56 actuator family whose register map this
//!    glove shares ([`reg::FACTORY_RESET`]).
//! 6. **Error-code order**: the table names 1609 "thumb" and 1610 "bending
//!    of the thumb"; every other table, and the manual's own ERROR(3) =
//!    index example, orders little, ring, middle, index, thumb, which we use
//!    ([`reg::ERROR_CODE`]). Bits 5..=7 are undefined and reported as such.
//! 7. **Device IDs**: the manual gives 1..=254 and no broadcast ID. Requests
//!    to 0 or 255 are refused ([`EncodeError::IdOutOfRange`]); the decoders
//!    and [`encode_response`] accept any ID.
//! 8. **Read length**: N is a byte, but an answer can carry at most 252
//!    bytes (LEN = 3 + N <= 255), so [`encode_request`] refuses N > 252 and
//!    N = 0 (and writes of zero bytes).
//! 9. **Signedness**: the manual types every 16-bit field "short". Force
//!    fields are `i16`; the position fields of frames are `u16` (range
//!    0..=1000, so both readings agree); the position *registers* are `i16`
//!    because the set-points use -1 as "leave this finger alone"; currents
//!    and the voltage are `u16`.
//! 10. **Field names**: the force-control answer calls its fields
//!     `Finger*_Pos_Set` and the position-control answer `Finger*_Force_Set`;
//!     they are actual values, not set-points.
//! 11. **Force sign**: a positive force *set-point* pushes the operator's
//!     hand open; a positive *actual* force means the operator's finger
//!     pushes towards a fist (the manual's notes to 2.2.1 and 2.2.2).
//! 12. **Undocumented units/defaults**: the voltage has no unit, the
//!     calibration register no default, the set-point registers no default
//!     and no "savable" statement; we leave them empty / `None` / `false`.
//! 13. **Out-of-range readings** from the glove are decoded raw; only the
//!     encoders check ranges.

mod decode;
mod frame;
mod registers;

pub use decode::{
    DecodeError, Decoder, Direction, RequestDecoder, Requests, ResponseDecoder, Responses,
};
pub use frame::{
    checksum, encode_request, encode_response, Command, Data, EncodeError, Frame, Request,
    Response, DEFAULT_ID, DOFS, FINGERS, FORCE_FRAME_LEN, FORCE_MAX, FORCE_MIN, FRAME_OVERHEAD,
    MAX_DATA, MAX_FRAME, MAX_ID, MIN_ID, POSITION_ANSWER_LEN, POSITION_FRAME_LEN, POSITION_MAX,
    REQUEST_HEADER, RESPONSE_HEADER, WRITE_ACCEPTED, WRITE_REFUSED,
};
pub use registers::{
    decode_values, read_request, reg, register_at, register_containing, wire_time, write_request,
    Access, BaudRate, ErrorBits, Register, RegisterError, Values, Width, BITS_PER_BYTE,
    CALIBRATION_STEPS, MAX_VALUES, REGISTERS,
};
