//! The Revo2 as a `teleop-ecat-master` driver: identity, configuration in PRE-OP, hand command
//! -> outputs, inputs -> joint and tactile data, the hold, and tactile data polled by SDO when
//! it is not in the process data.

use std::time::Duration;

use ethercrab::MainDevice;
use futures_lite::future::block_on;
use teleop_ecat_master::{Driver, Found, Image, OpGroup, PreOpGroup};
use teleop_msgs::HandCommand;
use teleop_revo2_protocol::{obj, Inputs, TactileData, JOINTS};

use crate::bus::{check_identity, configure, DeviceInfo};
use crate::config::{Revo2Config, TactileSource};
use crate::convert::{hold_outputs, hold_speeds, outputs_for, position_targets};

/// The Revo2's process data is the first SubDevice's.
const REVO2: usize = 0;

/// The Revo2 driver: its configuration, what bring-up learned about the device, and the last
/// commanded position targets (what the hand holds when it has no command).
#[derive(Debug, Clone)]
pub struct Revo2 {
    config: Revo2Config,
    info: DeviceInfo,
    /// Position targets of the latest command packed since bring-up, in the device's units;
    /// `None` before the first or after a command of another mode.
    target: Option<[i16; JOINTS]>,
}

impl Revo2 {
    /// A driver for a Revo2 configured by `config` (checked by [`Revo2Config::validate`]).
    pub fn new(config: Revo2Config) -> Self {
        Self {
            config,
            info: DeviceInfo::default(),
            target: None,
        }
    }

    /// The node configuration.
    pub fn config(&self) -> &Revo2Config {
        &self.config
    }

    /// What the latest bring-up learned (default before the first).
    pub fn info(&self) -> &DeviceInfo {
        &self.info
    }

    /// What the latest bring-up learned, taken.
    pub fn into_info(self) -> DeviceInfo {
        self.info
    }
}

impl Driver for Revo2 {
    type Command = HandCommand;
    type Inputs = Inputs;
    type Polled = TactileData;

    fn name(&self) -> &str {
        "Revo2"
    }

    fn identify(&self, found: &[Found]) -> anyhow::Result<()> {
        check_identity(found)
    }

    async fn configure(
        &mut self,
        md: &MainDevice<'static>,
        group: &PreOpGroup,
    ) -> anyhow::Result<()> {
        self.info = configure(md, group, &self.config).await?;
        // A device brought up (again) holds where it is until it is commanded.
        self.target = None;
        Ok(())
    }

    fn pack(&mut self, command: &HandCommand, outputs: &mut Image) -> bool {
        let Some(out) = outputs_for(command, &self.config, self.info.units()) else {
            return false;
        };
        self.target = position_targets(&out);
        let _ = out.pack(outputs.subdevice_mut(REVO2));
        true
    }

    fn unpack(&mut self, inputs: &Image, polled: Option<&TactileData>) -> Option<Inputs> {
        let mut decoded = Inputs::unpack(inputs.subdevice(REVO2), &self.info.tx_assignment).ok()?;
        if self.poll_period().is_some() {
            decoded.tactile = polled.copied();
        }
        Some(decoded)
    }

    /// Holds the last commanded position targets (a grasp keeps its squeeze), or the measured
    /// position when none was commanded, at the configured hold speed.
    fn hold(&mut self, last: Option<&Inputs>, outputs: &mut Image) {
        let Some(last) = last else {
            return; // called with none only for drivers that hold every cycle
        };
        let speeds = hold_speeds(&self.config, self.info.units());
        let out = hold_outputs(self.target.as_ref(), &last.joints, &speeds);
        let _ = out.pack(outputs.subdevice_mut(REVO2));
    }

    /// Tactile data by SDO (0x6010) at `tactile_poll_hz` when it is not in the process data.
    fn poll_period(&self) -> Option<Duration> {
        (!self.info.tactile_in_pdo() && self.config.tactile != TactileSource::Off)
            .then(|| Duration::from_secs_f64(1.0 / self.config.tactile_poll_hz))
    }

    fn poll(md: &MainDevice<'static>, group: &OpGroup) -> anyhow::Result<TactileData> {
        block_on(read_tactile(md, group))
    }
}

async fn read_tactile(md: &MainDevice<'static>, group: &OpGroup) -> anyhow::Result<TactileData> {
    let sd = group.subdevice(md, REVO2)?;
    let mut raw = [0u8; 60];
    let mut at = 0;
    for (sub, len) in [(1u8, 10usize), (2, 10), (3, 10), (4, 20), (5, 10)] {
        // `[u16; N]` reads are broken in ethercrab 0.7 (buffer sized N bytes): read bytes.
        let v: heapless::Vec<u8, 32> = sd.sdo_read(obj::TACTILE_INPUTS, sub).await?;
        if v.len() != len {
            anyhow::bail!("0x6010:{sub:02} has {} bytes, expected {len}", v.len());
        }
        raw[at..at + len].copy_from_slice(&v);
        at += len;
    }
    Ok(TactileData::unpack(&raw)?)
}
