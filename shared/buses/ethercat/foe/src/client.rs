//! The FoE write client: sends a file to a SubDevice through any [`MailboxPort`], with reply
//! timeouts, repeats, BUSY handling and the server's error packets.

use std::time::{Duration, Instant};

use crate::mailbox::{self, mailbox_type, MailboxError, MailboxHeader};
use crate::packet::{self, ErrorCode, Packet};

/// Raw access to one SubDevice's mailboxes (the SM0 it receives on, the SM1 it answers on).
///
/// The port moves whole mailbox messages (header included); the client builds and reads them.
/// An implementation over ethercrab lives with the node that owns the bus; tests use an
/// emulated SubDevice.
pub trait MailboxPort {
    /// Size of the SubDevice's receive mailbox (the SM0 length): the longest message
    /// [`send`](Self::send) takes, header included.
    fn request_size(&self) -> usize;

    /// Places one mailbox message in the SubDevice's receive mailbox (padded to its size).
    fn send(&mut self, message: &[u8]) -> Result<(), PortError>;

    /// Waits up to `timeout` for the SubDevice's send mailbox to fill and takes its content
    /// (the whole buffer: header, data and padding). `Ok(None)`: nothing came in time.
    /// `Duration::ZERO` looks once.
    fn receive(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, PortError>;
}

impl<P: MailboxPort + ?Sized> MailboxPort for &mut P {
    fn request_size(&self) -> usize {
        (**self).request_size()
    }
    fn send(&mut self, message: &[u8]) -> Result<(), PortError> {
        (**self).send(message)
    }
    fn receive(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, PortError> {
        (**self).receive(timeout)
    }
}

/// Why a mailbox access failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PortError {
    /// The receive mailbox is still full: the SubDevice has not taken the previous message yet.
    #[error("the device's receive mailbox is still full")]
    Full,
    /// The access did not complete (frame lost, working counter wrong, link down...).
    #[error("{0}")]
    Link(String),
}

/// Timeouts and repeats of the client.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClientConfig {
    /// How long to wait for the answer to one packet before sending it again.
    pub reply_timeout: Duration,
    /// How often a packet is sent again (after no answer or a failed access) before giving up.
    pub retries: u32,
    /// Wait before repeating a packet that the server answered with BUSY.
    pub busy_delay: Duration,
    /// Give up when the server has answered BUSY for this long in a row.
    pub busy_timeout: Duration,
    /// Password of the request (0: none).
    pub password: u32,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            reply_timeout: Duration::from_millis(1000),
            retries: 3,
            busy_delay: Duration::from_millis(20),
            busy_timeout: Duration::from_secs(60),
            password: 0,
        }
    }
}

/// What a BUSY packet said.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Busy {
    /// Progress so far.
    pub done: u16,
    /// Progress at the end.
    pub entire: u16,
    /// The server's text (may be empty).
    pub text: String,
}

/// Progress of a write, reported after each acknowledge and each BUSY.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Progress {
    /// File bytes the server has acknowledged.
    pub acknowledged: u64,
    /// File size.
    pub total: u64,
    /// The server's last BUSY, while it is busy with the packet in flight.
    pub busy: Option<Busy>,
}

/// How a finished write went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Summary {
    /// DATA packets acknowledged.
    pub packets: u32,
    /// File bytes written.
    pub bytes: u64,
    /// Packets sent again after no answer or a failed access.
    pub repeats: u32,
    /// BUSY answers.
    pub busy: u32,
    /// Duration of the whole write.
    pub elapsed: Duration,
}

/// Why a write failed. `packet` is the packet in flight: 0 is the write request, 1.. the data.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FoeError {
    /// The receive mailbox cannot carry an FoE packet.
    #[error("the device's receive mailbox ({size} bytes) is too small for FoE")]
    MailboxTooSmall {
        /// Its size.
        size: usize,
    },
    /// The file name does not fit one write request.
    #[error("the file name ({len} bytes) does not fit the device's {size}-byte mailbox")]
    NameTooLong {
        /// Name length.
        len: usize,
        /// Mailbox size.
        size: usize,
    },
    /// The server answered with an FoE error packet.
    #[error("the device refused {}: FoE error {code}{}", packet_name(*.packet), text_suffix(.text))]
    Refused {
        /// Packet in flight.
        packet: u32,
        /// The error code.
        code: ErrorCode,
        /// The error text (may be empty).
        text: String,
    },
    /// No answer, even after the repeats: the mailbox could be accessed (at least once) but the
    /// device did not answer.
    #[error(
        "no answer from the device to {} after {attempts} attempts ({waited:.1?}): it stopped answering",
        packet_name(*.packet)
    )]
    NoAnswer {
        /// Packet in flight.
        packet: u32,
        /// Times it was sent.
        attempts: u32,
        /// Time since it was first sent.
        waited: Duration,
    },
    /// The mailbox could not be accessed, even after the repeats.
    #[error(
        "the device's mailbox could not be accessed at {} after {attempts} attempts ({message}): it left the bus or the link is down",
        packet_name(*.packet)
    )]
    Link {
        /// Packet in flight.
        packet: u32,
        /// Attempts made.
        attempts: u32,
        /// The last failure.
        message: String,
    },
    /// The server stayed busy too long.
    #[error("the device stayed busy for {busy_for:.1?} at {}: gave up", packet_name(*.packet))]
    BusyTimeout {
        /// Packet in flight.
        packet: u32,
        /// How long it was busy.
        busy_for: Duration,
    },
    /// The server answered with a mailbox error (e.g. FoE not supported in this state).
    #[error("the device answered {} with mailbox error {error}", packet_name(*.packet))]
    Mailbox {
        /// Packet in flight.
        packet: u32,
        /// The error detail.
        error: MailboxError,
    },
    /// An answer that makes no sense here.
    #[error("unexpected answer to {}: {what}", packet_name(*.packet))]
    Protocol {
        /// Packet in flight.
        packet: u32,
        /// What came.
        what: String,
    },
}

impl FoeError {
    /// The server's FoE error code, for [`FoeError::Refused`].
    pub fn code(&self) -> Option<ErrorCode> {
        match self {
            Self::Refused { code, .. } => Some(*code),
            _ => None,
        }
    }

    /// True if the server may still be in the middle of the transfer (so the client tells it
    /// with an ERR packet that the transfer is over).
    fn leaves_server_open(&self) -> bool {
        matches!(
            self,
            Self::NoAnswer { .. }
                | Self::Link { .. }
                | Self::BusyTimeout { .. }
                | Self::Protocol { .. }
        )
    }
}

fn packet_name(packet: u32) -> String {
    if packet == 0 {
        "the write request".to_owned()
    } else {
        format!("data packet {packet}")
    }
}

fn text_suffix(text: &str) -> String {
    if text.is_empty() {
        String::new()
    } else {
        format!(": {text}")
    }
}

/// The answer to one packet.
enum Answer {
    Ack,
    Busy(Busy),
    Nothing,
    Failed(String),
}

/// Bytes of mailbox and FoE headers in front of the data of a DATA packet.
pub const OVERHEAD: usize = mailbox::HEADER_LEN + packet::HEADER_LEN;

/// An FoE client on a mailbox port.
#[derive(Debug)]
pub struct Client<P> {
    port: P,
    config: ClientConfig,
    counter: u8,
}

impl<P: MailboxPort> Client<P> {
    /// A client on `port`.
    pub fn new(port: P, config: ClientConfig) -> Self {
        Self {
            port,
            config,
            counter: 0,
        }
    }

    /// The port.
    pub fn port(&self) -> &P {
        &self.port
    }

    /// The port, mutably.
    pub fn port_mut(&mut self) -> &mut P {
        &mut self.port
    }

    /// Gives the port back.
    pub fn into_port(self) -> P {
        self.port
    }

    /// Writes `data` as the file `name` (FoE write: WRQ, then DATA packets as large as the
    /// receive mailbox allows, each acknowledged). Calls `progress` after each acknowledge and
    /// each BUSY answer. On a failure that may leave the server in the middle of the transfer
    /// (no answer, failed accesses, endless BUSY, nonsense answers) it sends the server an ERR
    /// packet (best effort) before returning the error.
    pub fn write(
        &mut self,
        name: &str,
        data: &[u8],
        progress: &mut dyn FnMut(&Progress),
    ) -> Result<Summary, FoeError> {
        let size = self.port.request_size();
        let Some(max_data) = size.checked_sub(OVERHEAD).filter(|&n| n > 0) else {
            return Err(FoeError::MailboxTooSmall { size });
        };
        if name.len() > max_data {
            return Err(FoeError::NameTooLong {
                len: name.len(),
                size,
            });
        }
        let start = Instant::now();
        let mut summary = Summary::default();
        self.drain();
        let result = self.write_packets(name, data, max_data, progress, &mut summary);
        summary.elapsed = start.elapsed();
        match result {
            Ok(()) => Ok(summary),
            Err(e) => {
                if e.leaves_server_open() {
                    self.abort("transfer aborted by the client");
                }
                Err(e)
            }
        }
    }

    fn write_packets(
        &mut self,
        name: &str,
        data: &[u8],
        max_data: usize,
        progress: &mut dyn FnMut(&Progress),
        summary: &mut Summary,
    ) -> Result<(), FoeError> {
        let total = data.len() as u64;
        let request = Packet::WriteRequest {
            password: self.config.password,
            name: name.as_bytes(),
        };
        self.exchange(&request, 0, 0, total, progress, summary)?;
        progress(&Progress {
            acknowledged: 0,
            total,
            busy: None,
        });
        let mut offset = 0usize;
        let mut number = 1u32;
        loop {
            let end = offset.saturating_add(max_data).min(data.len());
            let chunk = data.get(offset..end).unwrap_or_default();
            let packet = Packet::Data {
                packet: number,
                data: chunk,
            };
            self.exchange(&packet, number, offset as u64, total, progress, summary)?;
            summary.packets += 1;
            summary.bytes = end as u64;
            offset = end;
            progress(&Progress {
                acknowledged: offset as u64,
                total,
                busy: None,
            });
            if chunk.len() < max_data {
                return Ok(());
            }
            number = number.checked_add(1).ok_or_else(|| FoeError::Protocol {
                packet: number,
                what: "the file needs more than 2^32 packets".to_owned(),
            })?;
        }
    }

    /// Sends `packet` until the server acknowledges it (`expect` is its number).
    fn exchange(
        &mut self,
        packet: &Packet<'_>,
        expect: u32,
        acknowledged: u64,
        total: u64,
        progress: &mut dyn FnMut(&Progress),
        summary: &mut Summary,
    ) -> Result<(), FoeError> {
        let encoded = packet.to_vec();
        let first_sent = Instant::now();
        let mut busy_since: Option<Instant> = None;
        let mut attempts = 0u32;
        // Attempts whose accesses worked but that got no answer: when giving up, a device that
        // was reachable but silent is reported as such, not as a link failure.
        let mut unanswered = 0u32;
        loop {
            attempts += 1;
            if attempts > 1 {
                summary.repeats += 1;
                tracing::debug!(packet = expect, attempts, "FoE packet sent again");
            }
            let answer = match self.send(&encoded) {
                Ok(()) => self.answer(expect)?,
                Err(e) => Answer::Failed(e.to_string()),
            };
            let gave_up = attempts > self.config.retries;
            let no_answer = |attempts| FoeError::NoAnswer {
                packet: expect,
                attempts,
                waited: first_sent.elapsed(),
            };
            match answer {
                Answer::Ack => return Ok(()),
                Answer::Busy(busy) => {
                    summary.busy += 1;
                    let since = *busy_since.get_or_insert_with(Instant::now);
                    if since.elapsed() > self.config.busy_timeout {
                        return Err(FoeError::BusyTimeout {
                            packet: expect,
                            busy_for: since.elapsed(),
                        });
                    }
                    progress(&Progress {
                        acknowledged,
                        total,
                        busy: Some(busy),
                    });
                    // A BUSY is an answer: the repeats start over.
                    attempts = 0;
                    unanswered = 0;
                    std::thread::sleep(self.config.busy_delay);
                }
                Answer::Nothing if gave_up => return Err(no_answer(attempts)),
                Answer::Nothing => unanswered += 1,
                Answer::Failed(_) if gave_up && unanswered > 0 => return Err(no_answer(attempts)),
                Answer::Failed(message) if gave_up => {
                    return Err(FoeError::Link {
                        packet: expect,
                        attempts,
                        message,
                    })
                }
                Answer::Failed(message) => {
                    tracing::debug!(packet = expect, %message, "FoE mailbox access failed");
                    std::thread::sleep(self.config.busy_delay);
                }
            }
        }
    }

    /// Sends one FoE packet in a mailbox message with the next counter; waits up to the reply
    /// timeout for a full receive mailbox to empty.
    fn send(&mut self, encoded: &[u8]) -> Result<(), PortError> {
        self.counter = mailbox::next_counter(self.counter);
        let message = mailbox::request(mailbox_type::FOE, self.counter, encoded)
            .ok_or_else(|| PortError::Link("FoE packet longer than a mailbox".to_owned()))?;
        let deadline = Instant::now() + self.config.reply_timeout;
        loop {
            match self.port.send(&message) {
                Err(PortError::Full) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(1));
                }
                other => return other,
            }
        }
    }

    /// Waits for the answer to packet `expect`.
    fn answer(&mut self, expect: u32) -> Result<Answer, FoeError> {
        let deadline = Instant::now() + self.config.reply_timeout;
        loop {
            let remaining = deadline.saturating_duration_since(Instant::now());
            let message = match self.port.receive(remaining) {
                Ok(Some(m)) => m,
                Ok(None) => return Ok(Answer::Nothing),
                Err(e) => return Ok(Answer::Failed(e.to_string())),
            };
            let (header, data) = match MailboxHeader::decode(&message) {
                Ok(decoded) => decoded,
                Err(e) => {
                    tracing::warn!("ignoring an unreadable mailbox message: {e}");
                    continue;
                }
            };
            match header.mailbox_type {
                mailbox_type::FOE => {}
                mailbox_type::ERR => {
                    return Err(FoeError::Mailbox {
                        packet: expect,
                        error: MailboxError::decode(data).unwrap_or(MailboxError(0)),
                    })
                }
                other => {
                    tracing::debug!(mailbox_type = other, "ignoring a mailbox message");
                    continue;
                }
            }
            let protocol = |what: String| FoeError::Protocol {
                packet: expect,
                what,
            };
            match Packet::decode(data).map_err(|e| protocol(e.to_string()))? {
                Packet::Ack { packet } if packet == expect => return Ok(Answer::Ack),
                Packet::Ack { packet } if packet < expect => {
                    // The answer to an earlier copy of a packet sent again.
                    tracing::debug!(packet, "stale FoE acknowledge ignored");
                }
                Packet::Ack { packet } => {
                    return Err(protocol(format!("acknowledge of packet {packet}")))
                }
                Packet::Error { code, text } => {
                    return Err(FoeError::Refused {
                        packet: expect,
                        code,
                        text: packet::text(text),
                    })
                }
                Packet::Busy { done, entire, text } => {
                    return Ok(Answer::Busy(Busy {
                        done,
                        entire,
                        text: packet::text(text),
                    }))
                }
                other => return Err(protocol(format!("FoE OpCode {}", other.opcode()))),
            }
        }
    }

    /// Takes stale answers out of the send mailbox.
    fn drain(&mut self) {
        for _ in 0..16 {
            match self.port.receive(Duration::ZERO) {
                Ok(Some(_)) => tracing::debug!("stale mailbox message discarded"),
                _ => break,
            }
        }
    }

    /// Tells the server the transfer is over (an ERR packet, not answered), best effort.
    fn abort(&mut self, text: &str) {
        let packet = Packet::Error {
            code: ErrorCode::NOT_DEFINED,
            text: text.as_bytes(),
        };
        self.counter = mailbox::next_counter(self.counter);
        if let Some(message) = mailbox::request(mailbox_type::FOE, self.counter, &packet.to_vec()) {
            if let Err(e) = self.port.send(&message) {
                tracing::debug!("FoE abort not delivered: {e}");
            }
        }
    }
}
