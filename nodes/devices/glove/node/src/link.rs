//! The serial link to one glove: request/answer exchanges over `serialport` with timeouts,
//! resynchronisation and counters. Used by the glove node and by `teleop glove`.
//!
//! The protocol's answers carry no request number: the force-control answer to one request
//! looks like the answer to the next. So after a timeout the link resynchronises before the
//! next request: it reads and discards until the line is quiet, so that an answer arriving
//! after its exchange gave up is never taken for the answer to the next request (see
//! [`GloveLink::exchange`]).

use std::io::{Read, Write};
use std::os::fd::AsRawFd;
use std::path::Path;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};
use teleop_glove_protocol::{
    decode_values, encode_request, read_request, wire_time, write_request, DecodeError, Register,
    Request, Response, ResponseDecoder, Values, MAX_FRAME,
};
use teleop_runtime::serial_latency;

/// Why an exchange failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The port could not be opened or configured.
    #[error("{port}: cannot open: {detail}")]
    Open {
        /// The port path.
        port: String,
        /// What the OS said.
        detail: String,
    },
    /// Reading or writing the port failed: it is gone or broken; reopen it.
    #[error("{port}: I/O error: {source}")]
    Io {
        /// The port path.
        port: String,
        /// The error.
        source: std::io::Error,
    },
    /// No matching answer within the timeout.
    #[error("no answer within {0:?}")]
    Timeout(Duration),
    /// The request could not be encoded (a value out of range).
    #[error("invalid request: {0}")]
    Encode(#[from] teleop_glove_protocol::EncodeError),
    /// The device refused a register write.
    #[error("the glove refused the write to {0}")]
    Refused(&'static str),
    /// An answer of another kind than asked for.
    #[error("the glove answered with {0:?}")]
    Mismatch(teleop_glove_protocol::Command),
    /// The answer's register bytes do not fit the register.
    #[error("bad register answer: {0}")]
    Register(#[from] teleop_glove_protocol::RegisterError),
}

/// Counters of what went wrong on the line (never reset while the link object lives).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Completed exchanges.
    pub exchanges: u64,
    /// Exchanges without an answer in time.
    pub timeouts: u64,
    /// Frames with a bad checksum or an impossible length.
    pub bad_frames: u64,
    /// Runs of bytes that were not part of any frame.
    pub garbage: u64,
    /// Well-formed frames from another device id.
    pub other_id: u64,
    /// Answers that did not match the request (of another kind or register).
    pub unexpected: u64,
    /// Answers that arrived after their exchange had timed out, discarded while resynchronising.
    pub late: u64,
}

impl LinkStats {
    /// All problems together.
    pub fn errors(&self) -> u64 {
        self.timeouts + self.bad_frames + self.garbage + self.other_id + self.unexpected + self.late
    }
}

/// Character times without a byte after which the line counts as quiet again once bytes came
/// in after a timeout. (A USB-serial adapter passes bytes on in bursts every latency-timer
/// period; at 1 ms, see [`serial_latency`], a burst gap is shorter than this at 115200 baud.
/// Should a slower adapter split a late answer anyway, its tail has no header and cannot be
/// taken for an answer.)
const QUIET_CHARS: usize = 12;

/// An open serial link to the glove with device id `id`.
pub struct GloveLink {
    port: TTYPort,
    path: String,
    id: u8,
    baud: u32,
    timeout: Duration,
    low_latency: bool,
    decoder: ResponseDecoder,
    stats: LinkStats,
}

impl GloveLink {
    /// Opens `path` (USB serial, Bluetooth SPP such as /dev/rfcomm0, or a pseudo-terminal) at
    /// `baud`, 8N1, exclusively, and asks the driver for low latency: `ASYNC_LOW_LATENCY` (a
    /// refusal, as from a pseudo-terminal, is only a debug note), and a warning, once per
    /// adapter, naming the fix when a USB-serial adapter's latency timer is above 1 ms.
    pub fn open(path: &str, baud: u32, id: u8, timeout: Duration) -> Result<Self, LinkError> {
        let port = serialport::new(path, baud)
            .data_bits(serialport::DataBits::Eight)
            .parity(serialport::Parity::None)
            .stop_bits(serialport::StopBits::One)
            .flow_control(serialport::FlowControl::None)
            .timeout(timeout)
            .open_native()
            .map_err(|e| LinkError::Open {
                port: path.to_string(),
                detail: e.to_string(),
            })?;
        let _ = port.clear(serialport::ClearBuffer::All);
        let low_latency = serial_latency::tune(port.as_raw_fd(), Path::new(path));
        Ok(Self {
            port,
            path: path.to_string(),
            id,
            baud,
            timeout,
            low_latency,
            decoder: ResponseDecoder::new(Some(id)),
            stats: LinkStats::default(),
        })
    }

    /// The port path.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The device id requests go to.
    pub fn id(&self) -> u8 {
        self.id
    }

    /// Talks to another device id from now on.
    pub fn set_id(&mut self, id: u8) {
        self.id = id;
        self.decoder.set_expected_id(Some(id));
    }

    /// Changes the port's line speed (after the glove changed its own).
    pub fn set_baud(&mut self, baud: u32) -> Result<(), LinkError> {
        self.port.set_baud_rate(baud).map_err(|e| LinkError::Open {
            port: self.path.clone(),
            detail: e.to_string(),
        })?;
        self.baud = baud;
        Ok(())
    }

    /// Whether the driver accepted low-latency mode (`ASYNC_LOW_LATENCY`) for the port.
    pub fn low_latency(&self) -> bool {
        self.low_latency
    }

    /// Counters so far.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// Sends `request` and waits for its answer. Returns the answer and the CLOCK_MONOTONIC
    /// time its last byte was read. Frames that do not answer this request are counted and
    /// skipped. A timeout is counted, the line resynchronised (see [`Self::resync`]), and the
    /// timeout returned.
    pub fn exchange(&mut self, request: &Request) -> Result<(Response, u64), LinkError> {
        let mut frame = [0u8; MAX_FRAME];
        let n = encode_request(self.id, request, &mut frame)?;
        // Whatever is still buffered belongs to an earlier exchange.
        self.drain_stale();
        self.port.write_all(&frame[..n]).map_err(|e| self.io(e))?;
        let deadline = Instant::now() + self.timeout;
        let mut buf = [0u8; 256];
        let (mut start, mut end) = (0, 0);
        loop {
            let fed = if start < end {
                let t = self.decoder.push(&buf[start..end]);
                start += t;
                t
            } else {
                0
            };
            let mut decoded = false;
            while let Some(item) = self.decoder.next() {
                decoded = true;
                match item {
                    Ok(f) if answers(request, &f.body) => {
                        self.stats.exchanges += 1;
                        return Ok((f.body, teleop_runtime::now_ns()));
                    }
                    Ok(_) => self.stats.unexpected += 1,
                    Err(e) => self.count(e),
                }
            }
            if start < end {
                if fed == 0 && !decoded {
                    // Cannot happen with a total decoder; never spin on it.
                    self.decoder.clear();
                }
                continue;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                self.stats.timeouts += 1;
                self.resync()?;
                return Err(LinkError::Timeout(self.timeout));
            }
            end = self.read(&mut buf, left)?;
            start = 0;
        }
    }

    /// After a timeout: reads and discards until the line is quiet, so that the answer to the
    /// request that timed out cannot be taken for the answer to the next one.
    ///
    /// Quiet means no byte for [`QUIET_CHARS`] character times at the current baud rate after
    /// the last byte, or no byte at all for one more answer timeout: a late answer usually has
    /// not begun when the exchange gives up, and one that does not begin within twice the
    /// answer timeout cannot be told from a lost one. (So a lost answer costs two answer
    /// timeouts.) Whole frames read meanwhile are counted as [`LinkStats::late`], other bytes
    /// as line errors. Bounded: a line still busy after two answer timeouts is flushed with a
    /// warning.
    fn resync(&mut self) -> Result<(), LinkError> {
        self.decoder.clear();
        let begin = Instant::now();
        let limit = begin + 2 * self.timeout;
        let quiet = wire_time(QUIET_CHARS, self.baud);
        let mut quiet_at = begin + self.timeout;
        let (mut bytes, late_before) = (0usize, self.stats.late);
        let mut buf = [0u8; 256];
        let settled = loop {
            let now = Instant::now();
            if now >= quiet_at {
                break true;
            }
            if now >= limit {
                break false;
            }
            let n = self.read(&mut buf, quiet_at.min(limit) - now)?;
            if n == 0 {
                continue;
            }
            quiet_at = Instant::now() + quiet;
            bytes += n;
            let mut taken = 0;
            while taken < n {
                taken += self.decoder.push(&buf[taken..n]);
                while let Some(item) = self.decoder.next() {
                    match item {
                        Ok(_) => self.stats.late += 1,
                        Err(e) => self.count(e),
                    }
                }
            }
        };
        self.decoder.clear();
        let late = self.stats.late - late_before;
        if !settled {
            let _ = self.port.clear(serialport::ClearBuffer::Input);
            tracing::warn!(
                port = %self.path,
                bytes,
                late,
                "the line did not go quiet within {:?} after a timeout; input flushed",
                2 * self.timeout
            );
        } else if bytes > 0 {
            tracing::debug!(
                port = %self.path,
                bytes,
                late,
                "resynchronised after a timeout: discarded what arrived late"
            );
        }
        Ok(())
    }

    /// One read of at most `buf.len()` bytes, waiting up to `wait`; 0 when nothing came.
    fn read(&mut self, buf: &mut [u8], wait: Duration) -> Result<usize, LinkError> {
        let _ = self.port.set_timeout(wait);
        match self.port.read(buf) {
            Ok(0) => Err(self.io(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                "port closed",
            ))),
            Ok(n) => Ok(n),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted
                ) =>
            {
                Ok(0)
            }
            Err(e) => Err(self.io(e)),
        }
    }

    /// Reads a register group and decodes its values.
    pub fn read_register(&mut self, register: &Register) -> Result<Values, LinkError> {
        match self.exchange(&read_request(register))?.0 {
            Response::ReadRegister { data, .. } => Ok(decode_values(register, data.as_slice())?),
            other => Err(LinkError::Mismatch(other.command())),
        }
    }

    /// Writes a register group; a refusal is an error.
    pub fn write_register(&mut self, register: &Register, values: &[i32]) -> Result<(), LinkError> {
        match self.exchange(&write_request(register, values)?)?.0 {
            Response::WriteRegister { status, .. }
                if status == teleop_glove_protocol::WRITE_ACCEPTED =>
            {
                Ok(())
            }
            _ => Err(LinkError::Refused(register.name)),
        }
    }

    fn drain_stale(&mut self) {
        if self.port.bytes_to_read().unwrap_or(0) > 0 {
            let _ = self.port.clear(serialport::ClearBuffer::Input);
        }
        self.decoder.clear();
    }

    fn count(&mut self, e: DecodeError) {
        match e {
            DecodeError::Garbage { .. } => self.stats.garbage += 1,
            DecodeError::OtherId { .. } => self.stats.other_id += 1,
            DecodeError::BadChecksum { .. }
            | DecodeError::BadLength { .. }
            | DecodeError::UnknownCommand { .. } => self.stats.bad_frames += 1,
        }
        tracing::debug!(port = %self.path, "line error: {e}");
    }

    fn io(&self, source: std::io::Error) -> LinkError {
        LinkError::Io {
            port: self.path.clone(),
            source,
        }
    }
}

/// True when `answer` is the answer to `request` (same command, same register address).
fn answers(request: &Request, answer: &Response) -> bool {
    match (request, answer) {
        (Request::ForceControl { .. }, Response::ForceControl { .. })
        | (Request::PositionControl { .. }, Response::PositionControl { .. }) => true,
        (Request::ReadRegister { address, len }, Response::ReadRegister { address: a, data }) => {
            address == a && usize::from(*len) == data.len()
        }
        (Request::WriteRegister { address, .. }, Response::WriteRegister { address: a, .. }) => {
            address == a
        }
        _ => false,
    }
}
