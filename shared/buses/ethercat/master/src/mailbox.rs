//! Raw mailbox access with ethercrab's public `Command` API, for what ethercrab 0.7 does not do
//! itself: FoE (its [`MailboxPort`] for `teleop-foe`, on any mailbox, the bootstrap one
//! included) and the normal (non-expedited) CoE SDO download that strings need.
//!
//! Nothing here knows the Revo2: any SubDevice with mailboxes can use it.
//!
//! - [`EcatMailbox::send`]: FPWR of the whole receive mailbox (SM0) buffer; a working counter
//!   of 0 means the mailbox is still full ([`PortError::Full`]).
//! - [`EcatMailbox::receive`]: FPRD of the send mailbox's SM status byte (0x0805 + 8 n) until
//!   bit 3 ("mailbox full") is set, then FPRD of the whole send mailbox buffer (reading its last
//!   byte empties it).
//!
//! These calls block on ethercrab's futures (`futures_lite::future::block_on`): call them from a
//! plain thread, not from inside another future.

use std::time::{Duration, Instant};

use ethercrab::{Command, MainDevice};
use futures_lite::future::block_on;
use teleop_foe::mailbox::{self as mbx, mailbox_type, MailboxError, MailboxHeader};
use teleop_foe::{MailboxPort, PortError};

/// Start and length of a mailbox buffer in the ESC's memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MailboxArea {
    /// Physical start address.
    pub start: u16,
    /// Length in bytes.
    pub len: u16,
}

/// SM status register of sync manager `n` (0x0805 + 8 n).
pub const fn sm_status(n: u8) -> u16 {
    0x0805 + 8 * n as u16
}

/// "Mailbox full" in an SM status byte.
const MAILBOX_FULL: u8 = 0x08;

/// One SubDevice's mailboxes through a MainDevice: a [`MailboxPort`].
pub struct EcatMailbox<'a> {
    md: &'a MainDevice<'a>,
    address: u16,
    receive_mailbox: MailboxArea,
    send_mailbox: MailboxArea,
    send_sm: u8,
    poll: Duration,
}

impl<'a> EcatMailbox<'a> {
    /// The mailboxes of the SubDevice at configured station `address`: `receive_mailbox` is the
    /// buffer of SM0 (the SubDevice receives there), `send_mailbox` the buffer of SM1.
    pub fn new(
        md: &'a MainDevice<'a>,
        address: u16,
        receive_mailbox: MailboxArea,
        send_mailbox: MailboxArea,
    ) -> Self {
        Self {
            md,
            address,
            receive_mailbox,
            send_mailbox,
            send_sm: 1,
            poll: Duration::from_millis(1),
        }
    }

    /// How long [`receive`](MailboxPort::receive) waits between two looks at the SM status.
    pub fn with_poll_interval(mut self, poll: Duration) -> Self {
        self.poll = poll;
        self
    }
}

fn link(e: ethercrab::error::Error) -> PortError {
    PortError::Link(e.to_string())
}

impl MailboxPort for EcatMailbox<'_> {
    fn request_size(&self) -> usize {
        usize::from(self.receive_mailbox.len)
    }

    fn send(&mut self, message: &[u8]) -> Result<(), PortError> {
        let size = usize::from(self.receive_mailbox.len);
        if message.len() > size {
            return Err(PortError::Link(format!(
                "a {}-byte message does not fit the {size}-byte mailbox",
                message.len()
            )));
        }
        // The whole buffer: only a write of its last byte hands the message to the SubDevice.
        let mut buffer = message.to_vec();
        buffer.resize(size, 0);
        let write = Command::fpwr(self.address, self.receive_mailbox.start)
            .send_receive_slice(self.md, buffer.as_slice());
        match block_on(write) {
            Ok(_) => Ok(()),
            Err(ethercrab::error::Error::WorkingCounter { received: 0, .. }) => {
                Err(PortError::Full)
            }
            Err(e) => Err(link(e)),
        }
    }

    fn receive(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, PortError> {
        let deadline = Instant::now() + timeout;
        loop {
            let status = block_on(
                Command::fprd(self.address, sm_status(self.send_sm)).receive::<u8>(self.md),
            )
            .map_err(link)?;
            if status & MAILBOX_FULL != 0 {
                let read = Command::fprd(self.address, self.send_mailbox.start)
                    .receive_slice(self.md, self.send_mailbox.len);
                match block_on(read) {
                    Ok(data) => return Ok(Some(data.to_vec())),
                    // Emptied in between (read by someone else): keep waiting.
                    Err(ethercrab::error::Error::WorkingCounter { received: 0, .. }) => {}
                    Err(e) => return Err(link(e)),
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            std::thread::sleep(self.poll.min(deadline - now));
        }
    }
}

/// Why an SDO download over a mailbox port failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SdoError {
    /// The value does not fit one normal download in this mailbox.
    #[error("{len} bytes do not fit one SDO download in a {size}-byte mailbox")]
    TooLong {
        /// Value length.
        len: usize,
        /// Mailbox size.
        size: usize,
    },
    /// The SubDevice aborted the transfer.
    #[error("SDO abort {0:#010x}")]
    Abort(u32),
    /// The SubDevice answered with a mailbox error.
    #[error("mailbox error {0}")]
    Mailbox(MailboxError),
    /// No answer in time.
    #[error("no answer within {0:?}")]
    NoAnswer(Duration),
    /// The mailbox could not be accessed.
    #[error("{0}")]
    Port(#[from] PortError),
    /// An answer that is not the download's.
    #[error("unexpected answer: {0}")]
    Unexpected(String),
}

/// Writes `data` to the object `index:sub` with a CoE SDO download (ETG.1000.6 CoE, CiA 301):
/// expedited for up to 4 bytes, normal (size, then the data, in one mailbox) for longer values,
/// which ethercrab 0.7's `sdo_write` cannot send.
///
/// The request goes with mailbox counter 0, which SubDevices do not check for repeats: ethercrab
/// keeps its own counter for the same mailbox, and a request that happened to repeat its last
/// value would be dropped as a repeat.
pub fn sdo_download(
    port: &mut dyn MailboxPort,
    index: u16,
    sub: u8,
    data: &[u8],
    timeout: Duration,
) -> Result<(), SdoError> {
    let [i0, i1] = index.to_le_bytes();
    // CoE header: number 0, service 2 (SDO request).
    let mut coe = vec![0x00, 0x20];
    if data.len() <= 4 {
        let unused = 4 - data.len() as u8;
        coe.extend_from_slice(&[0x23 | (unused << 2), i0, i1, sub]);
        coe.extend_from_slice(data);
        coe.resize(10, 0);
    } else {
        let len = u32::try_from(data.len()).unwrap_or(u32::MAX);
        coe.extend_from_slice(&[0x21, i0, i1, sub]);
        coe.extend_from_slice(&len.to_le_bytes());
        coe.extend_from_slice(data);
    }
    let size = port.request_size();
    if mbx::HEADER_LEN + coe.len() > size {
        return Err(SdoError::TooLong {
            len: data.len(),
            size,
        });
    }
    let message = mbx::request(mailbox_type::COE, 0, &coe).ok_or(SdoError::TooLong {
        len: data.len(),
        size,
    })?;
    // Stale answers out of the way first.
    for _ in 0..16 {
        if port.receive(Duration::ZERO)?.is_none() {
            break;
        }
    }
    port.send(&message)?;
    let deadline = Instant::now() + timeout;
    loop {
        let remaining = deadline.saturating_duration_since(Instant::now());
        let Some(reply) = port.receive(remaining)? else {
            return Err(SdoError::NoAnswer(timeout));
        };
        let Ok((header, body)) = MailboxHeader::decode(&reply) else {
            continue;
        };
        match header.mailbox_type {
            mailbox_type::ERR => {
                return Err(SdoError::Mailbox(
                    MailboxError::decode(body).unwrap_or(MailboxError(0)),
                ))
            }
            mailbox_type::COE => {}
            _ => continue,
        }
        // CoE service in the top 4 bits of the 2-byte header: 3 = SDO response; others (e.g.
        // emergencies, 1) are not the answer.
        let [_, service, command, r0, r1, rsub, rest @ ..] = body else {
            return Err(SdoError::Unexpected(format!("{body:02x?}")));
        };
        if service >> 4 != 3 {
            continue;
        }
        if u16::from_le_bytes([*r0, *r1]) != index || *rsub != sub {
            return Err(SdoError::Unexpected(format!(
                "answer for {:#06x}:{rsub:02x}",
                u16::from_le_bytes([*r0, *r1])
            )));
        }
        return match (command, rest) {
            (0x60, _) => Ok(()),
            (0x80, [a, b, c, d, ..]) => Err(SdoError::Abort(u32::from_le_bytes([*a, *b, *c, *d]))),
            (other, _) => Err(SdoError::Unexpected(format!("SDO command {other:#04x}"))),
        };
    }
}
