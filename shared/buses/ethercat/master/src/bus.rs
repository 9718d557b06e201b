//! The EtherCAT bus: the MainDevice and what carries its frames (the frame pump over a
//! `teleop-ecat-link` link, or ethercrab's own raw-socket task), reopened after ethercrab's task
//! ended; the bus scan; and the AL acknowledge that ethercrab's typestate API does not do.

use std::future::Future;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Poll, Waker};
use std::thread::JoinHandle;
use std::time::Duration;

use ethercrab::subdevice_group::{Op, PreOp};
use ethercrab::{
    MainDevice, MainDeviceConfig, PduLoop, PduRx, PduStorage, PduTx, RegisterAddress,
    SubDeviceGroup, Timeouts,
};
use teleop_ecat_link::{FrameLink, LinkError, RawSocketLink, StreamLink};

use crate::pump::{Connect, Pump};
use crate::transport::Transport;

/// Most SubDevices on the bus.
pub const MAX_SUBDEVICES: usize = 4;
/// Process image bytes (outputs and inputs of every SubDevice together).
pub const MAX_PDI: usize = 256;
const MAX_FRAMES: usize = 16;
const FRAME_SIZE: usize = PduStorage::element_size(1100);

/// A group in PRE-OP.
pub type PreOpGroup = SubDeviceGroup<MAX_SUBDEVICES, MAX_PDI, ethercrab::DefaultLock, PreOp>;
/// A group in OP.
pub type OpGroup = SubDeviceGroup<MAX_SUBDEVICES, MAX_PDI, ethercrab::DefaultLock, Op>;

/// How a link is made for a transport.
///
/// `ethercrab:NAME` has no [`FrameLink`]: its connector only carries the interface name to
/// [`Bus::open`], which starts ethercrab's own task on it instead of a frame pump (called on its
/// own, the connector fails with a message saying so).
pub fn connector(transport: &Transport) -> Connect {
    match transport.clone() {
        Transport::Sim(path) => {
            Box::new(move || Ok(Box::new(StreamLink::connect(&path)?) as Box<dyn FrameLink>))
        }
        Transport::Interface(name) => Box::new(move || {
            Ok(
                Box::new(RawSocketLink::open(&name, teleop_ecat_link::Accept::All)?)
                    as Box<dyn FrameLink>,
            )
        }),
        Transport::EthercrabInterface(name) => Box::new(move || {
            Err(LinkError::Io {
                context: format!("transport ethercrab:{name}"),
                source: std::io::Error::other(UseEthercrabTask {
                    interface: name.clone(),
                }),
            })
        }),
    }
}

/// What the connector of `ethercrab:NAME` returns: a request to run ethercrab's own task on
/// `interface`, recognised by [`Bus::open`].
#[derive(Debug, thiserror::Error)]
#[error(
    "{interface} is driven by ethercrab's own raw-socket task, not a frame pump: open it with Bus::open"
)]
struct UseEthercrabTask {
    interface: String,
}

/// The MainDevice and what carries its frames: the node's frame pump (`sim:` and `interface:`
/// transports) or ethercrab's own raw-socket task (`ethercrab:`).
///
/// ethercrab's task ends for good on a send error (e.g. the interface going admin-down: ENETDOWN)
/// and on a reply it cannot match (one arriving after its PDU timed out, e.g. after a stall
/// longer than the 20 ms PDU timeout: "Failed to claim receiving frame"), and takes the bus's PDU
/// handles with it: [`link_alive`](Self::link_alive) then turns false and
/// [`current`](Self::current) opens a fresh bus once the interface is up. The pump ignores such
/// replies and reopens its socket instead.
pub struct Bus {
    /// The ethercrab MainDevice. Private: it borrows `_storage`, which this bus frees; a public
    /// field could be moved or swapped out of the bus and outlive it (see [`md`](Self::md)).
    md: MainDevice<'static>,
    /// The frame pump (link state and counters); `None` on the `ethercrab:` transport.
    pub pump: Option<Pump>,
    /// ethercrab's own task, on the `ethercrab:` transport.
    task: Option<EthercrabTask>,
    /// The latest bus opened by [`current`](Self::current) after a task ended (kept by the
    /// bus first opened; replacing it frees the one before once nobody uses it).
    latest: Mutex<Option<Arc<Bus>>>,
    /// The PDU storage the MainDevice and the frame carriers borrow: the last field, so that
    /// it is freed after them.
    _storage: Storage,
}

/// The PDU storages alive now (each bus has one; see [`Bus::live_storages`]).
static LIVE_STORAGES: AtomicUsize = AtomicUsize::new(0);

/// A bus's own PDU storage (ethercrab splits a storage only once, and its PDU handles cannot
/// be had back from a task that ended on an error), freed with the bus: a link that flaps for
/// hours does not grow the process.
struct Storage(NonNull<PduStorage<MAX_FRAMES, FRAME_SIZE>>);

// SAFETY: a PduStorage is made to be shared between threads (ethercrab's own storages are
// statics); this handle only frees it.
unsafe impl Send for Storage {}
// SAFETY: as above; the handle gives no access.
unsafe impl Sync for Storage {}

impl Storage {
    /// A fresh storage, split.
    fn split() -> anyhow::Result<(Self, PduTx<'static>, PduRx<'static>, PduLoop<'static>)> {
        let storage = Storage(NonNull::from(Box::leak(Box::new(PduStorage::new()))));
        LIVE_STORAGES.fetch_add(1, Ordering::SeqCst);
        // SAFETY: the storage lives until `Storage` is dropped, which the bus does after the
        // MainDevice and the pump or task holding these handles (its last field).
        let shared: &'static PduStorage<MAX_FRAMES, FRAME_SIZE> = unsafe { storage.0.as_ref() };
        let (tx, rx, pdu_loop) = shared
            .try_split()
            .map_err(|()| anyhow::anyhow!("PDU storage already in use"))?;
        Ok((storage, tx, rx, pdu_loop))
    }
}

impl Drop for Storage {
    fn drop(&mut self) {
        // SAFETY: made by `Box::leak` in `split`; everything borrowing it is gone (see there).
        drop(unsafe { Box::from_raw(self.0.as_ptr()) });
        LIVE_STORAGES.fetch_sub(1, Ordering::SeqCst);
    }
}

impl Bus {
    /// A MainDevice whose frames go through links made by `connect`. Each bus has its own PDU
    /// storage (ethercrab splits a storage only once), so a process may open several in turn.
    ///
    /// A connector made by [`connector`] for `ethercrab:NAME` opens the bus as
    /// [`open_ethercrab`](Self::open_ethercrab) does. For the others, `connect` is called once
    /// here (to tell which it is) and that first result goes to the pump as its first link.
    pub fn open(mut connect: Connect) -> anyhow::Result<Self> {
        let first = connect();
        if let Err(LinkError::Io { source, .. }) = &first {
            if let Some(request) = source
                .get_ref()
                .and_then(|e| e.downcast_ref::<UseEthercrabTask>())
            {
                return Self::open_ethercrab(&request.interface);
            }
        }
        let mut first = Some(first);
        let connect: Connect = Box::new(move || match first.take() {
            Some(link) => link,
            None => connect(),
        });
        let (storage, tx, rx, pdu_loop) = Storage::split()?;
        let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
        let pump = Pump::start(tx, rx, connect)?;
        Ok(Self {
            md,
            pump: Some(pump),
            task: None,
            latest: Mutex::new(None),
            _storage: storage,
        })
    }

    /// The bus for `transport`.
    pub fn open_transport(transport: &Transport) -> anyhow::Result<Self> {
        match transport {
            Transport::EthercrabInterface(name) => Self::open_ethercrab(name),
            other => Self::open(connector(other)),
        }
    }

    /// A MainDevice whose frames go through ethercrab's own raw-socket task
    /// (`ethercrab::std::tx_rx_task`, unmodified) on `interface`, run on a dedicated thread.
    /// Fails when the raw socket cannot be opened (no CAP_NET_RAW: the message says how to grant
    /// it; no such interface). An interface that is down opens, but the task then ends on its
    /// first send: see [`current`](Self::current).
    pub fn open_ethercrab(interface: &str) -> anyhow::Result<Self> {
        let (storage, tx, rx, pdu_loop) = Storage::split()?;
        let task = EthercrabTask::start(interface, tx, rx)?;
        let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
        Ok(Self {
            md,
            pump: None,
            task: Some(task),
            latest: Mutex::new(None),
            _storage: storage,
        })
    }

    /// The ethercrab MainDevice, borrowed from the bus: it cannot outlive the bus, whose PDU
    /// storage it uses (ethercrab's calls tie what they return to this borrow).
    ///
    /// ```
    /// fn main_device(bus: &teleop_ecat_master::Bus) -> &ethercrab::MainDevice<'static> {
    ///     bus.md()
    /// }
    /// ```
    ///
    /// It cannot be taken out of the bus (the field was public: swapped into another bus, or
    /// moved out, it used a storage freed with its own bus):
    ///
    /// ```compile_fail,E0616
    /// fn swap(a: &mut teleop_ecat_master::Bus, b: &mut teleop_ecat_master::Bus) {
    ///     std::mem::swap(&mut a.md, &mut b.md);
    /// }
    /// ```
    pub fn md(&self) -> &MainDevice<'static> {
        &self.md
    }

    /// True while frames can flow: on the pump's transports, while its link is open (the pump
    /// reopens a lost link by itself); on `ethercrab:`, while ethercrab's task runs (once it has
    /// ended this bus is lost for good: use [`current`](Self::current)).
    pub fn link_alive(&self) -> bool {
        match (&self.pump, &self.task) {
            (Some(pump), _) => pump.status.up.load(Ordering::SeqCst),
            (None, Some(task)) => !task.ended(),
            (None, None) => false,
        }
    }

    /// The PDU storages alive in this process: one per bus not yet dropped (a bus replaced
    /// by [`current`](Self::current) is dropped once nobody uses it).
    pub fn live_storages() -> usize {
        LIVE_STORAGES.load(Ordering::SeqCst)
    }

    /// The bus to use now. On `ethercrab:`, when the task of the latest bus has ended and the
    /// interface is up, this opens a fresh bus (its own PDU storage, MainDevice and task), keeps
    /// it as the latest in place of the one before (which is freed once nobody uses it), and
    /// returns it; later calls return it. Otherwise (the pump's transports, which reconnect by
    /// themselves; a live task; an interface still down; a failed reopen, which is logged) it
    /// returns the latest bus as it is. Groups made with an earlier bus must not be used with a
    /// later one: bring the device up again.
    pub fn current(&self) -> CurrentBus<'_> {
        let mut latest = self.latest.lock().unwrap_or_else(|e| e.into_inner());
        let bus = match latest.as_ref() {
            Some(bus) => CurrentBus::Reopened(bus.clone()),
            None => CurrentBus::First(self),
        };
        let Some(task) = &bus.task else {
            return bus;
        };
        if !task.ended() {
            return bus;
        }
        match interface_up(&task.interface) {
            Ok(true) => {}
            Ok(false) => {
                tracing::info!(
                    interface = %task.interface,
                    "interface down: ethercrab's task is reopened when it is up"
                );
                return bus;
            }
            Err(e) => {
                tracing::warn!(interface = %task.interface, "cannot read the interface state: {e}");
                return bus;
            }
        }
        match Bus::open_ethercrab(&task.interface) {
            Ok(fresh) => {
                tracing::info!(
                    interface = %task.interface,
                    "ethercrab's task had ended: opened a fresh bus"
                );
                let fresh = Arc::new(fresh);
                *latest = Some(fresh.clone());
                CurrentBus::Reopened(fresh)
            }
            Err(e) => {
                tracing::warn!("reopening the bus failed: {e:#}");
                bus
            }
        }
    }
}

/// The bus [`Bus::current`] picked; dereferences to it (`&current` is a `&Bus`).
#[derive(Clone)]
pub enum CurrentBus<'a> {
    /// The bus first opened.
    First(&'a Bus),
    /// A bus opened after ethercrab's task ended.
    Reopened(Arc<Bus>),
}

impl std::ops::Deref for CurrentBus<'_> {
    type Target = Bus;

    fn deref(&self) -> &Bus {
        match self {
            CurrentBus::First(bus) => bus,
            CurrentBus::Reopened(bus) => bus,
        }
    }
}

/// ethercrab's `tx_rx_task` on its own thread, raced against a stop signal so that dropping the
/// bus ends the thread.
struct EthercrabTask {
    interface: String,
    ended: Arc<AtomicBool>,
    stop: Arc<StopSignal>,
    thread: Option<JoinHandle<()>>,
}

impl EthercrabTask {
    fn start(interface: &str, tx: PduTx<'static>, rx: PduRx<'static>) -> anyhow::Result<Self> {
        let task =
            ethercrab::std::tx_rx_task(interface, tx, rx).map_err(|e| open_error(interface, &e))?;
        let ended = Arc::new(AtomicBool::new(false));
        let stop = Arc::new(StopSignal::default());
        let thread = {
            let (ended, stop, name) = (ended.clone(), stop.clone(), interface.to_string());
            std::thread::Builder::new()
                .name("ethercrab-txrx".into())
                .spawn(move || {
                    // Frames wait for this thread: it runs at the cycle's priority.
                    teleop_runtime::realtime::enter_realtime();
                    let outcome = futures_lite::future::block_on(futures_lite::future::or(
                        async { Some(task.await) },
                        async {
                            stop.wait().await;
                            None
                        },
                    ));
                    ended.store(true, Ordering::SeqCst);
                    match outcome {
                        Some(Ok(_)) => tracing::info!(interface = %name, "ethercrab's task exited"),
                        Some(Err(e)) => tracing::warn!(
                            interface = %name,
                            "ethercrab's task ended: {e}; the bus is lost until it is reopened"
                        ),
                        None => tracing::debug!(interface = %name, "ethercrab's task stopped"),
                    }
                })?
        };
        tracing::info!(interface, "ethercrab's raw-socket task running");
        Ok(Self {
            interface: interface.to_string(),
            ended,
            stop,
            thread: Some(thread),
        })
    }

    fn ended(&self) -> bool {
        self.ended.load(Ordering::SeqCst)
    }
}

impl Drop for EthercrabTask {
    fn drop(&mut self) {
        self.stop.raise();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// A one-shot stop for the task's thread.
#[derive(Default)]
struct StopSignal {
    raised: AtomicBool,
    waker: Mutex<Option<Waker>>,
}

impl StopSignal {
    fn raise(&self) {
        self.raised.store(true, Ordering::SeqCst);
        let waker = self.waker.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(w) = waker {
            w.wake();
        }
    }

    fn wait(&self) -> impl Future<Output = ()> + '_ {
        futures_lite::future::poll_fn(move |cx| {
            *self.waker.lock().unwrap_or_else(|e| e.into_inner()) = Some(cx.waker().clone());
            if self.raised.load(Ordering::SeqCst) {
                Poll::Ready(())
            } else {
                Poll::Pending
            }
        })
    }
}

/// A clear error for a raw socket ethercrab could not open.
fn open_error(interface: &str, e: &std::io::Error) -> anyhow::Error {
    if e.kind() == std::io::ErrorKind::PermissionDenied {
        let binary = std::env::current_exe()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|_| "<binary>".into());
        anyhow::anyhow!(
            "ethercrab's raw EtherCAT socket on {interface}: {e}; run as root or grant the \
             capability: sudo setcap cap_net_raw,cap_net_admin=eip <binary> (here: {binary})"
        )
    } else if e.raw_os_error() == Some(libc::ENODEV) {
        anyhow::anyhow!("ethercrab's raw EtherCAT socket: no network interface {interface:?} ({e})")
    } else {
        anyhow::anyhow!("ethercrab's raw EtherCAT socket on {interface}: {e}")
    }
}

/// Whether `interface` is administratively up (SIOCGIFFLAGS; no privileges needed).
fn interface_up(interface: &str) -> std::io::Result<bool> {
    let name = interface.as_bytes();
    if name.is_empty() || name.len() >= libc::IFNAMSIZ || name.contains(&0) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("bad interface name {interface:?}"),
        ));
    }
    // SAFETY: a plain datagram socket, closed below; `req` is a zeroed ifreq whose name is
    // NUL-terminated (checked length), valid for SIOCGIFFLAGS, which fills `ifru_flags`.
    unsafe {
        let fd = libc::socket(libc::AF_INET, libc::SOCK_DGRAM | libc::SOCK_CLOEXEC, 0);
        if fd < 0 {
            return Err(std::io::Error::last_os_error());
        }
        let mut req: libc::ifreq = core::mem::zeroed();
        for (d, s) in req.ifr_name.iter_mut().zip(name) {
            *d = *s as libc::c_char;
        }
        let rc = libc::ioctl(fd, libc::SIOCGIFFLAGS, &mut req);
        let result = if rc < 0 {
            Err(std::io::Error::last_os_error())
        } else {
            Ok(i32::from(req.ifr_ifru.ifru_flags) & libc::IFF_UP != 0)
        };
        libc::close(fd);
        result
    }
}

fn timeouts() -> Timeouts {
    Timeouts {
        pdu: Duration::from_millis(20),
        state_transition: Duration::from_secs(3),
        eeprom: Duration::from_millis(500),
        mailbox_echo: Duration::from_millis(500),
        mailbox_response: Duration::from_millis(1000),
        ..Timeouts::default()
    }
}

/// One SubDevice found by the bus scan, in bus order (what a driver's identity check sees).
#[derive(Debug, Clone, PartialEq)]
pub struct Found {
    /// Position on the bus (0 = first after the MainDevice); the index in the group.
    pub index: usize,
    /// Configured station address.
    pub address: u16,
    /// Vendor ID, product code, revision and serial number from the SII.
    pub identity: ethercrab::SubDeviceIdentity,
    /// The device name from the SII.
    pub name: String,
}

/// Scans the bus: every SubDevice in PRE-OP in one group, and what each is.
pub async fn scan(md: &MainDevice<'static>) -> anyhow::Result<(PreOpGroup, Vec<Found>)> {
    let group = md
        .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercrab::std::ethercat_now)
        .await
        .map_err(|e| anyhow::anyhow!("EtherCAT bus scan failed: {e}"))?;
    let found = group
        .iter(md)
        .enumerate()
        .map(|(index, sd)| Found {
            index,
            address: sd.configured_address(),
            identity: sd.identity(),
            name: sd.name().to_string(),
        })
        .collect();
    Ok((group, found))
}

/// How long [`recover_op`] waits for each step to show in the AL status (a firmware reads AL
/// control once per main loop).
const RECOVERY_STEP_TIMEOUT: Duration = Duration::from_millis(100);
/// AL control/status: the error (acknowledge) bit and the SAFE-OP and OP states.
const ERROR: u16 = 0x10;
const SAFE_OP: u16 = 0x04;
const OP: u16 = 0x08;

/// Recovers SubDevice `index` from an AL error (ethercrab does not do this by itself): writes
/// the acknowledge (SAFE-OP + error acknowledge), waits until the AL status shows the error
/// flag cleared, then requests OP and waits until it is in OP. A SubDevice firmware reads AL
/// control once per loop, so an OP request written right after the acknowledge would overwrite
/// it unread (the error stays, the request is ignored). Returns the AL status code the error
/// showed. Blocks the caller up to twice [`RECOVERY_STEP_TIMEOUT`].
pub async fn recover_op(
    md: &MainDevice<'static>,
    group: &OpGroup,
    index: usize,
) -> anyhow::Result<u16> {
    let sd = group.subdevice(md, index)?;
    let code = sd
        .register_read::<u16>(RegisterAddress::AlStatusCode)
        .await
        .unwrap_or(0);
    sd.register_write(RegisterAddress::AlControl, SAFE_OP | ERROR)
        .await?;
    wait_al_status(md, group, index, "the acknowledged error cleared", |s| {
        s & ERROR == 0
    })
    .await?;
    sd.register_write(RegisterAddress::AlControl, OP).await?;
    wait_al_status(md, group, index, "OP after the request", |s| {
        s & 0x0F == OP || s & ERROR != 0
    })
    .await?;
    Ok(code)
}

/// Polls the AL status of SubDevice `index` until `done` holds, up to
/// [`RECOVERY_STEP_TIMEOUT`]; the error names `what` was awaited.
async fn wait_al_status(
    md: &MainDevice<'static>,
    group: &OpGroup,
    index: usize,
    what: &str,
    done: fn(u16) -> bool,
) -> anyhow::Result<()> {
    let sd = group.subdevice(md, index)?;
    let start = std::time::Instant::now();
    loop {
        let status = sd.register_read::<u16>(RegisterAddress::AlStatus).await?;
        if done(status) {
            return Ok(());
        }
        if start.elapsed() > RECOVERY_STEP_TIMEOUT {
            anyhow::bail!(
                "SubDevice {index}: {what} not shown within {} ms (AL status {status:#06x})",
                RECOVERY_STEP_TIMEOUT.as_millis()
            );
        }
        std::thread::sleep(Duration::from_micros(200));
    }
}

/// The working counter a healthy cycle returns: the group's LRW counts, per SubDevice, 1 for its
/// inputs (the FMMU it is read through) and 2 for its outputs (written), and nothing for a
/// SubDevice without process data in that direction. ethercrab maps each direction of a
/// SubDevice through one FMMU, so this is what every ESC on the bus adds when it is in OP.
pub fn expected_wkc(md: &MainDevice<'static>, group: &OpGroup) -> u16 {
    group
        .iter(md)
        .map(|sd| {
            let io = sd.io_raw();
            u16::from(!io.inputs().is_empty()) + 2 * u16::from(!io.outputs().is_empty())
        })
        .sum()
}
