//! Drives ethercrab's PDU loop over a [`FrameLink`]: sends the frames the MainDevice queues and
//! hands the replies back. Runs in its own named thread and survives link loss: a failed link is
//! reopened with backoff while ethercrab sees timeouts (which the cyclic loop counts and rides
//! out), instead of dying as `ethercrab::std::tx_rx_task` does on a socket error.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::task::{Wake, Waker};
use std::thread::{JoinHandle, Thread};
use std::time::Duration;

use ethercrab::{PduRx, PduTx};
use teleop_ecat_link::{FrameLink, LinkError, MAX_FRAME};

/// Opens the link (again).
pub type Connect = Box<dyn FnMut() -> Result<Box<dyn FrameLink>, LinkError> + Send>;

/// Shared counters and the link state, readable from the cyclic loop.
#[derive(Debug, Default)]
pub struct PumpStatus {
    /// Frames sent.
    pub sent: AtomicU64,
    /// Frames received.
    pub received: AtomicU64,
    /// Times the link was lost.
    pub link_losses: AtomicU64,
    /// True while a link is open.
    pub up: AtomicBool,
}

/// Wakes the pump when ethercrab queues a frame: unparks it, and makes its eventfd readable so
/// that a pump waiting for replies on the link's descriptor wakes too.
struct Wakeup {
    thread: Thread,
    eventfd: libc::c_int,
}

impl Wake for Wakeup {
    fn wake(self: Arc<Self>) {
        self.wake_by_ref();
    }
    fn wake_by_ref(self: &Arc<Self>) {
        let one = 1u64.to_ne_bytes();
        // SAFETY: writing 8 bytes to our own eventfd.
        unsafe {
            libc::write(self.eventfd, one.as_ptr().cast(), 8);
        }
        self.thread.unpark();
    }
}

impl Drop for Wakeup {
    fn drop(&mut self) {
        // SAFETY: we own the eventfd.
        unsafe {
            libc::close(self.eventfd);
        }
    }
}

fn clear(eventfd: libc::c_int) {
    let mut buf = [0u8; 8];
    // SAFETY: reading 8 bytes from our own non-blocking eventfd.
    unsafe {
        libc::read(eventfd, buf.as_mut_ptr().cast(), 8);
    }
}

/// A running pump; [`stop`](Pump::stop) returns the PDU handles for reuse.
pub struct Pump {
    thread: Option<JoinHandle<(PduTx<'static>, PduRx<'static>)>>,
    stop: Arc<AtomicBool>,
    /// Counters and link state.
    pub status: Arc<PumpStatus>,
}

impl Pump {
    /// Starts pumping between `tx`/`rx` and links made by `connect`.
    pub fn start(
        tx: PduTx<'static>,
        rx: PduRx<'static>,
        connect: Connect,
    ) -> std::io::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let status = Arc::new(PumpStatus::default());
        let thread = {
            let (stop, status) = (stop.clone(), status.clone());
            std::thread::Builder::new()
                .name("ecat-pump".into())
                .spawn(move || {
                    // Frames wait for this thread: it runs at the cycle's priority.
                    teleop_runtime::realtime::enter_realtime();
                    run(tx, rx, connect, &stop, &status)
                })?
        };
        Ok(Self {
            thread: Some(thread),
            stop,
            status,
        })
    }

    /// Stops the thread and returns the PDU handles.
    pub fn stop(mut self) -> Option<(PduTx<'static>, PduRx<'static>)> {
        self.stop.store(true, Ordering::SeqCst);
        let thread = self.thread.take()?;
        thread.thread().unpark();
        thread.join().ok()
    }
}

impl Drop for Pump {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

fn run(
    mut tx: PduTx<'static>,
    mut rx: PduRx<'static>,
    mut connect: Connect,
    stop: &AtomicBool,
    status: &PumpStatus,
) -> (PduTx<'static>, PduRx<'static>) {
    // SAFETY: plain eventfd creation; owned by `Wakeup`.
    let eventfd = unsafe { libc::eventfd(0, libc::EFD_NONBLOCK | libc::EFD_CLOEXEC) };
    let wakeup = Arc::new(Wakeup {
        thread: std::thread::current(),
        eventfd,
    });
    let waker = Waker::from(wakeup);
    let mut buf = vec![0u8; MAX_FRAME];
    let mut backoff = Duration::from_millis(20);
    let mut logged_down = false;
    while !stop.load(Ordering::SeqCst) && !tx.should_exit() {
        let mut link = match connect() {
            Ok(link) => {
                tracing::info!("EtherCAT link open");
                status.up.store(true, Ordering::SeqCst);
                backoff = Duration::from_millis(20);
                logged_down = false;
                link
            }
            Err(e) => {
                if !logged_down {
                    tracing::warn!("EtherCAT link unavailable: {e}; retrying");
                    logged_down = true;
                }
                std::thread::park_timeout(backoff);
                backoff = (backoff * 2).min(Duration::from_millis(500));
                continue;
            }
        };
        if let Err(e) = serve(
            &mut tx,
            &mut rx,
            link.as_mut(),
            &waker,
            eventfd,
            &mut buf,
            stop,
            status,
        ) {
            status.up.store(false, Ordering::SeqCst);
            status.link_losses.fetch_add(1, Ordering::Relaxed);
            tracing::warn!("EtherCAT link lost: {e}; reopening");
        }
    }
    status.up.store(false, Ordering::SeqCst);
    (tx.release(), rx.release())
}

/// Pumps until stop (Ok) or a link error.
#[allow(clippy::too_many_arguments)]
fn serve(
    tx: &mut PduTx<'static>,
    rx: &mut PduRx<'static>,
    link: &mut dyn FrameLink,
    waker: &Waker,
    eventfd: libc::c_int,
    buf: &mut [u8],
    stop: &AtomicBool,
    status: &PumpStatus,
) -> Result<(), LinkError> {
    while !stop.load(Ordering::SeqCst) && !tx.should_exit() {
        tx.replace_waker(waker);
        let mut link_error = None;
        while let Some(frame) = tx.next_sendable_frame() {
            let result = frame.send_blocking(|bytes| match link.send(bytes) {
                Ok(()) => Ok(bytes.len()),
                Err(e) => {
                    link_error = Some(e);
                    Err(ethercrab::error::Error::SendFrame)
                }
            });
            if result.is_ok() {
                status.sent.fetch_add(1, Ordering::Relaxed);
            }
            if let Some(e) = link_error.take() {
                return Err(e);
            }
        }
        // Hand over every reply that is already here.
        while let Some(n) = link.recv(buf, Duration::ZERO)? {
            status.received.fetch_add(1, Ordering::Relaxed);
            if let Err(e) = rx.receive_frame(&buf[..n]) {
                tracing::debug!("frame not taken by ethercrab: {e}");
            }
        }
        // Sleep until a reply arrives or ethercrab queues a frame (lost frames are ethercrab's
        // to time out and retry).
        match link.fd() {
            Some(fd) => {
                let ready =
                    teleop_ecat_link::wait_readable(&[fd, eventfd], Duration::from_millis(10))
                        .map_err(|e| LinkError::Down(e.to_string()))?;
                if ready & 2 != 0 {
                    clear(eventfd);
                }
            }
            None => std::thread::park_timeout(Duration::from_millis(2)),
        }
    }
    Ok(())
}
