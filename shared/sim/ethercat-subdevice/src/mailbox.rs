//! Mailbox header (ETG.1000.4 5.6.1), mailbox error replies and the reply queue.

use std::collections::VecDeque;

/// Mailbox header length.
pub(crate) const HEADER_LEN: usize = 6;
/// Mailbox type: error reply.
pub(crate) const TYPE_ERR: u8 = 0x00;
/// Mailbox type: CoE.
pub(crate) const TYPE_COE: u8 = 0x03;
/// Mailbox type: FoE.
pub(crate) const TYPE_FOE: u8 = 0x04;
/// Replies waiting for SM1 beyond this are dropped (oldest first).
const QUEUE_LIMIT: usize = 16;

/// Mailbox error reply details (ETG.1000.4 table 30), sent in a mailbox of type 0 (ERR).
pub mod mailbox_error {
    /// Syntax of the 6-byte mailbox header is wrong.
    pub const SYNTAX: u16 = 0x0001;
    /// The mailbox protocol is not supported.
    pub const UNSUPPORTED_PROTOCOL: u16 = 0x0002;
    /// Channel field contains a wrong value.
    pub const INVALID_CHANNEL: u16 = 0x0003;
    /// The service in the mailbox protocol is not supported.
    pub const SERVICE_NOT_SUPPORTED: u16 = 0x0004;
    /// The mailbox protocol header is wrong.
    pub const INVALID_HEADER: u16 = 0x0005;
    /// Length of received mailbox data is too short.
    pub const SIZE_TOO_SHORT: u16 = 0x0006;
    /// Mailbox protocol cannot be processed because of limited resources.
    pub const NO_MORE_MEMORY: u16 = 0x0007;
    /// The length of the data is inconsistent.
    pub const INVALID_SIZE: u16 = 0x0008;
}

/// Protocol bit of SII word 0x1C for a mailbox type, if any.
pub(crate) fn protocol_bit(mailbox_type: u8) -> Option<u16> {
    match mailbox_type {
        0x01 => Some(0x01), // AoE
        0x02 => Some(0x02), // EoE
        0x03 => Some(0x04), // CoE
        0x04 => Some(0x08), // FoE
        0x05 => Some(0x10), // SoE
        0x0F => Some(0x20), // VoE
        _ => None,
    }
}

/// A parsed mailbox header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Header {
    /// Length of the data after the header.
    pub(crate) length: usize,
    /// Mailbox type (low nibble of byte 5).
    pub(crate) mailbox_type: u8,
    /// Counter 0..=7 (0: no duplicate detection).
    pub(crate) counter: u8,
}

impl Header {
    pub(crate) fn parse(raw: &[u8]) -> Option<Self> {
        let h = raw.get(..HEADER_LEN)?;
        Some(Self {
            length: usize::from(u16::from_le_bytes([h[0], h[1]])),
            mailbox_type: h[5] & 0x0F,
            counter: (h[5] >> 4) & 0x07,
        })
    }
}

/// Builds a complete mailbox message.
pub(crate) fn message(mailbox_type: u8, counter: u8, payload: &[u8]) -> Vec<u8> {
    let mut m = Vec::with_capacity(HEADER_LEN + payload.len());
    // Callers keep payloads below the SM1 size (a u16).
    m.extend_from_slice(&(payload.len() as u16).to_le_bytes());
    m.extend_from_slice(&[0, 0, 0, (mailbox_type & 0x0F) | ((counter & 0x07) << 4)]);
    m.extend_from_slice(payload);
    m
}

/// Payload of a mailbox error reply: type 0x0001 (mailbox command), detail.
pub(crate) fn error_payload(detail: u16) -> [u8; 4] {
    let d = detail.to_le_bytes();
    [0x01, 0x00, d[0], d[1]]
}

/// Mailbox state of the SubDevice side: duplicate detection, reply counter, pending replies and
/// the last reply (for the repeat request).
#[derive(Debug, Default)]
pub(crate) struct MailboxState {
    queue: VecDeque<Vec<u8>>,
    last_reply: Option<Vec<u8>>,
    last_request_counter: u8,
    reply_counter: u8,
}

impl MailboxState {
    /// Mailbox stopped (INIT) or restarted: forget everything.
    pub(crate) fn reset(&mut self) {
        *self = Self::default();
    }

    /// True if a request with this counter repeats the previous one (ETG.1000.4: a request with
    /// the same non-zero counter as the previous one was already received and is discarded).
    pub(crate) fn is_duplicate(&mut self, counter: u8) -> bool {
        if counter != 0 && counter == self.last_request_counter {
            return true;
        }
        self.last_request_counter = counter;
        false
    }

    /// Next reply counter, cycling 1..=7.
    pub(crate) fn next_counter(&mut self) -> u8 {
        self.reply_counter = if self.reply_counter >= 7 {
            1
        } else {
            self.reply_counter + 1
        };
        self.reply_counter
    }

    /// Queues a reply; returns false if an old one had to be dropped.
    pub(crate) fn push(&mut self, reply: Vec<u8>) -> bool {
        let mut kept = true;
        if self.queue.len() >= QUEUE_LIMIT {
            self.queue.pop_front();
            kept = false;
        }
        self.queue.push_back(reply);
        kept
    }

    /// Takes the next reply to place in SM1 and remembers it for a repeat request.
    pub(crate) fn pop(&mut self) -> Option<&[u8]> {
        let next = self.queue.pop_front()?;
        self.last_reply = Some(next);
        self.last_reply.as_deref()
    }

    pub(crate) fn last_reply(&self) -> Option<&[u8]> {
        self.last_reply.as_deref()
    }

    #[cfg(test)]
    pub(crate) fn pending(&self) -> usize {
        self.queue.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_round_trip() {
        let m = message(TYPE_COE, 5, &[1, 2, 3]);
        assert_eq!(m, [3, 0, 0, 0, 0, 0x53, 1, 2, 3]);
        let h = Header::parse(&m).expect("header");
        assert_eq!(
            h,
            Header {
                length: 3,
                mailbox_type: TYPE_COE,
                counter: 5
            }
        );
        assert_eq!(Header::parse(&m[..5]), None);
    }

    #[test]
    fn counters_and_duplicates() {
        let mut s = MailboxState::default();
        let seq: Vec<u8> = (0..8).map(|_| s.next_counter()).collect();
        assert_eq!(seq, [1, 2, 3, 4, 5, 6, 7, 1]);
        assert!(!s.is_duplicate(1));
        assert!(s.is_duplicate(1));
        assert!(!s.is_duplicate(2));
        assert!(!s.is_duplicate(0));
        assert!(!s.is_duplicate(0), "counter 0 disables duplicate detection");
    }

    #[test]
    fn queue_is_bounded() {
        let mut s = MailboxState::default();
        for i in 0..QUEUE_LIMIT {
            assert!(s.push(vec![i as u8]));
        }
        assert!(!s.push(vec![99]));
        assert_eq!(s.pending(), QUEUE_LIMIT);
        assert_eq!(s.pop(), Some(&[1u8][..]));
        assert_eq!(s.last_reply(), Some(&[1u8][..]));
    }
}
