//! The simulator under test and a host on its pty: the simulator as a process in a directory
//! of its own (its pty link and control socket there), the host a serial port opened on the
//! link at a baud rate, sending requests built with the protocol crate's encoders and reading
//! status packets with its scanner and parser.
#![allow(dead_code, clippy::unwrap_used)]

use std::ffi::OsString;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};
use teleop_leap_protocol::packet::{self, FastSyncReply, Scan, Status, MAX_PACKET};
use teleop_leap_protocol::EncodeError;
use teleop_sim_kit::testing::SimProcess;
use teleop_sim_kit::Stats;

/// The LEAP Hand's baud rate.
pub const BAUD: u32 = 4_000_000;
/// How long a host waits for statuses it expects (generous: a loaded test machine).
pub const WAIT: Duration = Duration::from_secs(2);

/// A running `teleop-sim-leap`.
pub struct Sim(pub SimProcess);

impl Sim {
    /// Starts the simulator with these extra arguments.
    pub fn start(args: &[&str]) -> Self {
        let args: Vec<OsString> = args.iter().map(OsString::from).collect();
        Self(SimProcess::start(
            Path::new(env!("CARGO_BIN_EXE_teleop-sim-leap")),
            |dir| {
                let mut all: Vec<OsString> = vec!["--link".into(), dir.join("leap").into()];
                all.extend(args);
                all
            },
            "leap: link ",
            "leap.ctl",
        ))
    }

    /// The pty's link.
    pub fn link(&self) -> PathBuf {
        self.0.dir().join("leap")
    }

    /// A control line's answer.
    pub fn control(&self, line: &str) -> String {
        self.0.control(line)
    }

    /// A control line that must succeed.
    pub fn control_ok(&self, line: &str) -> String {
        let reply = self.control(line);
        assert!(reply.starts_with("ok"), "{line}: {reply}");
        reply
    }

    /// `stats`, read back.
    pub fn stats(&self) -> Stats {
        self.0.stats()
    }

    /// A counter of `stats`.
    pub fn counter(&self, key: &str) -> u64 {
        self.stats()[key].parse().unwrap()
    }

    /// A host on the pty at `baud`.
    pub fn host(&self, baud: u32) -> Host {
        Host::open(&self.link(), baud)
    }
}

/// A status packet as received, owned.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reply {
    pub id: u8,
    pub error: u8,
    pub params: Vec<u8>,
}

impl Reply {
    /// The parameters as a little-endian unsigned number.
    pub fn value(&self) -> i64 {
        let mut raw = [0u8; 8];
        raw[..self.params.len()].copy_from_slice(&self.params);
        u64::from_le_bytes(raw) as i64
    }

    /// The parameters as a little-endian signed number.
    pub fn signed(&self) -> i64 {
        let shift = 64 - 8 * self.params.len() as u32;
        (self.value() << shift) >> shift
    }
}

/// A host on the serial port.
pub struct Host {
    port: TTYPort,
    out: Vec<u8>,
}

impl Host {
    /// Opens `path` at `baud` (8N1, as the ROBOTIS SDK does).
    pub fn open(path: &Path, baud: u32) -> Self {
        let port = serialport::new(path.to_string_lossy(), baud)
            .timeout(Duration::from_millis(5))
            .open_native()
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        Self {
            port,
            out: vec![0; MAX_PACKET],
        }
    }

    /// Drops what was received, then sends the request `encode` writes.
    pub fn send(&mut self, encode: impl FnOnce(&mut [u8]) -> Result<usize, EncodeError>) {
        let n = encode(&mut self.out).unwrap();
        self.port.clear(serialport::ClearBuffer::Input).unwrap();
        self.port.write_all(&self.out[..n]).unwrap();
    }

    /// Drops what was received, then sends `bytes` as they are.
    pub fn send_raw(&mut self, bytes: &[u8]) {
        self.port.clear(serialport::ClearBuffer::Input).unwrap();
        self.port.write_all(bytes).unwrap();
    }

    /// Every byte received until nothing more came for `quiet` after the last one (or `WAIT`
    /// passed): the first byte is waited for up to `WAIT`, a busy simulator's late answer is not
    /// taken for none.
    pub fn raw(&mut self, quiet: Duration) -> Vec<u8> {
        let mut got = Vec::new();
        let end = Instant::now() + WAIT;
        let mut last = Instant::now();
        let mut buf = [0u8; 1024];
        while Instant::now() < end && (got.is_empty() || last.elapsed() < quiet) {
            if let Ok(n) = self.port.read(&mut buf) {
                if n > 0 {
                    got.extend_from_slice(&buf[..n]);
                    last = Instant::now();
                }
            }
        }
        got
    }

    /// Up to `n` statuses, waiting at most `wait` for them all (packets that do not parse are
    /// skipped); fewer when they do not come.
    pub fn statuses_within(&mut self, n: usize, wait: Duration) -> Vec<Reply> {
        let mut got = Vec::new();
        let mut rx = Vec::new();
        let mut scratch = vec![0u8; MAX_PACKET];
        let end = Instant::now() + wait;
        let mut buf = [0u8; 1024];
        while got.len() < n && Instant::now() < end {
            if let Ok(k) = self.port.read(&mut buf) {
                rx.extend_from_slice(&buf[..k]);
            }
            loop {
                match packet::scan(&rx) {
                    Scan::Need(_) => break,
                    Scan::Skip(k) => {
                        rx.drain(..k);
                    }
                    Scan::Packet(k) => {
                        let parsed = packet::parse(&rx[..k], &mut scratch)
                            .ok()
                            .and_then(|p| Status::from_packet(&p).ok())
                            .map(|s| Reply {
                                id: s.id,
                                error: s.error.0,
                                params: s.params.to_vec(),
                            });
                        match parsed {
                            Some(reply) => {
                                got.push(reply);
                                rx.drain(..k);
                            }
                            None => {
                                rx.drain(..1);
                            }
                        }
                    }
                }
            }
        }
        got
    }

    /// Exactly `n` statuses (panics when they do not come within [`WAIT`]).
    pub fn statuses(&mut self, n: usize) -> Vec<Reply> {
        let got = self.statuses_within(n, WAIT);
        assert_eq!(got.len(), n, "statuses: {got:?}");
        got
    }

    /// One status.
    pub fn status(&mut self) -> Reply {
        self.statuses(1).remove(0)
    }

    /// No status within `wait`.
    pub fn silence(&mut self, wait: Duration) {
        let got = self.statuses_within(1, wait);
        assert!(got.is_empty(), "expected no status, got {got:?}");
    }

    /// Read of `len` bytes at `addr` from `id`.
    pub fn read(&mut self, id: u8, addr: u16, len: u16) -> Reply {
        self.send(|out| packet::read(id, addr, len, out));
        self.status()
    }

    /// Write of `data` at `addr` to `id`: the status's error byte.
    pub fn write(&mut self, id: u8, addr: u16, data: &[u8]) -> u8 {
        self.send(|out| packet::write(id, addr, data, out));
        self.status().error
    }

    /// Sync Write of one `len`-byte value per ID.
    pub fn sync_write(&mut self, addr: u16, values: &[(u8, i32)], len: usize) {
        let bytes: Vec<(u8, Vec<u8>)> = values
            .iter()
            .map(|&(id, v)| (id, v.to_le_bytes()[..len].to_vec()))
            .collect();
        self.send(|out| {
            packet::sync_write(
                addr,
                len as u16,
                bytes.iter().map(|(id, b)| (*id, b.as_slice())),
                out,
            )
        });
    }

    /// Fast Sync Read of `len` bytes at `addr` from `ids`: the raw reply bytes.
    pub fn fast_sync_read_raw(&mut self, addr: u16, len: u16, ids: &[u8]) -> Vec<u8> {
        self.send(|out| packet::fast_sync_read(addr, len, ids, out));
        self.raw(Duration::from_millis(100))
    }

    /// Fast Sync Read: `(id, error, data)` per block, every block's CRC checked.
    pub fn fast_sync_read(&mut self, addr: u16, len: u16, ids: &[u8]) -> Vec<(u8, u8, Vec<u8>)> {
        let raw = self.fast_sync_read_raw(addr, len, ids);
        let mut scratch = vec![0u8; MAX_PACKET];
        let p = packet::parse(&raw, &mut scratch).unwrap_or_else(|e| panic!("{e}: {raw:02X?}"));
        FastSyncReply::new(&p, len)
            .unwrap()
            .blocks()
            .map(|b| (b.id, b.error.0, b.data.to_vec()))
            .collect()
    }
}

/// Polls `f` until it gives a value (panics after `timeout`, naming `what`).
pub fn wait_for<T>(timeout: Duration, what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let end = Instant::now() + timeout;
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(Instant::now() < end, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}
