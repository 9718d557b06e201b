//! Test support: an in-process transport between ethercrab's `PduTx`/`PduRx` and a simulated
//! SubDevice, a virtual clock, and a small test application (4 output bytes, 6 input bytes).

#![allow(dead_code)]

use core::future::{poll_fn, Future};
use core::task::Poll;
use core::time::Duration;
use ethercrab::{PduRx, PduTx};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use teleop_ecat_sim::{AlState, Application, EscConfig, Identity, SdoAbort, SubDevice};

/// A virtual clock shared by the test (which advances it) and the transport (which passes it
/// to the SubDevice as `now`). ethercrab's own timeouts use wall time.
#[derive(Debug, Clone, Default)]
pub struct Clock(Arc<AtomicU64>);

impl Clock {
    pub fn now(&self) -> Duration {
        Duration::from_nanos(self.0.load(Ordering::SeqCst))
    }

    pub fn advance(&self, by: Duration) {
        let nanos = u64::try_from(by.as_nanos()).expect("duration fits u64 nanoseconds");
        self.0.fetch_add(nanos, Ordering::SeqCst);
    }
}

pub type Shared<A> = Arc<Mutex<SubDevice<A>>>;

/// The transport: every frame ethercrab wants to send goes through the SubDevice, and the
/// SubDevice's reply (if any) goes back to ethercrab. Never completes.
///
/// The waker must be registered before looking for frames, so that a frame queued after the
/// look-up wakes this future again.
pub async fn pump<A: Application>(
    mut tx: PduTx<'static>,
    mut rx: PduRx<'static>,
    sim: Shared<A>,
    clock: Clock,
) {
    poll_fn(|cx| {
        tx.replace_waker(cx.waker());
        while let Some(frame) = tx.next_sendable_frame() {
            let mut reply = None;
            let sent = frame.send_blocking(|bytes| {
                let mut sd = sim.lock().expect("simulator lock");
                reply = sd.process_frame(bytes, clock.now());
                Ok(bytes.len())
            });
            sent.expect("in-process send cannot fail");
            if let Some(reply) = reply {
                // A reply to a frame ethercrab already gave up on is refused: ignore it.
                let _ = rx.receive_frame(&reply);
            }
        }
        Poll::<()>::Pending
    })
    .await
}

/// Runs `body` (the MainDevice side) and the transport on this thread until `body` is done.
pub fn run<A: Application, T>(
    tx: PduTx<'static>,
    rx: PduRx<'static>,
    sim: Shared<A>,
    clock: Clock,
    body: impl Future<Output = T>,
) -> T {
    futures_lite::future::block_on(futures_lite::future::or(body, async move {
        pump(tx, rx, sim, clock).await;
        unreachable!("the transport never completes")
    }))
}

pub const VENDOR: u32 = 0x00BC_0000;
pub const PRODUCT: u32 = 0x0000_9252;
pub const NAME: &str = "Test hand";
/// 0x8000:0x11, a 20-byte string.
pub const FIRMWARE: &[u8; 20] = b"fw 1.2.3 build 0042 ";
/// 0x8000:0x20, 150 bytes: more than a 128-byte mailbox carries, so uploaded in segments.
pub fn long_object() -> Vec<u8> {
    (0..150u8).collect()
}

pub fn config() -> EscConfig {
    EscConfig {
        identity: Identity {
            vendor_id: VENDOR,
            product_code: PRODUCT,
            revision: 1,
            serial: 0x0000_1234,
        },
        name: NAME.to_owned(),
        ..EscConfig::default()
    }
}

/// A small device: RxPDO 0x1600 (0x7000:01 u16, 0x7000:02 u16), TxPDO 0x1A00 (0x6000:01 u16,
/// 0x6000:02 u32), a few parameters in 0x2000, a string in 0x8000:0x11.
#[derive(Debug)]
pub struct TestApp {
    pub rx_assign: Vec<u16>,
    pub tx_assign: Vec<u16>,
    pub mappings: BTreeMap<u16, Vec<u32>>,
    pub p_u8: u8,
    pub p_u16: u16,
    pub p_u32: u32,
    /// Last outputs received (OP only).
    pub outputs: Vec<u8>,
    pub output_count: u32,
    /// Inputs reported to the MainDevice.
    pub inputs: [u8; 6],
    pub lost: u32,
}

impl Default for TestApp {
    fn default() -> Self {
        let mut mappings = BTreeMap::new();
        mappings.insert(0x1600, vec![0x7000_0110, 0x7000_0210]);
        mappings.insert(0x1A00, vec![0x6000_0110, 0x6000_0220]);
        Self {
            rx_assign: vec![0x1600],
            tx_assign: vec![0x1A00],
            mappings,
            p_u8: 0x11,
            p_u16: 0x2222,
            p_u32: 0x3333_3333,
            outputs: Vec::new(),
            output_count: 0,
            inputs: [1, 2, 3, 4, 5, 6],
            lost: 0,
        }
    }
}

impl TestApp {
    fn bits(&self, assign: &[u16]) -> Option<usize> {
        assign.iter().try_fold(0usize, |sum, pdo| {
            let entries = self.mappings.get(pdo)?;
            Some(sum + entries.iter().map(|e| (e & 0xFF) as usize).sum::<usize>())
        })
    }

    fn assignment(&mut self, index: u16) -> Option<&mut Vec<u16>> {
        match index {
            0x1C12 => Some(&mut self.rx_assign),
            0x1C13 => Some(&mut self.tx_assign),
            _ => None,
        }
    }
}

fn array_read<T: Copy>(
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

fn array_write<T: Copy + Default>(
    values: &mut Vec<T>,
    sub: u8,
    data: &[u8],
    parse: impl Fn(&[u8]) -> Option<T>,
) -> Result<(), SdoAbort> {
    if sub == 0 {
        let [n] = data else {
            return Err(SdoAbort::LENGTH_MISMATCH);
        };
        values.resize(usize::from(*n), T::default());
        return Ok(());
    }
    let v = parse(data).ok_or(SdoAbort::LENGTH_MISMATCH)?;
    let i = usize::from(sub) - 1;
    if i >= values.len() {
        values.resize(i + 1, T::default());
    }
    values[i] = v;
    Ok(())
}

impl Application for TestApp {
    fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, SdoAbort> {
        match index {
            0x1018 => array_read(&[VENDOR, PRODUCT, 1, 0x1234], sub, |v| {
                v.to_le_bytes().to_vec()
            }),
            0x1C00 => array_read(&[1u8, 2, 3, 4], sub, |v| vec![v]),
            0x1C12 => array_read(&self.rx_assign, sub, |v| v.to_le_bytes().to_vec()),
            0x1C13 => array_read(&self.tx_assign, sub, |v| v.to_le_bytes().to_vec()),
            0x1600 | 0x1A00 => {
                let m = self
                    .mappings
                    .get(&index)
                    .ok_or(SdoAbort::OBJECT_DOES_NOT_EXIST)?;
                array_read(m, sub, |v| v.to_le_bytes().to_vec())
            }
            0x2000 => match sub {
                0 => Ok(vec![3]),
                1 => Ok(vec![self.p_u8]),
                2 => Ok(self.p_u16.to_le_bytes().to_vec()),
                3 => Ok(self.p_u32.to_le_bytes().to_vec()),
                _ => Err(SdoAbort::SUBINDEX_DOES_NOT_EXIST),
            },
            0x8000 => match sub {
                0 => Ok(vec![0x20]),
                0x11 => Ok(FIRMWARE.to_vec()),
                0x20 => Ok(long_object()),
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
        match index {
            0x1C12 | 0x1C13 | 0x1600 | 0x1A00 if state != AlState::PreOp => Err(SdoAbort::STATE),
            0x1C12 | 0x1C13 => {
                let values = self
                    .assignment(index)
                    .ok_or(SdoAbort::OBJECT_DOES_NOT_EXIST)?;
                array_write(values, sub, data, |d| {
                    Some(u16::from_le_bytes(d.try_into().ok()?))
                })
            }
            0x1600 | 0x1A00 => {
                let values = self.mappings.entry(index).or_default();
                array_write(values, sub, data, |d| {
                    Some(u32::from_le_bytes(d.try_into().ok()?))
                })
            }
            0x2000 => match (sub, data) {
                (1, [v]) => {
                    self.p_u8 = *v;
                    Ok(())
                }
                (2, [a, b]) => {
                    self.p_u16 = u16::from_le_bytes([*a, *b]);
                    Ok(())
                }
                (3, [a, b, c, d]) => {
                    self.p_u32 = u32::from_le_bytes([*a, *b, *c, *d]);
                    Ok(())
                }
                (1..=3, _) => Err(SdoAbort::LENGTH_MISMATCH),
                (0, _) => Err(SdoAbort::READ_ONLY),
                _ => Err(SdoAbort::SUBINDEX_DOES_NOT_EXIST),
            },
            0x1018 | 0x1C00 | 0x8000 => Err(SdoAbort::READ_ONLY),
            _ => Err(SdoAbort::OBJECT_DOES_NOT_EXIST),
        }
    }

    fn process_image_sizes(&self) -> Result<(usize, usize), u16> {
        let outputs = self.bits(&self.rx_assign).ok_or(0x001D_u16)?;
        let inputs = self.bits(&self.tx_assign).ok_or(0x001E_u16)?;
        Ok((outputs.div_ceil(8), inputs.div_ceil(8)))
    }

    fn write_outputs(&mut self, outputs: &[u8], _now: Duration) {
        self.outputs = outputs.to_vec();
        self.output_count += 1;
    }

    fn read_inputs(&mut self, inputs: &mut [u8], _now: Duration) {
        let n = inputs.len().min(self.inputs.len());
        inputs[..n].copy_from_slice(&self.inputs[..n]);
    }

    fn outputs_lost(&mut self) {
        self.lost += 1;
    }
}

pub fn shared(app: TestApp) -> Shared<TestApp> {
    Arc::new(Mutex::new(SubDevice::new(config(), app)))
}
