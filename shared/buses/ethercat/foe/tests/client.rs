//! The write client against a scripted FoE server behind an in-memory mailbox: packet sizes,
//! the end of the file, BUSY, lost requests and answers, stale acknowledges, refusals, a server
//! that stops answering, failed accesses and mailbox errors.
#![allow(clippy::unwrap_used)]

use std::collections::VecDeque;
use std::time::Duration;

use teleop_foe::mailbox::{self, mailbox_type, MailboxError, MailboxHeader};
use teleop_foe::packet::{self, ErrorCode, Packet};
use teleop_foe::{Client, ClientConfig, FoeError, MailboxPort, PortError, Progress};

/// What arrived at the server.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Seen {
    Write(String),
    Data(u32, usize),
    Err(u32, String),
}

#[derive(Default)]
struct Server {
    size: usize,
    expected: u32,
    file: Vec<u8>,
    done: bool,
    outbox: VecDeque<Vec<u8>>,
    seen: Vec<Seen>,
    counters: Vec<u8>,
    // Behaviour.
    busy_answers: u32,
    lose_answer_once: Vec<u32>,
    lose_request_once: Vec<u32>,
    double_acks: bool,
    stall_after: Option<u32>,
    refuse_write: Option<(ErrorCode, &'static str)>,
    refuse_packet: Option<u32>,
    failing_sends: u32,
    full_sends: u32,
    mailbox_error: bool,
    chatter: bool,
    wrong_ack: bool,
}

impl Server {
    fn new(size: usize) -> Self {
        Self {
            size,
            ..Self::default()
        }
    }

    fn reply(&mut self, p: Packet<'_>) {
        let m = mailbox::request(mailbox_type::FOE, 1, &p.to_vec()).unwrap();
        self.outbox.push_back(m);
    }

    fn handle(&mut self, p: Packet<'_>) {
        let max = self.size - 12;
        match p {
            Packet::WriteRequest { name, .. } => {
                self.seen.push(Seen::Write(packet::text(name)));
                if let Some((code, text)) = self.refuse_write {
                    self.reply(Packet::Error {
                        code,
                        text: text.as_bytes(),
                    });
                    return;
                }
                self.expected = 1;
                self.reply(Packet::Ack { packet: 0 });
            }
            Packet::Data { packet, data } => {
                self.seen.push(Seen::Data(packet, data.len()));
                if self.stall_after.is_some_and(|n| packet > n) {
                    return;
                }
                if self.refuse_packet == Some(packet) {
                    self.reply(Packet::Error {
                        code: ErrorCode::DISK_FULL,
                        text: b"flash full\0",
                    });
                    return;
                }
                if packet == self.expected {
                    self.file.extend_from_slice(data);
                    self.expected += 1;
                    if data.len() < max {
                        self.done = true;
                    }
                } else if packet + 1 != self.expected {
                    self.reply(Packet::Error {
                        code: ErrorCode::PACKET_NUMBER,
                        text: b"",
                    });
                    return;
                }
                if self.done && self.busy_answers > 0 {
                    self.busy_answers -= 1;
                    self.reply(Packet::Busy {
                        done: 50,
                        entire: 100,
                        text: b"writing",
                    });
                    return;
                }
                if let Some(i) = self.lose_answer_once.iter().position(|&n| n == packet) {
                    self.lose_answer_once.remove(i);
                    return;
                }
                if self.chatter {
                    // A CoE emergency in between: not for the FoE client.
                    let coe = mailbox::request(mailbox_type::COE, 2, &[0, 0x10, 0, 0]).unwrap();
                    self.outbox.push_back(coe);
                }
                let ack = if self.wrong_ack && packet == 2 {
                    packet + 3
                } else {
                    packet
                };
                self.reply(Packet::Ack { packet: ack });
                if self.double_acks {
                    self.reply(Packet::Ack { packet: ack });
                }
            }
            Packet::Error { code, text } => self.seen.push(Seen::Err(code.0, packet::text(text))),
            _ => self.reply(Packet::Error {
                code: ErrorCode::ILLEGAL,
                text: b"",
            }),
        }
    }
}

impl MailboxPort for Server {
    fn request_size(&self) -> usize {
        self.size
    }

    fn send(&mut self, message: &[u8]) -> Result<(), PortError> {
        assert!(
            message.len() <= self.size,
            "message longer than the mailbox"
        );
        if self.failing_sends > 0 {
            self.failing_sends -= 1;
            return Err(PortError::Link("frame lost".into()));
        }
        if self.full_sends > 0 {
            self.full_sends -= 1;
            return Err(PortError::Full);
        }
        let (h, data) = MailboxHeader::decode(message).unwrap();
        assert_eq!(h.mailbox_type, mailbox_type::FOE);
        self.counters.push(h.counter);
        if self.mailbox_error {
            let m = mailbox::request(
                mailbox_type::ERR,
                1,
                &MailboxError::UNSUPPORTED_PROTOCOL.encode(),
            )
            .unwrap();
            self.outbox.push_back(m);
            return Ok(());
        }
        let p = Packet::decode(data).unwrap();
        if let Packet::Data { packet, .. } = p {
            if let Some(i) = self.lose_request_once.iter().position(|&n| n == packet) {
                self.lose_request_once.remove(i);
                return Ok(());
            }
        }
        self.handle(p);
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, PortError> {
        match self.outbox.pop_front() {
            Some(mut m) => {
                m.resize(self.size, 0);
                Ok(Some(m))
            }
            None => {
                std::thread::sleep(timeout.min(Duration::from_millis(5)));
                Ok(None)
            }
        }
    }
}

fn config() -> ClientConfig {
    ClientConfig {
        reply_timeout: Duration::from_millis(30),
        retries: 2,
        busy_delay: Duration::from_millis(1),
        busy_timeout: Duration::from_secs(5),
        password: 0,
    }
}

fn file(n: usize) -> Vec<u8> {
    (0..n).map(|i| (i * 7 % 251) as u8).collect()
}

fn write(
    server: &mut Server,
    data: &[u8],
) -> (Result<teleop_foe::Summary, FoeError>, Vec<Progress>) {
    let mut progress = Vec::new();
    let result = Client::new(&mut *server, config())
        .write("fw.bin", data, &mut |p| progress.push(p.clone()));
    (result, progress)
}

#[test]
fn a_file_goes_in_packets_as_large_as_the_mailbox() {
    let mut server = Server::new(128);
    let data = file(1000);
    let (result, progress) = write(&mut server, &data);
    let summary = result.unwrap();
    assert_eq!(server.file, data);
    assert_eq!(server.seen[0], Seen::Write("fw.bin".into()));
    // 116 bytes per packet: 8 full ones and 72 bytes.
    let sizes: Vec<usize> = server
        .seen
        .iter()
        .filter_map(|s| match s {
            Seen::Data(_, n) => Some(*n),
            _ => None,
        })
        .collect();
    assert_eq!(sizes, [116, 116, 116, 116, 116, 116, 116, 116, 72]);
    assert_eq!(
        (summary.packets, summary.bytes, summary.repeats),
        (9, 1000, 0)
    );
    assert!(progress
        .windows(2)
        .all(|w| w[0].acknowledged <= w[1].acknowledged));
    assert_eq!(progress.last().unwrap().acknowledged, 1000);
    assert!(progress.iter().all(|p| p.total == 1000));
    // Counters run 1..=7 and never 0.
    assert_eq!(&server.counters[..9], &[1, 2, 3, 4, 5, 6, 7, 1, 2]);
}

#[test]
fn a_file_that_fills_its_last_packet_ends_with_an_empty_one() {
    let mut server = Server::new(64);
    let data = file(52 * 2);
    let summary = write(&mut server, &data).0.unwrap();
    assert_eq!(summary.packets, 3);
    assert_eq!(server.seen.last(), Some(&Seen::Data(3, 0)));
    assert_eq!(server.file, data);

    let mut server = Server::new(64);
    let summary = write(&mut server, &[]).0.unwrap();
    assert_eq!(summary.packets, 1);
    assert_eq!(
        server.seen,
        [Seen::Write("fw.bin".into()), Seen::Data(1, 0)]
    );
}

#[test]
fn busy_answers_make_the_client_send_the_packet_again() {
    let mut server = Server::new(128);
    server.busy_answers = 3;
    let data = file(300);
    let (result, progress) = write(&mut server, &data);
    let summary = result.unwrap();
    assert_eq!(summary.busy, 3);
    assert_eq!(summary.repeats, 0, "a BUSY is an answer, not a lost packet");
    assert_eq!(server.file, data);
    let last: Vec<&Seen> = server
        .seen
        .iter()
        .filter(|s| **s == Seen::Data(3, 68))
        .collect();
    assert_eq!(
        last.len(),
        4,
        "the last packet went 4 times: {:?}",
        server.seen
    );
    let busy: Vec<&Progress> = progress.iter().filter(|p| p.busy.is_some()).collect();
    assert_eq!(busy.len(), 3);
    assert_eq!(busy[0].busy.as_ref().unwrap().text, "writing");
    assert_eq!(busy[0].acknowledged, 232);
}

#[test]
fn lost_answers_and_requests_are_repeated_and_stale_acks_ignored() {
    let mut server = Server::new(128);
    server.lose_answer_once = vec![2, 5];
    server.lose_request_once = vec![3];
    server.double_acks = true;
    server.chatter = true;
    let data = file(700);
    let summary = write(&mut server, &data).0.unwrap();
    assert_eq!(server.file, data, "duplicates are not stored twice");
    assert_eq!(summary.repeats, 3);
    assert_eq!(summary.packets, 7);
}

#[test]
fn a_refused_request_reports_the_code_and_text_and_sends_no_abort() {
    let mut server = Server::new(128);
    server.refuse_write = Some((ErrorCode::NO_RIGHTS, "bad authentication code\0"));
    let err = write(&mut server, &file(10)).0.unwrap_err();
    assert_eq!(err.code(), Some(ErrorCode::NO_RIGHTS));
    assert_eq!(
        err.to_string(),
        "the device refused the write request: FoE error 0x800a (no rights (password or authentication invalid)): bad authentication code"
    );
    assert!(!server.seen.iter().any(|s| matches!(s, Seen::Err(..))));

    let mut server = Server::new(128);
    server.refuse_packet = Some(3);
    let err = write(&mut server, &file(1000)).0.unwrap_err();
    assert!(
        matches!(err, FoeError::Refused { packet: 3, code: ErrorCode::DISK_FULL, ref text } if text == "flash full"),
        "{err:?}"
    );
    assert!(err.to_string().contains("data packet 3"), "{err}");
}

#[test]
fn a_server_that_stops_answering_is_given_up_and_told_so() {
    let mut server = Server::new(128);
    server.stall_after = Some(4);
    let err = write(&mut server, &file(1000)).0.unwrap_err();
    match &err {
        FoeError::NoAnswer {
            packet, attempts, ..
        } => assert_eq!((*packet, *attempts), (5, 3)),
        other => panic!("{other:?}"),
    }
    assert!(err.to_string().contains("stopped answering"), "{err}");
    let copies = server
        .seen
        .iter()
        .filter(|s| **s == Seen::Data(5, 116))
        .count();
    assert_eq!(copies, 3);
    assert!(
        matches!(server.seen.last(), Some(Seen::Err(0x8000, t)) if t.contains("aborted")),
        "{:?}",
        server.seen
    );
}

#[test]
fn failed_accesses_are_retried_then_reported() {
    let mut server = Server::new(128);
    server.failing_sends = 2;
    server.full_sends = 1;
    let data = file(200);
    let summary = write(&mut server, &data).0.unwrap();
    assert_eq!(server.file, data);
    assert_eq!(summary.repeats, 2);

    let mut server = Server::new(128);
    server.failing_sends = 100;
    let err = write(&mut server, &data).0.unwrap_err();
    assert!(
        matches!(err, FoeError::Link { packet: 0, attempts: 3, ref message } if message == "frame lost"),
        "{err:?}"
    );
}

#[test]
fn mailbox_errors_and_nonsense_end_the_transfer() {
    let mut server = Server::new(128);
    server.mailbox_error = true;
    let err = write(&mut server, &file(10)).0.unwrap_err();
    assert_eq!(
        err,
        FoeError::Mailbox {
            packet: 0,
            error: MailboxError::UNSUPPORTED_PROTOCOL
        }
    );
    assert!(err.to_string().contains("not supported"), "{err}");

    let mut server = Server::new(128);
    server.wrong_ack = true;
    let err = write(&mut server, &file(500)).0.unwrap_err();
    assert!(
        matches!(err, FoeError::Protocol { packet: 2, .. }),
        "{err:?}"
    );
    assert!(matches!(server.seen.last(), Some(Seen::Err(0x8000, _))));
}

#[test]
fn endless_busy_is_given_up() {
    let mut server = Server::new(128);
    server.busy_answers = u32::MAX;
    let mut progress = Vec::new();
    let config = ClientConfig {
        busy_timeout: Duration::from_millis(50),
        ..config()
    };
    let err = Client::new(&mut server, config)
        .write("fw.bin", &file(50), &mut |p| progress.push(p.clone()))
        .unwrap_err();
    assert!(
        matches!(err, FoeError::BusyTimeout { packet: 1, .. }),
        "{err:?}"
    );
}

#[test]
fn sizes_that_cannot_work_are_refused_before_sending() {
    let mut server = Server::new(12);
    let err = write(&mut server, &file(10)).0.unwrap_err();
    assert_eq!(err, FoeError::MailboxTooSmall { size: 12 });
    let mut server = Server::new(16);
    let err = Client::new(&mut server, config())
        .write("a-long-name.bin", &[], &mut |_| {})
        .unwrap_err();
    assert_eq!(err, FoeError::NameTooLong { len: 15, size: 16 });
    assert!(server.seen.is_empty());
}
