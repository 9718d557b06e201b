//! The EtherCAT bus with one Revo2 on it: the MainDevice and what carries its frames (the node's
//! frame pump, or ethercrab's own raw-socket task), bring-up to OP (identity check,
//! configuration in PRE-OP with read-back, PDO assignment), and the AL acknowledge that
//! ethercrab's typestate API does not do.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::task::{Poll, Waker};
use std::thread::JoinHandle;
use std::time::Duration;

use ethercrab::subdevice_group::{Op, PreOp};
use ethercrab::{
    MainDevice, MainDeviceConfig, PduLoop, PduRx, PduStorage, PduTx, RegisterAddress,
    SubDeviceGroup, Timeouts,
};
use teleop_ecat_link::{FrameLink, LinkError, RawSocketLink, StreamLink};
use teleop_revo2_protocol::{
    obj, UnitMode, JOINT_ONLY_TX_ASSIGNMENT, PRODUCT_CODE, REVISION, VENDOR_ID,
};

use crate::config::{Revo2Config, TactileSource, Transport};
use crate::pump::{Connect, Pump};

/// Most SubDevices on the bus we look at.
pub const MAX_SUBDEVICES: usize = 4;
/// Process image bytes.
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
    /// The ethercrab MainDevice.
    pub md: MainDevice<'static>,
    /// The frame pump (link state and counters); `None` on the `ethercrab:` transport.
    pub pump: Option<Pump>,
    /// ethercrab's own task, on the `ethercrab:` transport.
    task: Option<EthercrabTask>,
    /// The bus opened by [`current`](Self::current) after this one's task ended.
    successor: OnceLock<Box<Bus>>,
}

/// A fresh PDU storage, split. Each bus has its own (ethercrab splits a storage only once, and
/// its PDU handles cannot be had back from a task that ended on an error), leaked: a few KiB
/// per bus opened.
fn split_storage() -> anyhow::Result<(PduTx<'static>, PduRx<'static>, PduLoop<'static>)> {
    let storage: &'static PduStorage<MAX_FRAMES, FRAME_SIZE> =
        Box::leak(Box::new(PduStorage::new()));
    storage
        .try_split()
        .map_err(|()| anyhow::anyhow!("PDU storage already in use"))
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
        let (tx, rx, pdu_loop) = split_storage()?;
        let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
        let pump = Pump::start(tx, rx, connect)?;
        Ok(Self {
            md,
            pump: Some(pump),
            task: None,
            successor: OnceLock::new(),
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
        let (tx, rx, pdu_loop) = split_storage()?;
        let task = EthercrabTask::start(interface, tx, rx)?;
        let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
        Ok(Self {
            md,
            pump: None,
            task: Some(task),
            successor: OnceLock::new(),
        })
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

    /// The bus to use now. On `ethercrab:`, when the task of the latest bus has ended and the
    /// interface is up, this opens a fresh bus (its own PDU storage, MainDevice and task), keeps
    /// it as this bus's successor, and returns it; later calls return it (or its own successor).
    /// Otherwise (the pump's transports, which reconnect by themselves; a live task; an
    /// interface still down; a failed reopen, which is logged) it returns the latest bus as it
    /// is. Groups made with an earlier bus must not be used with a later one: bring the device
    /// up again.
    pub fn current(&self) -> CurrentBus<'_> {
        CurrentBus(self.latest())
    }

    fn latest(&self) -> &Bus {
        let mut bus = self;
        while let Some(next) = bus.successor.get() {
            bus = next;
        }
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
                let _ = bus.successor.set(Box::new(fresh));
                bus.successor.get().map_or(bus, |b| b)
            }
            Err(e) => {
                tracing::warn!("reopening the bus failed: {e:#}");
                bus
            }
        }
    }
}

/// The bus [`Bus::current`] picked; dereferences to it (`&current` is a `&Bus`).
pub struct CurrentBus<'a>(&'a Bus);

impl std::ops::Deref for CurrentBus<'_> {
    type Target = Bus;

    fn deref(&self) -> &Bus {
        self.0
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

/// What bring-up learned about the device.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DeviceInfo {
    /// Serial number in the identity.
    pub serial: u32,
    /// Control board firmware version (0x8000:11).
    pub control_fw: String,
    /// Control board serial number (0x8000:12).
    pub control_sn: String,
    /// Wrist board firmware version (0x8000:13).
    pub wrist_fw: String,
    /// Wrist board serial number (0x8000:14).
    pub wrist_sn: String,
    /// Unit mode in effect.
    pub unit_mode: u8,
    /// Input PDO assignment in effect.
    pub tx_assignment: Vec<u16>,
}

impl DeviceInfo {
    /// The unit mode as a type.
    pub fn units(&self) -> UnitMode {
        if self.unit_mode == 1 {
            UnitMode::Physical
        } else {
            UnitMode::Percent
        }
    }

    /// True when tactile data comes in the process data.
    pub fn tactile_in_pdo(&self) -> bool {
        self.tx_assignment.contains(&obj::TACTILE_TX_PDO)
    }
}

/// Finds the Revo2 and leaves it in PRE-OP with identity checked.
pub async fn discover(md: &MainDevice<'static>) -> anyhow::Result<PreOpGroup> {
    let group = md
        .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercrab::std::ethercat_now)
        .await
        .map_err(|e| anyhow::anyhow!("EtherCAT bus scan failed: {e}"))?;
    let sd = group.subdevice(md, 0).map_err(|_| {
        anyhow::anyhow!("no EtherCAT SubDevice on the bus: is the Revo2 connected and powered?")
    })?;
    let id = sd.identity();
    if id.vendor_id != VENDOR_ID || id.product_id != PRODUCT_CODE {
        anyhow::bail!(
            "the first SubDevice is not a Revo2: vendor {:#010x} product {:#010x} (\"{}\"), expected vendor {VENDOR_ID:#010x} product {PRODUCT_CODE:#010x}",
            id.vendor_id,
            id.product_id,
            sd.name()
        );
    }
    if id.revision != REVISION {
        tracing::warn!(
            revision = id.revision,
            expected = REVISION,
            "unexpected Revo2 revision; continuing"
        );
    }
    Ok(group)
}

/// Reads a string object.
pub async fn read_string(
    md: &MainDevice<'static>,
    group: &PreOpGroup,
    index: u16,
    sub: u8,
) -> anyhow::Result<String> {
    let sd = group.subdevice(md, 0)?;
    let s: heapless::String<64> = sd
        .sdo_read(index, sub)
        .await
        .map_err(|e| anyhow::anyhow!("SDO read {index:#06x}:{sub:#04x} failed: {e}"))?;
    Ok(s.trim_end_matches(['\0', ' ']).to_string())
}

/// Writes one configuration value and reads it back.
async fn write_checked<T>(
    md: &MainDevice<'static>,
    group: &PreOpGroup,
    sub: u8,
    value: T,
    name: &str,
) -> anyhow::Result<()>
where
    T: ethercrab::EtherCrabWireWrite
        + ethercrab::EtherCrabWireReadSized
        + PartialEq
        + Copy
        + core::fmt::Debug,
    T: ethercrab::EtherCrabWireSized,
{
    let sd = group.subdevice(md, 0)?;
    sd.sdo_write(obj::CONFIG, sub, value)
        .await
        .map_err(|e| anyhow::anyhow!("writing {name} (0x8000:{sub:#04x}) failed: {e}"))?;
    let back: T = sd
        .sdo_read(obj::CONFIG, sub)
        .await
        .map_err(|e| anyhow::anyhow!("reading back {name} (0x8000:{sub:#04x}) failed: {e}"))?;
    if back != value {
        anyhow::bail!("{name} (0x8000:{sub:#04x}) reads back {back:?} after writing {value:?}");
    }
    Ok(())
}

/// Applies the configuration in PRE-OP, logs versions and serial numbers, assigns the PDOs, and
/// goes to OP.
pub async fn bring_up(
    md: &MainDevice<'static>,
    config: &Revo2Config,
) -> anyhow::Result<(OpGroup, DeviceInfo)> {
    let group = discover(md).await?;
    let d = &config.device;
    for (name, sub, value) in [
        ("hand_type", 0x01u8, d.hand_type),
        ("led_switch", 0x02, d.led_switch),
        ("buzzer_switch", 0x03, d.buzzer_switch),
        ("vibrator_switch", 0x04, d.vibrator_switch),
        ("unit_mode", 0x05, d.unit_mode),
        ("auto_calibration", 0x07, d.auto_calibration),
        ("turbo_mode", 0x08, d.turbo_mode),
    ] {
        if let Some(v) = value {
            write_checked(md, &group, sub, v, name).await?;
        }
    }
    if let Some(currents) = d.protection_current_ma {
        for (j, c) in currents.iter().enumerate() {
            write_checked(md, &group, 0x0A + j as u8, *c, "protection current").await?;
        }
    }
    if let Some(c) = d.thumb_aux_lock_cur {
        write_checked(md, &group, 0x10, c, "thumb_aux_lock_cur").await?;
    }
    let sd = group.subdevice(md, 0)?;
    let mut info = DeviceInfo {
        serial: sd.identity().serial,
        unit_mode: sd.sdo_read::<u8>(obj::CONFIG, 0x05).await.unwrap_or(0),
        ..Default::default()
    };
    info.control_fw = read_string(md, &group, obj::CONFIG, 0x11).await?;
    info.control_sn = read_string(md, &group, obj::CONFIG, 0x12).await?;
    info.wrist_fw = read_string(md, &group, obj::CONFIG, 0x13).await?;
    info.wrist_sn = read_string(md, &group, obj::CONFIG, 0x14).await?;
    tracing::info!(
        serial = info.serial,
        control_fw = %info.control_fw,
        control_sn = %info.control_sn,
        wrist_fw = %info.wrist_fw,
        wrist_sn = %info.wrist_sn,
        "Revo2 found"
    );
    // Inputs: joint data, plus tactile data when it is to come in the process data.
    let wanted: &[u16] = match config.tactile {
        TactileSource::Pdo => &[obj::JOINT_TX_PDO, obj::TACTILE_TX_PDO],
        _ => &JOINT_ONLY_TX_ASSIGNMENT,
    };
    let assigned = match sd.sdo_write_array(obj::SM3_ASSIGN, wanted).await {
        Ok(()) => wanted.to_vec(),
        Err(e) if config.tactile == TactileSource::Pdo => {
            tracing::warn!("the device refused tactile data in the process data ({e}); polling 0x6010 by SDO instead");
            sd.sdo_write_array(obj::SM3_ASSIGN, &JOINT_ONLY_TX_ASSIGNMENT)
                .await
                .map_err(|e| anyhow::anyhow!("assigning the joint TxPDO failed: {e}"))?;
            JOINT_ONLY_TX_ASSIGNMENT.to_vec()
        }
        Err(e) => anyhow::bail!("assigning the input PDOs failed: {e}"),
    };
    info.tx_assignment = assigned;
    let group = group
        .into_op(md)
        .await
        .map_err(|e| anyhow::anyhow!("PRE-OP -> OP failed: {e}"))?;
    Ok((group, info))
}

/// Acknowledges an AL error and requests OP again (ethercrab does not do this by itself).
pub async fn recover_op(md: &MainDevice<'static>, group: &OpGroup) -> anyhow::Result<u16> {
    let sd = group.subdevice(md, 0)?;
    let code = sd
        .register_read::<u16>(RegisterAddress::AlStatusCode)
        .await
        .unwrap_or(0);
    sd.register_write(RegisterAddress::AlControl, 0x0014u16)
        .await?;
    sd.register_write(RegisterAddress::AlControl, 0x0008u16)
        .await?;
    Ok(code)
}
