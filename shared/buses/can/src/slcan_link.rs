//! [`SlcanLink`]: an slcan adapter (CANable, CANtact, USBtin, CAN232/CANUSB) on a serial port.
//!
//! Opening follows the Linux slcan driver (docs/devices/allegro.md): an empty line to end whatever
//! the adapter half-received, `C` (close; a refusal is fine, it may be closed already), `Sn`
//! (bit rate), `F` (status; adapters without it just lose bus-state reports), `O` (open). Each
//! setup command waits for its answer; a BEL is an [`LinkError::Adapter`] naming the command.
//!
//! Once open, frames are written without waiting for acks: an adapter answers a transmitted
//! frame with a bare CR (CANable), with `z`/`Z` (CAN232, CANUSB), or not at all, and acks come
//! mixed with received frames. So acks are skipped wherever they come, a BEL counts as an
//! error, and nothing assumes one ack per frame. When the adapter answered `F` at open, `F` is
//! asked again every [`SlcanLink::STATUS_INTERVAL`] while receiving: its flags give the bus state
//! (bus error -> bus-off, error passive, error warning) and overruns; Linux-driver-style `s`
//! state lines are taken too. Entering bus-off is returned once from [`CanLink::recv`] as
//! [`LinkError::BusOff`]; reopen to restart the controller.
//!
//! Timestamps: `Z1` is asked before `O` (Lawicel: only while closed); an adapter that takes it
//! stamps each received frame with its own millisecond clock when the frame was on the bus,
//! which [`CanLink::rx_stamp_ms`] gives back: frames a loaded host reads late keep the time
//! they were sent. An adapter that refuses or ignores `Z1` just gives none.
//!
//! Receiving waits in the serial port's `poll` with the caller's timeout (no busy polling);
//! sending encodes into a reused buffer (no allocation per frame).

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

use crate::slcan::{self, Command, Item};
use crate::{Bitrate, BusState, CanFrame, CanLink, LinkCounters, LinkError};

const COMMAND_TIMEOUT: Duration = SlcanLink::COMMAND_TIMEOUT;
const STATUS_INTERVAL: Duration = SlcanLink::STATUS_INTERVAL;
/// How long a write may block (the adapter not taking bytes).
const WRITE_TIMEOUT: Duration = Duration::from_millis(200);
/// Quiet time that ends the drain at open.
const DRAIN_QUIET: Duration = Duration::from_millis(20);
/// Received frames kept between calls (one read can bring many); more are dropped as
/// overruns.
const QUEUE: usize = 1024;

/// An open slcan adapter.
pub struct SlcanLink {
    port: TTYPort,
    path: PathBuf,
    decoder: slcan::Decoder,
    rx: RxState,
    out: Vec<u8>,
    buf: [u8; 512],
    status_supported: bool,
    status_interval: Option<Duration>,
    next_status: Instant,
    /// The adapter's timestamp of the frame `recv` returned last.
    last_stamp: Option<u16>,
}

/// What the decoder's items change (split from the port so the decoder callback can borrow it).
struct RxState {
    frames: VecDeque<(CanFrame, Option<u16>)>,
    counters: LinkCounters,
    state: BusState,
    bus_off_reported: bool,
    what: String,
}

impl RxState {
    /// Takes one item received while the link is in use.
    fn take(&mut self, item: Item) {
        match item {
            Item::Frame {
                frame,
                timestamp_ms,
            } => {
                if self.frames.len() >= QUEUE {
                    self.frames.pop_front();
                    self.counters.overruns += 1;
                }
                self.frames.push_back((frame, timestamp_ms));
                self.counters.rx += 1;
            }
            Item::Ok | Item::FrameAck | Item::Version(_) | Item::Serial(_) => {}
            Item::Error => {
                self.counters.errors += 1;
                tracing::debug!(link = %self.what, "the adapter refused a command or frame (BEL)");
            }
            Item::Status(flags) => {
                if flags & (slcan::status::RX_FIFO_FULL | slcan::status::DATA_OVERRUN) != 0 {
                    self.counters.overruns += 1;
                }
                self.set_state(slcan::status_bus_state(flags));
            }
            Item::State { state, .. } => self.set_state(state),
            Item::BusError { overrun, .. } => {
                self.counters.errors += 1;
                if overrun {
                    self.counters.overruns += 1;
                }
            }
            Item::Garbage(line) => {
                self.counters.errors += 1;
                tracing::debug!(
                    link = %self.what,
                    "unparsable line from the adapter: \"{}\"",
                    line.escape_ascii()
                );
            }
        }
    }

    fn set_state(&mut self, state: BusState) {
        if state != self.state {
            tracing::debug!(link = %self.what, "bus state {} -> {}", self.state, state);
        }
        if state != BusState::BusOff {
            self.bus_off_reported = false;
        }
        self.state = state;
    }
}

/// What answered a setup command.
enum Answer {
    Ok,
    Refused,
    Status(u8),
    None,
}

impl SlcanLink {
    /// How long a setup command may take to be answered.
    pub const COMMAND_TIMEOUT: Duration = Duration::from_millis(500);
    /// How often the status flags are asked for while the link is in use (when the adapter
    /// answers `F`).
    pub const STATUS_INTERVAL: Duration = Duration::from_millis(100);

    /// Opens the adapter at `path` (`serial_baud` for a UART; USB-CDC adapters ignore it),
    /// sets `bitrate` and opens the CAN channel.
    ///
    /// Errors: [`LinkError::NotFound`] when there is no such device,
    /// [`LinkError::Unsupported`] for a bit rate without an slcan code,
    /// [`LinkError::Adapter`] when the adapter refuses or does not answer a setup command
    /// (naming it), [`LinkError::Io`] otherwise.
    pub fn open(path: &Path, serial_baud: u32, bitrate: Bitrate) -> Result<Self, LinkError> {
        let what = format!("slcan:{}", path.display());
        let Some(code) = bitrate.slcan_code() else {
            return Err(LinkError::Unsupported {
                what,
                detail: format!(
                    "bit rate {} bit/s has no slcan S code (10k 20k 50k 100k 125k 250k 500k \
                     750k/800k 1M)",
                    bitrate.0
                ),
            });
        };
        let port = serialport::new(path.to_string_lossy(), serial_baud)
            .data_bits(serialport::DataBits::Eight)
            .parity(serialport::Parity::None)
            .stop_bits(serialport::StopBits::One)
            .flow_control(serialport::FlowControl::None)
            .timeout(COMMAND_TIMEOUT)
            .open_native()
            .map_err(|e| open_error(&what, path, e))?;
        let _ = port.clear(serialport::ClearBuffer::All);
        let mut link = Self {
            port,
            path: path.to_path_buf(),
            decoder: slcan::Decoder::new(),
            rx: RxState {
                frames: VecDeque::with_capacity(QUEUE),
                counters: LinkCounters::default(),
                state: BusState::ErrorActive,
                bus_off_reported: false,
                what,
            },
            out: Vec::with_capacity(64),
            buf: [0; 512],
            status_supported: false,
            status_interval: Some(STATUS_INTERVAL),
            next_status: Instant::now(),
            last_stamp: None,
        };
        link.start(code)?;
        Ok(link)
    }

    /// The setup sequence: empty line, C, Sn, F, O.
    fn start(&mut self, code: u8) -> Result<(), LinkError> {
        self.write_raw(b"\r")?;
        self.drain_until_quiet()?;
        // Closed already is fine: some adapters refuse C then, some do not answer.
        let _ = self.command(Command::Close, COMMAND_TIMEOUT / 2)?;
        match self.command(Command::Bitrate(code), COMMAND_TIMEOUT)? {
            Answer::Ok | Answer::Status(_) => {}
            Answer::Refused => return Err(self.refused(Command::Bitrate(code))),
            Answer::None => return Err(self.no_answer(Command::Bitrate(code))),
        }
        match self.command(Command::Status, COMMAND_TIMEOUT / 4)? {
            Answer::Status(flags) => {
                self.status_supported = true;
                self.rx.set_state(slcan::status_bus_state(flags));
            }
            _ => tracing::debug!(link = %self.rx.what, "no answer to F: no bus-state reports"),
        }
        // Timestamps, while closed; refused or unanswered: frames come without them.
        let _ = self.command(Command::Timestamps(true), COMMAND_TIMEOUT / 4)?;
        match self.command(Command::Open, COMMAND_TIMEOUT)? {
            Answer::Ok | Answer::Status(_) => {}
            Answer::Refused => return Err(self.refused(Command::Open)),
            Answer::None => return Err(self.no_answer(Command::Open)),
        }
        self.next_status = Instant::now() + STATUS_INTERVAL;
        tracing::debug!(link = %self.rx.what, "open (status flags {})",
            if self.status_supported { "supported" } else { "not supported" });
        Ok(())
    }

    /// Sends a setup command and waits up to `timeout` for its answer: OK (CR), refusal
    /// (BEL) or a status reply. Frames meanwhile are queued, `z`/`Z` skipped.
    fn command(&mut self, cmd: Command, timeout: Duration) -> Result<Answer, LinkError> {
        self.out.clear();
        cmd.encode(&mut self.out);
        let line = std::mem::take(&mut self.out);
        let written = self.write_raw(&line);
        self.out = line;
        written?;
        let deadline = Instant::now() + timeout;
        let mut answer = None;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(Answer::None);
            }
            let n = self.read(left)?;
            let mut start = 0;
            while start < n && answer.is_none() {
                // Feed byte by byte until the answer, so that what follows it is decoded
                // as ordinary traffic.
                let byte = [self.buf[start]];
                start += 1;
                let rx = &mut self.rx;
                self.decoder.push(&byte, &mut |item| match item {
                    Item::Ok if answer.is_none() => answer = Some(Answer::Ok),
                    Item::Error if answer.is_none() => answer = Some(Answer::Refused),
                    Item::Status(f) if answer.is_none() && cmd == Command::Status => {
                        answer = Some(Answer::Status(f))
                    }
                    other => rx.take(other),
                });
            }
            if start < n {
                let rx = &mut self.rx;
                self.decoder
                    .push(&self.buf[start..n], &mut |item| rx.take(item));
            }
            if let Some(a) = answer {
                return Ok(a);
            }
        }
    }

    /// Reads and discards until the line has been quiet for [`DRAIN_QUIET`] (at most
    /// [`Self::COMMAND_TIMEOUT`]).
    fn drain_until_quiet(&mut self) -> Result<(), LinkError> {
        let limit = Instant::now() + COMMAND_TIMEOUT;
        while Instant::now() < limit {
            if self.read(DRAIN_QUIET)? == 0 {
                break;
            }
        }
        self.decoder.clear();
        Ok(())
    }

    fn refused(&self, cmd: Command) -> LinkError {
        LinkError::Adapter {
            what: self.rx.what.clone(),
            detail: format!("the adapter refused `{cmd}` ({}) with BEL", cmd.meaning()),
        }
    }

    fn no_answer(&self, cmd: Command) -> LinkError {
        LinkError::Adapter {
            what: self.rx.what.clone(),
            detail: format!(
                "no answer to `{cmd}` ({}) within {COMMAND_TIMEOUT:?}: is this an slcan \
                 adapter, at the right serial baud?",
                cmd.meaning()
            ),
        }
    }

    /// The serial device path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// True when the adapter answered `F` at open (so bus state is reported).
    pub fn status_supported(&self) -> bool {
        self.status_supported
    }

    /// How often to ask for status flags while in use (`None`: never). Default
    /// [`Self::STATUS_INTERVAL`]; has no effect when the adapter does not answer `F`.
    pub fn set_status_interval(&mut self, interval: Option<Duration>) {
        self.status_interval = interval;
    }

    /// One read into `self.buf`, waiting up to `wait` (zero: only what is there); 0 when
    /// nothing came.
    fn read(&mut self, wait: Duration) -> Result<usize, LinkError> {
        let _ = self.port.set_timeout(wait);
        match self.port.read(&mut self.buf) {
            Ok(0) => Err(self.disconnected("end of file")),
            Ok(n) => Ok(n),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                Ok(0)
            }
            Err(e) => Err(self.disconnected(&format!("read failed: {e}"))),
        }
    }

    fn write_raw(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let _ = self.port.set_timeout(WRITE_TIMEOUT);
        match self.port.write_all(bytes) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Err(LinkError::Io {
                what: self.rx.what.clone(),
                source: std::io::Error::new(
                    e.kind(),
                    format!("the adapter took no bytes for {WRITE_TIMEOUT:?}"),
                ),
            }),
            Err(e) => Err(self.disconnected(&format!("write failed: {e}"))),
        }
    }

    fn disconnected(&self, detail: &str) -> LinkError {
        LinkError::Disconnected {
            what: self.rx.what.clone(),
            detail: format!("{detail}; was the adapter unplugged? reopen to recover"),
        }
    }

    /// Asks for the status flags when due.
    fn poll_status(&mut self) -> Result<(), LinkError> {
        let Some(interval) = self.status_interval.filter(|_| self.status_supported) else {
            return Ok(());
        };
        let now = Instant::now();
        if now < self.next_status {
            return Ok(());
        }
        self.next_status = now + interval;
        self.write_raw(b"F\r")
    }
}

impl CanLink for SlcanLink {
    fn send(&mut self, frame: &CanFrame) -> Result<(), LinkError> {
        self.out.clear();
        slcan::encode_frame(frame, &mut self.out);
        let line = std::mem::take(&mut self.out);
        let written = self.write_raw(&line);
        self.out = line;
        written?;
        self.rx.counters.tx += 1;
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, LinkError> {
        let deadline = Instant::now() + timeout;
        let mut first = true;
        loop {
            if let Some((frame, stamp)) = self.rx.frames.pop_front() {
                self.last_stamp = stamp;
                return Ok(Some(frame));
            }
            if self.rx.state == BusState::BusOff && !self.rx.bus_off_reported {
                self.rx.bus_off_reported = true;
                return Err(LinkError::BusOff {
                    what: self.rx.what.clone(),
                });
            }
            self.poll_status()?;
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() && !first {
                return Ok(None);
            }
            first = false;
            let n = self.read(left)?;
            let rx = &mut self.rx;
            self.decoder.push(&self.buf[..n], &mut |item| rx.take(item));
        }
    }

    fn bus_state(&self) -> BusState {
        self.rx.state
    }

    fn counters(&self) -> LinkCounters {
        self.rx.counters
    }

    fn describe(&self) -> &str {
        &self.rx.what
    }

    fn rx_stamp_ms(&self) -> Option<u16> {
        self.last_stamp
    }
}

impl Drop for SlcanLink {
    /// Closes the CAN channel (best effort) so the adapter stops sending.
    fn drop(&mut self) {
        let _ = self.port.set_timeout(Duration::from_millis(20));
        let _ = self.port.write_all(b"C\r");
    }
}

fn open_error(what: &str, path: &Path, e: serialport::Error) -> LinkError {
    if !path.exists() {
        return LinkError::NotFound {
            what: what.to_string(),
            detail: "no such device; is the adapter plugged in (or the simulator running)?".into(),
        };
    }
    let kind = match e.kind() {
        serialport::ErrorKind::Io(kind) => kind,
        // serialport reports EBUSY (another process holds the port exclusively) as NoDevice.
        serialport::ErrorKind::NoDevice => std::io::ErrorKind::ResourceBusy,
        _ => std::io::ErrorKind::Other,
    };
    let hint = match kind {
        std::io::ErrorKind::PermissionDenied => {
            "; add the user to the group owning the device (dialout or uucp)"
        }
        std::io::ErrorKind::ResourceBusy => "; is another program using the adapter?",
        _ => "",
    };
    LinkError::Io {
        what: what.to_string(),
        source: std::io::Error::new(kind, format!("cannot open: {e}{hint}")),
    }
}
