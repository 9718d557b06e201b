//! The slcan (Lawicel ASCII) codec: pure, total, no I/O.
//!
//! Both directions: [`Decoder`] reads what an adapter sends (frames, acks, errors, status and
//! version replies, the Linux slcan driver's `s`/`e` state and error lines), [`CommandDecoder`]
//! reads what a host sends (for a simulated adapter). [`encode_frame`], [`Command::encode`] and
//! [`Item::encode`] write the lines. Every decoder takes any bytes and gives items or typed
//! errors, never a panic (proptested).
//!
//! Facts (docs/devices/allegro.md, "slcan (Lawicel ASCII)"): lines end in CR; OK = CR, error = BEL
//! (0x07); CAN232/CANUSB answer `t` with `z\r` and `T` with `Z\r`, CANable answers every line
//! with a bare CR or BEL and accepts either hex case; the Linux slcan driver writes upper-case
//! hex, ends a line at CR or BEL, and adds `e`/`s` error and state lines. So the decoder skips
//! line feeds, takes acks and errors wherever they come between frames, and accepts both hex
//! cases. Timestamps (`Z1`): 4 hex digits of milliseconds after the data, 0000..EA5F.

use std::fmt;

use crate::{BusState, CanFrame};

/// Longest line either decoder keeps (a 29-bit frame with 8 bytes and a timestamp is 31
/// characters; version strings of CANable firmware are longer). Longer lines become
/// [`Item::Garbage`] / a command error, cut to this length.
pub const MAX_LINE: usize = 64;

/// Bits of the `F` status reply (Lawicel; "meaning varies" between adapters).
pub mod status {
    /// Receive FIFO full.
    pub const RX_FIFO_FULL: u8 = 0x01;
    /// Transmit FIFO full.
    pub const TX_FIFO_FULL: u8 = 0x02;
    /// Error warning (an error counter at or above 96).
    pub const ERROR_WARNING: u8 = 0x04;
    /// Data overrun.
    pub const DATA_OVERRUN: u8 = 0x08;
    /// Error passive (an error counter at or above 128).
    pub const ERROR_PASSIVE: u8 = 0x20;
    /// Arbitration lost.
    pub const ARBITRATION_LOST: u8 = 0x40;
    /// Bus error (adapters use it for bus-off).
    pub const BUS_ERROR: u8 = 0x80;
}

/// The bus state that `F` status flags mean: bus error -> bus-off, error passive, error
/// warning, else error active.
pub fn status_bus_state(flags: u8) -> BusState {
    if flags & status::BUS_ERROR != 0 {
        BusState::BusOff
    } else if flags & status::ERROR_PASSIVE != 0 {
        BusState::ErrorPassive
    } else if flags & status::ERROR_WARNING != 0 {
        BusState::ErrorWarning
    } else {
        BusState::ErrorActive
    }
}

const HEX: &[u8; 16] = b"0123456789ABCDEF";
const CR: u8 = b'\r';
const LF: u8 = b'\n';
const BEL: u8 = 0x07;

fn push_hex(out: &mut Vec<u8>, value: u32, digits: u32) {
    for i in (0..digits).rev() {
        out.push(HEX[((value >> (4 * i)) & 0xF) as usize]);
    }
}

fn hex_digit(c: u8) -> Option<u32> {
    match c {
        b'0'..=b'9' => Some(u32::from(c - b'0')),
        b'a'..=b'f' => Some(u32::from(c - b'a' + 10)),
        b'A'..=b'F' => Some(u32::from(c - b'A' + 10)),
        _ => None,
    }
}

/// Up to 8 hex digits (either case) as a number; `None` for other characters or an empty or
/// longer string.
fn parse_hex(s: &[u8]) -> Option<u32> {
    if s.is_empty() || s.len() > 8 {
        return None;
    }
    s.iter()
        .try_fold(0u32, |acc, &c| Some(acc << 4 | hex_digit(c)?))
}

fn parse_dec(s: &[u8]) -> Option<u16> {
    if s.is_empty() || s.len() > 4 {
        return None;
    }
    s.iter().try_fold(0u16, |acc, &c| {
        c.is_ascii_digit().then(|| acc * 10 + u16::from(c - b'0'))
    })
}

/// Writes `frame` as an slcan line: `t3D380080008000800080\r`, `r2000\r`, `T1234567821122\r`,
/// upper-case hex, CR-terminated.
pub fn encode_frame(frame: &CanFrame, out: &mut Vec<u8>) {
    encode_frame_body(frame, out);
    out.push(CR);
}

/// Writes `frame` as an adapter does with timestamps on (`Z1`): the line of
/// [`encode_frame`] with 4 hex digits of milliseconds before the CR (the value is taken
/// modulo 60000, as adapters wrap).
pub fn encode_frame_timestamped(frame: &CanFrame, timestamp_ms: u16, out: &mut Vec<u8>) {
    encode_frame_body(frame, out);
    push_hex(out, u32::from(timestamp_ms % 60_000), 4);
    out.push(CR);
}

fn encode_frame_body(frame: &CanFrame, out: &mut Vec<u8>) {
    let (kind, digits) = match (frame.is_extended(), frame.is_remote()) {
        (false, false) => (b't', 3),
        (false, true) => (b'r', 3),
        (true, false) => (b'T', 8),
        (true, true) => (b'R', 8),
    };
    out.push(kind);
    push_hex(out, frame.raw_id(), digits);
    // dlc() is at most 8.
    out.push(b'0' + frame.dlc() as u8);
    for &b in frame.data() {
        push_hex(out, u32::from(b), 2);
    }
}

/// Parses a frame line (`t`, `T`, `r`, `R`); the timestamp when `timestamps_ok` and present.
/// `None` when the line is not a well-formed frame.
fn parse_frame(line: &[u8], timestamps_ok: bool) -> Option<(CanFrame, Option<u16>)> {
    let (&kind, rest) = line.split_first()?;
    let (extended, remote) = match kind {
        b't' => (false, false),
        b'r' => (false, true),
        b'T' => (true, false),
        b'R' => (true, true),
        _ => return None,
    };
    let id_len = if extended { 8 } else { 3 };
    let id = parse_hex(rest.get(..id_len)?)?;
    let dlc_char = *rest.get(id_len)?;
    if !(b'0'..=b'8').contains(&dlc_char) {
        return None;
    }
    let dlc = dlc_char - b'0';
    let tail = rest.get(id_len + 1..)?;
    let data_len = if remote { 0 } else { 2 * usize::from(dlc) };
    let (data_hex, stamp) = if tail.len() == data_len {
        (tail, None)
    } else if timestamps_ok && tail.len() == data_len + 4 {
        let (d, s) = tail.split_at(data_len);
        (d, Some(u16::try_from(parse_hex(s)?).ok()?))
    } else {
        return None;
    };
    let mut data = [0u8; 8];
    for (i, pair) in data_hex.chunks_exact(2).enumerate() {
        data[i] = u8::try_from(parse_hex(pair)?).ok()?;
    }
    let frame = match (extended, remote) {
        (false, false) => CanFrame::standard(u16::try_from(id).ok()?, &data[..usize::from(dlc)]),
        (false, true) => CanFrame::standard_remote(u16::try_from(id).ok()?, dlc),
        (true, false) => CanFrame::extended(id, &data[..usize::from(dlc)]),
        (true, true) => CanFrame::extended_remote(id, dlc),
    }?;
    Some((frame, stamp))
}

/// Bytes as printable text: ASCII as is, others as `\xNN`.
fn escaped(bytes: &[u8]) -> String {
    bytes.escape_ascii().to_string()
}

/// A host command to an slcan adapter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// `Sn`: standard bit rate code 0..8 (see [`crate::Bitrate::slcan_code`]); only while closed.
    Bitrate(u8),
    /// `sxxyy`: raw BTR0/BTR1 of an SJA1000; only while closed.
    Btr(u8, u8),
    /// `O`: open the channel (normal mode).
    Open,
    /// `L`: open listen-only.
    ListenOnly,
    /// `C`: close the channel.
    Close,
    /// `t`/`T`/`r`/`R`: send a frame.
    Transmit(CanFrame),
    /// `F`: read (and clear) the status flags.
    Status,
    /// `V`: hardware and firmware version.
    Version,
    /// `N`: serial number.
    Serial,
    /// `Z0`/`Z1`: timestamps off/on.
    Timestamps(bool),
    /// `Mxxxxxxxx`: acceptance code.
    AcceptanceCode(u32),
    /// `mxxxxxxxx`: acceptance mask.
    AcceptanceMask(u32),
}

impl Command {
    /// Writes the command line, CR-terminated.
    pub fn encode(&self, out: &mut Vec<u8>) {
        match *self {
            Command::Bitrate(n) => {
                out.push(b'S');
                push_hex(out, u32::from(n), if n > 0xF { 2 } else { 1 });
            }
            Command::Btr(b0, b1) => {
                out.push(b's');
                push_hex(out, u32::from(b0) << 8 | u32::from(b1), 4);
            }
            Command::Open => out.push(b'O'),
            Command::ListenOnly => out.push(b'L'),
            Command::Close => out.push(b'C'),
            Command::Transmit(ref frame) => encode_frame_body(frame, out),
            Command::Status => out.push(b'F'),
            Command::Version => out.push(b'V'),
            Command::Serial => out.push(b'N'),
            Command::Timestamps(on) => out.extend_from_slice(if on { b"Z1" } else { b"Z0" }),
            Command::AcceptanceCode(v) => {
                out.push(b'M');
                push_hex(out, v, 8);
            }
            Command::AcceptanceMask(v) => {
                out.push(b'm');
                push_hex(out, v, 8);
            }
        }
        out.push(CR);
    }

    /// What the command does, for messages ("set bit rate", "open", ...).
    pub fn meaning(&self) -> &'static str {
        match self {
            Command::Bitrate(_) => "set bit rate",
            Command::Btr(..) => "set bit timing registers",
            Command::Open => "open the channel",
            Command::ListenOnly => "open the channel listen-only",
            Command::Close => "close the channel",
            Command::Transmit(_) => "transmit",
            Command::Status => "read status flags",
            Command::Version => "read version",
            Command::Serial => "read serial number",
            Command::Timestamps(_) => "set timestamps",
            Command::AcceptanceCode(_) => "set acceptance code",
            Command::AcceptanceMask(_) => "set acceptance mask",
        }
    }
}

/// The command as its line without the CR, e.g. `S8`, `O`, `t1000`.
impl fmt::Display for Command {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut line = Vec::with_capacity(32);
        self.encode(&mut line);
        line.pop();
        f.write_str(&escaped(&line))
    }
}

/// One thing an adapter sent.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Item {
    /// A received frame, with the adapter's timestamp when timestamps are on.
    Frame {
        /// The frame.
        frame: CanFrame,
        /// Milliseconds 0..60000 (wrapping), when the line carried one.
        timestamp_ms: Option<u16>,
    },
    /// An empty line (a bare CR): OK, the answer to a command (and, on CANable, to every
    /// transmitted frame).
    Ok,
    /// `z` or `Z`: a transmitted frame accepted (CAN232/CANUSB style).
    FrameAck,
    /// BEL: a command refused.
    Error,
    /// `Fxx`: the status flags (see [`status`]).
    Status(u8),
    /// `V...` or `v...`: the version text after the letter.
    Version(String),
    /// `N...`: the serial number text after the letter.
    Serial(String),
    /// Linux slcan driver `sSRRRTTT` state line (`sa057033`: active, rx errors 57, tx 33).
    State {
        /// The controller's state.
        state: BusState,
        /// Receive error counter.
        rx_errors: u16,
        /// Transmit error counter.
        tx_errors: u16,
    },
    /// Linux slcan driver `eNcc..` error line: which kinds of errors it reported.
    BusError {
        /// Receive-side errors (CRC, form, stuff, rx overrun).
        rx: bool,
        /// Transmit-side errors (ACK, bit 0/1, tx overrun).
        tx: bool,
        /// An rx or tx overrun among them.
        overrun: bool,
    },
    /// A line that parses as none of the above (cut to [`MAX_LINE`] bytes).
    Garbage(Vec<u8>),
}

impl Item {
    /// Writes the item as an adapter sends it (for a simulated adapter): frames as
    /// [`encode_frame`] (or timestamped), `Ok` as CR, `FrameAck` as `z\r`, `Error` as BEL,
    /// `Status` as `Fxx\r`, state lines in the Linux driver's form. Garbage is written as is
    /// with a CR.
    pub fn encode(&self, out: &mut Vec<u8>) {
        match self {
            Item::Frame {
                frame,
                timestamp_ms: None,
            } => encode_frame(frame, out),
            Item::Frame {
                frame,
                timestamp_ms: Some(t),
            } => encode_frame_timestamped(frame, *t, out),
            Item::Ok => out.push(CR),
            Item::FrameAck => out.extend_from_slice(b"z\r"),
            Item::Error => out.push(BEL),
            Item::Status(flags) => {
                out.push(b'F');
                push_hex(out, u32::from(*flags), 2);
                out.push(CR);
            }
            Item::Version(text) => {
                out.push(b'V');
                out.extend_from_slice(text.as_bytes());
                out.push(CR);
            }
            Item::Serial(text) => {
                out.push(b'N');
                out.extend_from_slice(text.as_bytes());
                out.push(CR);
            }
            Item::State {
                state,
                rx_errors,
                tx_errors,
            } => {
                let c = match state {
                    BusState::ErrorActive => 'a',
                    BusState::ErrorWarning => 'w',
                    BusState::ErrorPassive => 'p',
                    BusState::BusOff => 'b',
                };
                let line = format!("s{c}{:03}{:03}\r", rx_errors % 1000, tx_errors % 1000);
                out.extend_from_slice(line.as_bytes());
            }
            Item::BusError { rx, tx, overrun } => {
                let mut codes = Vec::with_capacity(3);
                if *rx {
                    codes.push(if *overrun { b'o' } else { b'c' });
                }
                if *tx {
                    codes.push(if *overrun { b'O' } else { b'a' });
                }
                if codes.is_empty() && *overrun {
                    codes.push(b'o');
                }
                out.push(b'e');
                out.push(b'0' + codes.len() as u8);
                out.extend_from_slice(&codes);
                out.push(CR);
            }
            Item::Garbage(bytes) => {
                out.extend_from_slice(bytes);
                out.push(CR);
            }
        }
    }
}

/// A fixed line buffer: no allocation while lines fit.
#[derive(Clone, Debug)]
struct LineBuf {
    bytes: [u8; MAX_LINE],
    len: usize,
    overflow: bool,
}

impl Default for LineBuf {
    fn default() -> Self {
        Self {
            bytes: [0; MAX_LINE],
            len: 0,
            overflow: false,
        }
    }
}

impl LineBuf {
    fn push(&mut self, b: u8) {
        if self.len < MAX_LINE {
            self.bytes[self.len] = b;
            self.len += 1;
        } else {
            self.overflow = true;
        }
    }

    fn line(&self) -> &[u8] {
        &self.bytes[..self.len]
    }

    fn is_empty(&self) -> bool {
        self.len == 0 && !self.overflow
    }

    fn clear(&mut self) {
        self.len = 0;
        self.overflow = false;
    }
}

/// Host side: a streaming decoder of what an adapter sends. Keeps a partial line between
/// pushes; allocates only for version/serial text and garbage.
#[derive(Clone, Debug, Default)]
pub struct Decoder {
    line: LineBuf,
}

impl Decoder {
    /// A decoder at the start of a line.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets a partial line (after reopening the port).
    pub fn clear(&mut self) {
        self.line.clear();
    }

    /// True when part of a line is buffered.
    pub fn is_mid_line(&self) -> bool {
        !self.line.is_empty()
    }

    /// Feeds bytes; calls `out` for each complete item, in order.
    ///
    /// A CR ends a line (an empty one is [`Item::Ok`]); a BEL ends a non-empty line (as the
    /// Linux driver does) and is then [`Item::Error`] itself; line feeds are skipped.
    pub fn push(&mut self, bytes: &[u8], out: &mut impl FnMut(Item)) {
        for &b in bytes {
            match b {
                CR => {
                    out(self.finish());
                }
                BEL => {
                    if !self.line.is_empty() {
                        out(self.finish());
                    }
                    out(Item::Error);
                }
                LF => {}
                _ => self.line.push(b),
            }
        }
    }

    fn finish(&mut self) -> Item {
        let item = if self.line.overflow {
            Item::Garbage(self.line.line().to_vec())
        } else {
            decode_line(self.line.line())
        };
        self.line.clear();
        item
    }
}

fn decode_line(line: &[u8]) -> Item {
    let Some((&first, rest)) = line.split_first() else {
        return Item::Ok;
    };
    let garbage = || Item::Garbage(line.to_vec());
    match first {
        b't' | b'T' | b'r' | b'R' => match parse_frame(line, true) {
            Some((frame, timestamp_ms)) => Item::Frame {
                frame,
                timestamp_ms,
            },
            None => garbage(),
        },
        b'z' | b'Z' if rest.is_empty() => Item::FrameAck,
        b'F' => match (rest.len(), parse_hex(rest)) {
            (2, Some(v)) => Item::Status(v as u8),
            _ => garbage(),
        },
        b'V' | b'v' => Item::Version(escaped(rest)),
        b'N' => Item::Serial(escaped(rest)),
        b's' => decode_state(rest).unwrap_or_else(garbage),
        b'e' => decode_errors(rest).unwrap_or_else(garbage),
        _ => garbage(),
    }
}

/// `sSRRRTTT` (after the `s`): state letter, 3-digit rx and tx error counters.
fn decode_state(rest: &[u8]) -> Option<Item> {
    if rest.len() != 7 {
        return None;
    }
    let state = match rest[0] {
        b'a' => BusState::ErrorActive,
        b'w' => BusState::ErrorWarning,
        b'p' => BusState::ErrorPassive,
        b'b' => BusState::BusOff,
        _ => return None,
    };
    Some(Item::State {
        state,
        rx_errors: parse_dec(&rest[1..4])?,
        tx_errors: parse_dec(&rest[4..7])?,
    })
}

/// `eNcc..` (after the `e`): count digit and that many error codes.
fn decode_errors(rest: &[u8]) -> Option<Item> {
    let (&n, codes) = rest.split_first()?;
    if !(b'0'..=b'8').contains(&n) || codes.len() != usize::from(n - b'0') {
        return None;
    }
    let (mut rx, mut tx, mut overrun) = (false, false, false);
    for &c in codes {
        match c {
            b'a' | b'b' | b'B' => tx = true,
            b'c' | b'f' | b's' => rx = true,
            b'o' => {
                rx = true;
                overrun = true;
            }
            b'O' => {
                tx = true;
                overrun = true;
            }
            _ => return None,
        }
    }
    Some(Item::BusError { rx, tx, overrun })
}

/// Device side (for a simulated adapter): a streaming decoder of host command lines.
/// Lines end at CR or LF; empty lines are skipped.
#[derive(Clone, Debug, Default)]
pub struct CommandDecoder {
    line: LineBuf,
}

impl CommandDecoder {
    /// A decoder at the start of a line.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets a partial line.
    pub fn clear(&mut self) {
        self.line.clear();
    }

    /// Feeds bytes; calls `out` for each complete line: the command, or why it is not one
    /// (the adapter answers those with BEL).
    pub fn push(&mut self, bytes: &[u8], out: &mut impl FnMut(Result<Command, String>)) {
        for &b in bytes {
            match b {
                CR | LF => {
                    if self.line.is_empty() {
                        continue;
                    }
                    let result = if self.line.overflow {
                        Err(format!(
                            "line longer than {MAX_LINE} characters: \"{}...\"",
                            escaped(self.line.line())
                        ))
                    } else {
                        decode_command(self.line.line())
                    };
                    self.line.clear();
                    out(result);
                }
                _ => self.line.push(b),
            }
        }
    }
}

fn decode_command(line: &[u8]) -> Result<Command, String> {
    let bad = |why: &str| Err(format!("\"{}\": {why}", escaped(line)));
    let Some((&first, rest)) = line.split_first() else {
        return bad("empty command");
    };
    let single = |c: Command| {
        if rest.is_empty() {
            Ok(c)
        } else {
            bad("unexpected characters after the command letter")
        }
    };
    match first {
        b'S' => match rest {
            [d @ b'0'..=b'8'] => Ok(Command::Bitrate(d - b'0')),
            _ => bad("bit rate code must be one digit 0..8"),
        },
        b's' => match (rest.len(), parse_hex(rest)) {
            (4, Some(v)) => Ok(Command::Btr((v >> 8) as u8, v as u8)),
            _ => bad("BTR0/BTR1 must be 4 hex digits"),
        },
        b'O' => single(Command::Open),
        b'L' => single(Command::ListenOnly),
        b'C' => single(Command::Close),
        b'F' => single(Command::Status),
        b'V' | b'v' => single(Command::Version),
        b'N' => single(Command::Serial),
        b'Z' => match rest {
            b"0" => Ok(Command::Timestamps(false)),
            b"1" => Ok(Command::Timestamps(true)),
            _ => bad("timestamps must be Z0 or Z1"),
        },
        b'M' | b'm' => match (rest.len(), parse_hex(rest)) {
            (8, Some(v)) if first == b'M' => Ok(Command::AcceptanceCode(v)),
            (8, Some(v)) => Ok(Command::AcceptanceMask(v)),
            _ => bad("acceptance code/mask must be 8 hex digits"),
        },
        b't' | b'T' | b'r' | b'R' => match parse_frame(line, false) {
            Some((frame, _)) => Ok(Command::Transmit(frame)),
            None => bad("not a well-formed frame (id digits, DLC 0..8, 2 hex digits per byte)"),
        },
        _ => bad("unknown command"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn items(bytes: &[u8]) -> Vec<Item> {
        let mut d = Decoder::new();
        let mut v = Vec::new();
        d.push(bytes, &mut |i| v.push(i));
        v
    }

    fn commands(bytes: &[u8]) -> Vec<Result<Command, String>> {
        let mut d = CommandDecoder::new();
        let mut v = Vec::new();
        d.push(bytes, &mut |c| v.push(c));
        v
    }

    fn line(frame: &CanFrame) -> String {
        let mut out = Vec::new();
        encode_frame(frame, &mut out);
        String::from_utf8(out).expect("ascii")
    }

    #[test]
    fn the_slcan_protocol_examples_encode_as_documented() {
        let on = CanFrame::standard(0x100, &[]).expect("valid");
        assert_eq!(line(&on), "t1000\r");
        let period = CanFrame::standard(0x204, &[3, 0, 0, 0, 0, 0]).expect("valid");
        assert_eq!(line(&period), "t2046030000000000\r");
        let info = CanFrame::standard_remote(0x200, 0).expect("valid");
        assert_eq!(line(&info), "r2000\r");
        assert_eq!(
            line(&CanFrame::standard(0x0CA, &[3]).expect("valid")),
            "t0CA103\r"
        );
        let ext = CanFrame::extended(0x12AB_CDEF, &[0xAA, 0x55]).expect("valid");
        assert_eq!(line(&ext), "T12ABCDEF2AA55\r");
        let pos = CanFrame::standard(0x3D3, &[0, 0x80, 0, 0x80, 0, 0x80, 0, 0x80]).expect("ok");
        assert_eq!(line(&pos), "t3D380080008000800080\r");
    }

    #[test]
    fn decodes_acks_frames_and_errors_interleaved() {
        let got = items(b"\rz\rt1230\r\x07Z\rt4563112233\r\n\r");
        let f1 = CanFrame::standard(0x123, &[]).expect("valid");
        let f2 = CanFrame::standard(0x456, &[0x11, 0x22, 0x33]).expect("valid");
        assert_eq!(
            got,
            vec![
                Item::Ok,
                Item::FrameAck,
                Item::Frame {
                    frame: f1,
                    timestamp_ms: None
                },
                Item::Error,
                Item::FrameAck,
                Item::Frame {
                    frame: f2,
                    timestamp_ms: None
                },
                Item::Ok,
            ]
        );
    }

    #[test]
    fn lower_case_hex_and_timestamps() {
        let got = items(b"t3d32abcdEA5F\r");
        let f = CanFrame::standard(0x3D3, &[0xAB, 0xCD]).expect("valid");
        assert_eq!(
            got,
            vec![Item::Frame {
                frame: f,
                timestamp_ms: Some(0xEA5F)
            }]
        );
        let r = items(b"r20001234\r");
        assert!(matches!(
            r[0],
            Item::Frame {
                timestamp_ms: Some(0x1234),
                ..
            }
        ));
    }

    #[test]
    fn split_across_pushes() {
        let mut d = Decoder::new();
        let mut v = Vec::new();
        for chunk in [&b"t12"[..], b"31A", b"B\rF", b"2", b"0\r"] {
            d.push(chunk, &mut |i| v.push(i));
        }
        assert_eq!(
            v,
            vec![
                Item::Frame {
                    frame: CanFrame::standard(0x123, &[0xAB]).expect("ok"),
                    timestamp_ms: None
                },
                Item::Status(0x20),
            ]
        );
        assert!(!d.is_mid_line());
    }

    #[test]
    fn status_version_serial_and_linux_lines() {
        assert_eq!(items(b"F84\r"), vec![Item::Status(0x84)]);
        assert_eq!(items(b"V1013\r"), vec![Item::Version("1013".into())]);
        assert_eq!(items(b"NA123\r"), vec![Item::Serial("A123".into())]);
        assert_eq!(
            items(b"sb256255\r"),
            vec![Item::State {
                state: BusState::BusOff,
                rx_errors: 256,
                tx_errors: 255
            }]
        );
        assert_eq!(
            items(b"e3bcO\r"),
            vec![Item::BusError {
                rx: true,
                tx: true,
                overrun: true
            }]
        );
        assert_eq!(status_bus_state(0xA0), BusState::BusOff);
        assert_eq!(status_bus_state(0x20), BusState::ErrorPassive);
        assert_eq!(status_bus_state(0x04), BusState::ErrorWarning);
        assert_eq!(status_bus_state(0x08), BusState::ErrorActive);
    }

    #[test]
    fn garbage_lines() {
        for bad in [
            &b"t80000\r"[..], // 11-bit id above 0x7FF
            b"t1239\r",       // DLC 9
            b"t12321\r",      // odd data digits
            b"T2000000000\r", // 29-bit id too large
            b"t12G0\r",
            b"F1\r",
            b"x\r",
            b"zz\r",
            b"sq000000\r",
            b"e2a\r",
        ] {
            let got = items(bad);
            assert!(
                matches!(got.as_slice(), [Item::Garbage(_)]),
                "{bad:?}: {got:?}"
            );
        }
        let long = [b'V'; 100];
        let got = items(&[&long[..], b"\r"].concat());
        assert!(matches!(&got[..], [Item::Garbage(g)] if g.len() == MAX_LINE));
        // The decoder recovers on the next line.
        assert_eq!(items(&[&long[..], b"\r\r"].concat())[1], Item::Ok);
    }

    #[test]
    fn bel_ends_a_line() {
        let got = items(b"t1230\x07");
        assert_eq!(got.len(), 2);
        assert_eq!(got[1], Item::Error);
    }

    #[test]
    fn commands_decode() {
        let got = commands(b"C\rS8\r\nF\rO\rt1000\rZ1\rM00000000\rmFFFFFFFF\rs0014\rV\rN\rL\r");
        let ok: Vec<Command> = got.into_iter().map(|c| c.expect("valid")).collect();
        assert_eq!(
            ok,
            vec![
                Command::Close,
                Command::Bitrate(8),
                Command::Status,
                Command::Open,
                Command::Transmit(CanFrame::standard(0x100, &[]).expect("ok")),
                Command::Timestamps(true),
                Command::AcceptanceCode(0),
                Command::AcceptanceMask(0xFFFF_FFFF),
                Command::Btr(0x00, 0x14),
                Command::Version,
                Command::Serial,
                Command::ListenOnly,
            ]
        );
        for bad in [
            &b"S9\r"[..],
            b"Ox\r",
            b"t1000AA\r",
            b"Q\r",
            b"Z2\r",
            b"M12\r",
        ] {
            let got = commands(bad);
            assert!(matches!(got.as_slice(), [Err(_)]), "{bad:?}: {got:?}");
        }
        let e = commands(b"S9\r").remove(0).expect_err("bad");
        assert!(e.contains("S9"), "{e}");
    }

    #[test]
    fn command_display_names_the_line() {
        assert_eq!(Command::Bitrate(8).to_string(), "S8");
        assert_eq!(Command::Open.to_string(), "O");
        assert_eq!(
            Command::Transmit(CanFrame::standard(0x100, &[]).expect("ok")).to_string(),
            "t1000"
        );
    }

    fn any_frame() -> impl Strategy<Value = CanFrame> {
        (
            0u32..=0x1FFF_FFFF,
            any::<bool>(),
            any::<bool>(),
            proptest::collection::vec(any::<u8>(), 0..=8),
        )
            .prop_map(|(id, ext, remote, data)| {
                match (ext, remote) {
                    (false, false) => CanFrame::standard((id & 0x7FF) as u16, &data),
                    (false, true) => {
                        CanFrame::standard_remote((id & 0x7FF) as u16, data.len() as u8)
                    }
                    (true, false) => CanFrame::extended(id, &data),
                    (true, true) => CanFrame::extended_remote(id, data.len() as u8),
                }
                .expect("valid")
            })
    }

    fn any_command() -> impl Strategy<Value = Command> {
        prop_oneof![
            (0u8..=8).prop_map(Command::Bitrate),
            (any::<u8>(), any::<u8>()).prop_map(|(a, b)| Command::Btr(a, b)),
            Just(Command::Open),
            Just(Command::ListenOnly),
            Just(Command::Close),
            any_frame().prop_map(Command::Transmit),
            Just(Command::Status),
            Just(Command::Version),
            Just(Command::Serial),
            any::<bool>().prop_map(Command::Timestamps),
            any::<u32>().prop_map(Command::AcceptanceCode),
            any::<u32>().prop_map(Command::AcceptanceMask),
        ]
    }

    proptest! {
        #[test]
        fn decoders_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let mut n = 0usize;
            Decoder::new().push(&bytes, &mut |_| n += 1);
            CommandDecoder::new().push(&bytes, &mut |_| n += 1);
            prop_assert!(n <= 2 * bytes.len());
        }

        #[test]
        fn decoders_never_panic_on_slcan_like_bytes(
            bytes in proptest::collection::vec(
                prop_oneof![Just(b'\r'), Just(0x07u8), Just(b't'), Just(b'T'), Just(b'r'),
                            Just(b'F'), Just(b's'), Just(b'e'), Just(b'z'), Just(b'8'),
                            (b'0'..=b'9'), (b'A'..=b'F'), (b'a'..=b'f')],
                0..256)
        ) {
            Decoder::new().push(&bytes, &mut |_| {});
            CommandDecoder::new().push(&bytes, &mut |_| {});
        }

        #[test]
        fn frame_round_trip(frame in any_frame(), stamp in proptest::option::of(0u16..60_000)) {
            let mut out = Vec::new();
            match stamp {
                Some(t) => encode_frame_timestamped(&frame, t, &mut out),
                None => encode_frame(&frame, &mut out),
            }
            prop_assert_eq!(items(&out), vec![Item::Frame { frame, timestamp_ms: stamp }]);
        }

        #[test]
        fn command_round_trip(cmd in any_command()) {
            let mut out = Vec::new();
            cmd.encode(&mut out);
            prop_assert_eq!(commands(&out), vec![Ok(cmd)]);
        }

        #[test]
        fn frames_survive_interleaved_acks(frames in proptest::collection::vec(any_frame(), 0..16),
                                           acks in proptest::collection::vec(0u8..4, 16)) {
            let mut out = Vec::new();
            for (f, a) in frames.iter().zip(&acks) {
                match a {
                    0 => out.push(b'\r'),
                    1 => out.extend_from_slice(b"z\r"),
                    2 => out.push(0x07),
                    _ => {}
                }
                encode_frame(f, &mut out);
            }
            let got: Vec<CanFrame> = items(&out).into_iter().filter_map(|i| match i {
                Item::Frame { frame, .. } => Some(frame),
                _ => None,
            }).collect();
            prop_assert_eq!(got, frames);
        }
    }
}
