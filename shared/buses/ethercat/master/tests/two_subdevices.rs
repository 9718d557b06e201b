//! The master layer with something other than the Revo2: a bus of two emulated SubDevices
//! (`teleop-ecat-sim`) in this process, as the Shadow Hand has them: a bridge without process
//! data (its mailbox only) and a "palm" with outputs and inputs, driven by a tiny test driver.
//! Each test has its own emulators, in-process link and bus (no sockets, no privileges).
#![allow(clippy::unwrap_used, missing_docs)]

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use ethercrab::MainDevice;
use futures_lite::future::block_on;
use teleop_ecat_link::{FrameLink, InProcessLink};
use teleop_ecat_master::{
    bring_up, expected_wkc, Bus, Counters, Driver, Event, Exchange, Found, Host, Image, OpGroup,
    PreOpGroup, Settings, WrongDevice,
};
use teleop_ecat_sim::{AlState, Application, EscConfig, Identity, SdoAbort, SubDevice};

const VENDOR: u32 = 0x0000_0530;
const BRIDGE: u32 = 0x0000_0b01;
const PALM: u32 = 0x0000_0b02;

/// Palm output modes (second output word).
const FOLLOW: u16 = 1;
const HOLD: u16 = 2;

/// A CoE SubDevice with an optional RxPDO 0x1600 (two u16: target, mode) and TxPDO 0x1A00 (two
/// u16: position, last mode), and a parameter 0x2000:01 (u16). Its "joint" goes to the target
/// at once.
#[derive(Debug, Default)]
struct Board {
    rx_assign: Vec<u16>,
    tx_assign: Vec<u16>,
    mappings: BTreeMap<u16, Vec<u32>>,
    parameter: u16,
    /// Last outputs (target, mode) received in OP.
    outputs: Option<(u16, u16)>,
    position: u16,
}

impl Board {
    fn bridge() -> Self {
        Self {
            parameter: 0x0B0B,
            ..Default::default()
        }
    }

    fn palm() -> Self {
        let mut mappings = BTreeMap::new();
        mappings.insert(0x1600, vec![0x7000_0110, 0x7000_0210]);
        mappings.insert(0x1A00, vec![0x6000_0110, 0x6000_0210]);
        Self {
            mappings,
            ..Default::default()
        }
    }

    fn bytes(&self, assign: &[u16]) -> Option<usize> {
        let bits = assign.iter().try_fold(0usize, |sum, pdo| {
            let entries = self.mappings.get(pdo)?;
            Some(sum + entries.iter().map(|e| (e & 0xFF) as usize).sum::<usize>())
        })?;
        Some(bits.div_ceil(8))
    }
}

fn array<T: Copy>(
    values: &[T],
    sub: u8,
    bytes: impl Fn(T) -> Vec<u8>,
) -> Result<Vec<u8>, SdoAbort> {
    match sub {
        0 => Ok(vec![values.len() as u8]),
        n => values
            .get(usize::from(n) - 1)
            .map(|v| bytes(*v))
            .ok_or(SdoAbort::SUBINDEX_DOES_NOT_EXIST),
    }
}

impl Application for Board {
    fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, SdoAbort> {
        match index {
            0x1C12 => array(&self.rx_assign, sub, |v| v.to_le_bytes().to_vec()),
            0x1C13 => array(&self.tx_assign, sub, |v| v.to_le_bytes().to_vec()),
            0x1600 | 0x1A00 => {
                let m = self
                    .mappings
                    .get(&index)
                    .ok_or(SdoAbort::OBJECT_DOES_NOT_EXIST)?;
                array(m, sub, |v| v.to_le_bytes().to_vec())
            }
            0x2000 => match sub {
                0 => Ok(vec![1]),
                1 => Ok(self.parameter.to_le_bytes().to_vec()),
                _ => Err(SdoAbort::SUBINDEX_DOES_NOT_EXIST),
            },
            _ => Err(SdoAbort::OBJECT_DOES_NOT_EXIST),
        }
    }

    fn sdo_write(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        state: AlState,
    ) -> Result<(), SdoAbort> {
        match (index, sub, data) {
            (0x1C12 | 0x1C13, _, _) if state != AlState::PreOp => Err(SdoAbort::STATE),
            (0x1C12 | 0x1C13, 0, [n]) => {
                let assign = if index == 0x1C12 {
                    &mut self.rx_assign
                } else {
                    &mut self.tx_assign
                };
                assign.resize(usize::from(*n), 0);
                Ok(())
            }
            (0x1C12 | 0x1C13, n, [a, b]) => {
                let pdo = u16::from_le_bytes([*a, *b]);
                if !self.mappings.contains_key(&pdo) {
                    return Err(SdoAbort::VALUE_RANGE);
                }
                let assign = if index == 0x1C12 {
                    &mut self.rx_assign
                } else {
                    &mut self.tx_assign
                };
                // Sub-index 0 is set to 0 first, then the entries, then the count.
                let i = usize::from(n) - 1;
                if i >= assign.len() {
                    assign.resize(i + 1, 0);
                }
                let slot = &mut assign[i];
                *slot = pdo;
                Ok(())
            }
            (0x2000, 1, [a, b]) => {
                self.parameter = u16::from_le_bytes([*a, *b]);
                Ok(())
            }
            (0x1C12 | 0x1C13 | 0x2000, _, _) => Err(SdoAbort::LENGTH_MISMATCH),
            _ => Err(SdoAbort::OBJECT_DOES_NOT_EXIST),
        }
    }

    fn process_image_sizes(&self) -> Result<(usize, usize), u16> {
        let outputs = self.bytes(&self.rx_assign).ok_or(0x001D_u16)?;
        let inputs = self.bytes(&self.tx_assign).ok_or(0x001E_u16)?;
        Ok((outputs, inputs))
    }

    fn write_outputs(&mut self, outputs: &[u8], _now: Duration) {
        if let [t0, t1, m0, m1, ..] = outputs {
            let target = u16::from_le_bytes([*t0, *t1]);
            self.outputs = Some((target, u16::from_le_bytes([*m0, *m1])));
            self.position = target;
        }
    }

    fn read_inputs(&mut self, inputs: &mut [u8], _now: Duration) {
        let mode = self.outputs.map_or(0, |(_, m)| m);
        for (dst, src) in inputs.iter_mut().zip(
            self.position
                .to_le_bytes()
                .into_iter()
                .chain(mode.to_le_bytes()),
        ) {
            *dst = src;
        }
    }
}

type Sim = Arc<Mutex<SubDevice<Board>>>;

fn lock(sim: &Sim) -> MutexGuard<'_, SubDevice<Board>> {
    sim.lock().unwrap_or_else(|e| e.into_inner())
}

fn esc(product_code: u32, name: &str, mac: u8, port1_linked: bool) -> EscConfig {
    EscConfig {
        identity: Identity {
            vendor_id: VENDOR,
            product_code,
            revision: 1,
            serial: u32::from(mac),
        },
        name: name.into(),
        mac: [0x02, 0, 0, 0, 0xec, mac],
        port1_linked,
        ..EscConfig::default()
    }
}

/// The bridge (first on the bus) and the palm behind it.
struct Rig {
    bridge: Sim,
    palm: Sim,
    bus: Bus,
}

impl Rig {
    fn new(palm_product: u32) -> Self {
        let bridge: Sim = Arc::new(Mutex::new(SubDevice::new(
            esc(BRIDGE, "test bridge", 1, true),
            Board::bridge(),
        )));
        let palm: Sim = Arc::new(Mutex::new(SubDevice::new(
            esc(palm_product, "test palm", 2, false),
            Board::palm(),
        )));
        let start = Instant::now();
        let (b, p) = (bridge.clone(), palm.clone());
        let bus = Bus::open(Box::new(move || {
            let (b, p) = (b.clone(), p.clone());
            Ok(Box::new(InProcessLink::new(move |frame: &[u8]| {
                let now = start.elapsed();
                let through_bridge = lock(&b).process_frame(frame, now)?;
                lock(&p).process_frame(&through_bridge, now)
            })) as Box<dyn FrameLink>)
        }))
        .unwrap();
        Self { bridge, palm, bus }
    }
}

/// What the test driver decodes from the palm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct PalmInputs {
    position: u16,
    mode: u16,
    /// The bridge's parameter, read by the side channel.
    bridge_parameter: Option<u16>,
}

/// The test driver: the bridge at 0 (no process data), the palm at 1.
struct Gripper {
    /// Whether the palm's outputs are assigned (without, it only has inputs).
    outputs: bool,
    /// Written to the palm's 0x2000:01 in PRE-OP.
    parameter: u16,
}

impl Driver for Gripper {
    type Command = u16;
    type Inputs = PalmInputs;
    type Polled = u16;

    fn name(&self) -> &str {
        "test gripper"
    }

    fn identify(&self, found: &[Found]) -> anyhow::Result<()> {
        let expected = [BRIDGE, PALM];
        if found.len() != expected.len() {
            anyhow::bail!(
                "{} SubDevices on the bus, expected a bridge and a palm",
                found.len()
            );
        }
        for (f, product) in found.iter().zip(expected) {
            if f.identity.vendor_id != VENDOR || f.identity.product_id != product {
                anyhow::bail!(
                    "SubDevice {} is not the gripper's: vendor {:#010x} product {:#010x} (\"{}\")",
                    f.index,
                    f.identity.vendor_id,
                    f.identity.product_id,
                    f.name
                );
            }
        }
        Ok(())
    }

    async fn configure(
        &mut self,
        md: &MainDevice<'static>,
        group: &PreOpGroup,
    ) -> anyhow::Result<()> {
        let palm = group.subdevice(md, 1)?;
        palm.sdo_write(0x2000, 1, self.parameter).await?;
        let rx: &[u16] = if self.outputs { &[0x1600] } else { &[] };
        palm.sdo_write_array(0x1C12, rx).await?;
        palm.sdo_write_array(0x1C13, &[0x1A00u16]).await?;
        Ok(())
    }

    fn pack(&mut self, command: &u16, outputs: &mut Image) -> bool {
        let out = outputs.subdevice_mut(1);
        if out.len() < 4 {
            return false;
        }
        out[..2].copy_from_slice(&(*command).min(1000).to_le_bytes());
        out[2..4].copy_from_slice(&FOLLOW.to_le_bytes());
        true
    }

    fn unpack(&mut self, inputs: &Image, polled: Option<&u16>) -> Option<PalmInputs> {
        let [p0, p1, m0, m1] = *inputs.subdevice(1) else {
            return None;
        };
        Some(PalmInputs {
            position: u16::from_le_bytes([p0, p1]),
            mode: u16::from_le_bytes([m0, m1]),
            bridge_parameter: polled.copied(),
        })
    }

    fn hold(&mut self, last: Option<&PalmInputs>, outputs: &mut Image) {
        let Some(last) = last else { return };
        if let Some(out) = outputs.subdevice_mut(1).get_mut(..4) {
            out[..2].copy_from_slice(&last.position.to_le_bytes());
            out[2..].copy_from_slice(&HOLD.to_le_bytes());
        }
    }

    fn poll_period(&self) -> Option<Duration> {
        Some(Duration::from_millis(10))
    }

    fn poll(md: &MainDevice<'static>, group: &OpGroup) -> anyhow::Result<u16> {
        let bridge = group.subdevice(md, 0)?;
        Ok(block_on(bridge.sdo_read::<u16>(0x2000, 1))?)
    }
}

#[test]
fn the_expected_working_counter_comes_from_the_subdevices_process_data() {
    for (outputs, expected) in [(true, 3u16), (false, 1)] {
        let rig = Rig::new(PALM);
        let mut driver = Gripper {
            outputs,
            parameter: 7,
        };
        let group = block_on(bring_up(rig.bus.md(), &mut driver)).unwrap();
        assert_eq!(group.len(), 2);
        let bridge = group.subdevice(rig.bus.md(), 0).unwrap();
        assert!(bridge.io_raw().inputs().is_empty() && bridge.io_raw().outputs().is_empty());
        assert_eq!(
            expected_wkc(rig.bus.md(), &group),
            expected,
            "palm outputs: {outputs}"
        );
        let mut good = 0;
        for _ in 0..20 {
            if let Ok(r) = block_on(group.tx_rx(rig.bus.md())) {
                assert_eq!(r.working_counter, expected, "palm outputs: {outputs}");
                good += 1;
            }
        }
        assert!(good > 0, "no exchange answered");
        assert_eq!(lock(&rig.bridge).al_state(), (AlState::Op, false, 0));
        assert_eq!(lock(&rig.palm).al_state(), (AlState::Op, false, 0));
        assert_eq!(lock(&rig.palm).app().parameter, 7, "configured in PRE-OP");
    }
}

#[test]
fn a_foreign_subdevice_is_refused_by_name() {
    let rig = Rig::new(0x0000_0bad);
    let mut driver = Gripper {
        outputs: true,
        parameter: 0,
    };
    let err = block_on(bring_up(rig.bus.md(), &mut driver)).err().unwrap();
    assert!(
        err.is::<WrongDevice>(),
        "a wrong device is its own error, not a lost link: {err:#}"
    );
    let err = err.to_string();
    assert!(
        err.contains("SubDevice 1") && err.contains("0x00000bad") && err.contains("test palm"),
        "{err}"
    );
    assert_eq!(
        lock(&rig.palm).al_state().0,
        AlState::PreOp,
        "not taken to OP"
    );
}

/// What the test host saw.
#[derive(Debug, Default)]
struct Seen {
    connected: u32,
    link_down: u32,
    recovered: u32,
    lost: u32,
    last: Option<(PalmInputs, Exchange)>,
}

/// Commands from the test (`None`: hold), everything seen kept for it.
#[derive(Clone, Default)]
struct TestHost {
    stop: Arc<AtomicBool>,
    command: Arc<Mutex<Option<u16>>>,
    seen: Arc<Mutex<Seen>>,
}

impl TestHost {
    fn seen(&self) -> MutexGuard<'_, Seen> {
        self.seen.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn command(&self, c: Option<u16>) {
        *self.command.lock().unwrap() = c;
    }
}

impl Host<Gripper> for TestHost {
    fn stop_requested(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }

    fn command(&mut self) -> Option<u16> {
        *self.command.lock().unwrap()
    }

    fn connected(&mut self, _driver: &Gripper) {
        self.seen().connected += 1;
    }

    fn exchanged(
        &mut self,
        _driver: &Gripper,
        inputs: &PalmInputs,
        exchange: &Exchange,
    ) -> anyhow::Result<()> {
        self.seen().last = Some((*inputs, *exchange));
        Ok(())
    }

    fn event(&mut self, event: Event) {
        match event {
            Event::Lost => self.seen().lost += 1,
            Event::Recovered => self.seen().recovered += 1,
            Event::Refused => {}
        }
    }

    fn link_down(&mut self, _counters: &Counters) -> anyhow::Result<()> {
        self.seen().link_down += 1;
        Ok(())
    }
}

/// Waits (up to 10 s) until `ok` holds for what the host saw.
fn wait(host: &TestHost, what: &str, ok: impl Fn(&Seen) -> bool) {
    let start = Instant::now();
    while !ok(&host.seen()) {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "timed out waiting for {what}: {:?}",
            host.seen()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn commands_followed_stale_holds_al_error_recovered_lost_link_brought_up_again() {
    let rig = Rig::new(PALM);
    let (bridge, palm) = (rig.bridge.clone(), rig.palm.clone());
    let host = TestHost::default();
    host.command(Some(400));
    let runner = {
        let mut host = host.clone();
        std::thread::spawn(move || {
            let mut driver = Gripper {
                outputs: true,
                parameter: 1,
            };
            let settings = Settings {
                period: Duration::from_millis(2),
                link_timeout: Duration::from_millis(100),
            };
            teleop_ecat_master::run(&rig.bus, &mut driver, &mut host, &settings)
        })
    };
    // OP, following the command; the side channel reads the bridge.
    wait(&host, "the command followed", |s| {
        s.last.is_some_and(|(i, e)| {
            i.position == 400
                && i.mode == FOLLOW
                && !e.holding
                && i.bridge_parameter == Some(0x0B0B)
        })
    });
    assert_eq!(host.seen().connected, 1);
    assert_eq!(lock(&bridge).al_state(), (AlState::Op, false, 0));
    host.command(Some(1500));
    wait(&host, "the clamped command followed", |s| {
        s.last.is_some_and(|(i, _)| i.position == 1000)
    });

    // Stale: the driver's hold goes out, at the last position.
    host.command(None);
    wait(&host, "holding", |s| {
        s.last
            .is_some_and(|(i, e)| e.holding && i.mode == HOLD && i.position == 1000)
    });
    assert_eq!(lock(&palm).app().outputs, Some((1000, HOLD)));

    // The palm's watchdog drops it to SAFE-OP: acknowledged, OP again, and the command followed.
    host.command(Some(300));
    wait(&host, "following again", |s| {
        s.last.is_some_and(|(i, e)| i.position == 300 && !e.holding)
    });
    lock(&palm).trip_watchdog();
    wait(&host, "the palm recovered", |s| {
        s.recovered == 1
            && s.last
                .is_some_and(|(i, e)| i.position == 300 && e.counters.recoveries == 1)
    });
    assert_eq!(lock(&palm).al_state(), (AlState::Op, false, 0));
    // A wrong working counter (the palm miscounts) is counted and its inputs ignored.
    let before = host.seen().last.unwrap().1.counters.wkc_errors;
    lock(&palm).faults().wrong_wkc_probability = 0.3;
    wait(&host, "wrong working counters counted", |s| {
        s.last.is_some_and(|(_, e)| e.counters.wkc_errors > before)
    });
    lock(&palm).faults().wrong_wkc_probability = 0.0;

    // Fresh again, then the palm stops answering (every frame is lost behind the bridge): the
    // link is reported down, and the bus brought up again once the palm is back.
    host.command(Some(250));
    wait(&host, "following again", |s| {
        s.last.is_some_and(|(i, e)| i.position == 250 && !e.holding)
    });
    assert_eq!(host.seen().link_down, 0);
    lock(&palm).faults().link_down = true;
    wait(&host, "the link reported down", |s| {
        s.lost == 1 && s.link_down >= 1
    });
    let lost_frames = host.seen().last.unwrap().1.counters.lost_frames;
    lock(&palm).faults().link_down = false;
    wait(&host, "OP again", |s| s.connected == 2);
    host.command(Some(600));
    wait(&host, "following after the bring-up", |s| {
        s.last.is_some_and(|(i, e)| {
            i.position == 600 && !e.holding && e.counters.lost_frames > lost_frames
        })
    });
    assert_eq!(lock(&palm).al_state(), (AlState::Op, false, 0));

    // Stop: the hold goes out, then both leave OP.
    host.stop.store(true, Ordering::SeqCst);
    runner.join().unwrap().unwrap();
    assert_eq!(lock(&palm).app().outputs, Some((600, HOLD)));
    assert_eq!(lock(&palm).al_state().0, AlState::Init);
    assert_eq!(lock(&bridge).al_state().0, AlState::Init);
}
