//! The EtherCAT bus with one Revo2 on it: the MainDevice and its frame pump, bring-up to OP
//! (identity check, configuration in PRE-OP with read-back, PDO assignment), and the AL
//! acknowledge that ethercrab's typestate API does not do.

use std::time::Duration;

use ethercrab::subdevice_group::{Op, PreOp};
use ethercrab::{
    MainDevice, MainDeviceConfig, PduStorage, RegisterAddress, SubDeviceGroup, Timeouts,
};
use teleop_ecat_link::{FrameLink, RawSocketLink, StreamLink};
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
    }
}

/// The MainDevice and the pump that carries its frames.
pub struct Bus {
    /// The ethercrab MainDevice.
    pub md: MainDevice<'static>,
    /// The frame pump (link state and counters).
    pub pump: Pump,
}

impl Bus {
    /// A MainDevice whose frames go through links made by `connect`. Each bus has its own PDU
    /// storage (ethercrab splits a storage only once), so a process may open several in turn.
    pub fn open(connect: Connect) -> anyhow::Result<Self> {
        let storage: &'static PduStorage<MAX_FRAMES, FRAME_SIZE> =
            Box::leak(Box::new(PduStorage::new()));
        let (tx, rx, pdu_loop) = storage
            .try_split()
            .map_err(|()| anyhow::anyhow!("PDU storage already in use"))?;
        let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
        let pump = Pump::start(tx, rx, connect)?;
        Ok(Self { md, pump })
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
