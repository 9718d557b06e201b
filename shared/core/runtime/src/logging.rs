//! Logging setup shared by every executable.
//!
//! Events never block the thread that logs (a control loop): each formatted line goes into a
//! bounded queue that a writer thread empties into stderr. When stderr is full or stalled (a
//! pipe nobody reads) and the queue is full, the line is dropped and counted; the count is
//! written as soon as lines get through again, and [`dropped_log_lines`] gives it.

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use tracing_subscriber::EnvFilter;

/// Lines the queue holds before it drops.
const QUEUE_LINES: usize = 1024;
/// How long the process waits at exit for queued lines to reach stderr.
const EXIT_FLUSH: Duration = Duration::from_secs(1);

struct Queue {
    /// None: the writer thread could not start; lines are written directly.
    tx: Option<SyncSender<Vec<u8>>>,
    dropped: AtomicU64,
    pending: AtomicUsize,
}

fn queue() -> &'static Queue {
    static QUEUE: OnceLock<Queue> = OnceLock::new();
    QUEUE.get_or_init(|| {
        let (tx, rx) = sync_channel(QUEUE_LINES);
        let started = std::thread::Builder::new()
            .name("log-writer".into())
            .spawn(move || write_lines(rx))
            .is_ok();
        if started {
            // SAFETY: `flush_at_exit` is an `extern "C" fn()` that stays valid for the whole
            // process.
            unsafe {
                libc::atexit(flush_at_exit);
            }
        }
        Queue {
            tx: started.then_some(tx),
            dropped: AtomicU64::new(0),
            pending: AtomicUsize::new(0),
        }
    })
}

/// The writer thread: lines to stderr (blocking here blocks no loop), and the drop count
/// whenever it grew.
fn write_lines(rx: Receiver<Vec<u8>>) {
    let mut reported = 0u64;
    while let Ok(line) = rx.recv() {
        let q = queue();
        let dropped = q.dropped.load(Ordering::Relaxed);
        let mut err = std::io::stderr().lock();
        if dropped > reported {
            let _ = writeln!(
                err,
                "teleop: {} log lines dropped (stderr full or stalled)",
                dropped - reported
            );
            reported = dropped;
        }
        let _ = err.write_all(&line);
        q.pending.fetch_sub(1, Ordering::Relaxed);
    }
}

/// At exit: gives the writer thread a bounded time to write what is queued.
extern "C" fn flush_at_exit() {
    let q = queue();
    let until = Instant::now() + EXIT_FLUSH;
    while q.pending.load(Ordering::Relaxed) > 0 && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// Log lines dropped so far in this process because stderr was full or stalled.
pub fn dropped_log_lines() -> u64 {
    queue().dropped.load(Ordering::Relaxed)
}

/// The `io::Write` the subscriber formats each event into: one `write` per event, which never
/// blocks.
struct QueueWriter;

impl Write for QueueWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let q = queue();
        match &q.tx {
            Some(tx) => {
                q.pending.fetch_add(1, Ordering::Relaxed);
                if tx.try_send(buf.to_vec()).is_err() {
                    q.pending.fetch_sub(1, Ordering::Relaxed);
                    q.dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
            None => {
                let _ = std::io::stderr().write_all(buf);
            }
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Sends `tracing` events to stderr through the non-blocking queue, filtered by `TELEOP_LOG`
/// (default `info`), e.g. `TELEOP_LOG=debug` or `TELEOP_LOG=teleop_runtime=trace`. Also quiets
/// iceoryx2's own logger to warnings. Safe to call more than once.
pub fn init_logging() {
    // The writer thread starts here, from the thread that sets up (not from a real-time
    // thread that logs first, whose policy it would inherit).
    queue();
    let filter = EnvFilter::try_from_env("TELEOP_LOG").unwrap_or_else(|_| EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(|| QueueWriter)
        .with_target(false)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
}
