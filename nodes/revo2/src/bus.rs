//! The Revo2 on the bus (on `teleop-ecat-master`'s bus and bring-up): the identity check,
//! configuration in PRE-OP with read-back, the PDO assignment (with an SDO-polling fallback for
//! tactile data), and the string reads `teleop revo2` and the firmware upgrade use too.

use ethercrab::MainDevice;
use teleop_ecat_master::Found;
pub use teleop_ecat_master::{connector, Bus, OpGroup, PreOpGroup};
use teleop_revo2_protocol::{
    obj, UnitMode, JOINT_ONLY_TX_ASSIGNMENT, PRODUCT_CODE, REVISION, VENDOR_ID,
};

use crate::config::{Revo2Config, TactileSource};

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

/// Checks that the first SubDevice on the bus is a Revo2 (the process data is its).
pub fn check_identity(found: &[Found]) -> anyhow::Result<()> {
    let Some(first) = found.first() else {
        anyhow::bail!("no EtherCAT SubDevice on the bus: is the Revo2 connected and powered?");
    };
    let id = &first.identity;
    if id.vendor_id != VENDOR_ID || id.product_id != PRODUCT_CODE {
        anyhow::bail!(
            "the first SubDevice is not a Revo2: vendor {:#010x} product {:#010x} (\"{}\"), expected vendor {VENDOR_ID:#010x} product {PRODUCT_CODE:#010x}",
            id.vendor_id,
            id.product_id,
            first.name
        );
    }
    if id.revision != REVISION {
        tracing::warn!(
            revision = id.revision,
            expected = REVISION,
            "unexpected Revo2 revision; continuing"
        );
    }
    Ok(())
}

/// Finds the Revo2 and leaves it in PRE-OP with identity checked.
pub async fn discover(md: &MainDevice<'static>) -> anyhow::Result<PreOpGroup> {
    teleop_ecat_master::discover(md, check_identity).await
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

/// Applies the configuration in PRE-OP, logs versions and serial numbers, and assigns the PDOs
/// (the Revo2 driver's configuration step).
pub async fn configure(
    md: &MainDevice<'static>,
    group: &PreOpGroup,
    config: &Revo2Config,
) -> anyhow::Result<DeviceInfo> {
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
            write_checked(md, group, sub, v, name).await?;
        }
    }
    if let Some(currents) = d.protection_current_ma {
        for (j, c) in currents.iter().enumerate() {
            write_checked(md, group, 0x0A + j as u8, *c, "protection current").await?;
        }
    }
    if let Some(c) = d.thumb_aux_lock_cur {
        write_checked(md, group, 0x10, c, "thumb_aux_lock_cur").await?;
    }
    let sd = group.subdevice(md, 0)?;
    let mut info = DeviceInfo {
        serial: sd.identity().serial,
        unit_mode: sd.sdo_read::<u8>(obj::CONFIG, 0x05).await.unwrap_or(0),
        ..Default::default()
    };
    info.control_fw = read_string(md, group, obj::CONFIG, 0x11).await?;
    info.control_sn = read_string(md, group, obj::CONFIG, 0x12).await?;
    info.wrist_fw = read_string(md, group, obj::CONFIG, 0x13).await?;
    info.wrist_sn = read_string(md, group, obj::CONFIG, 0x14).await?;
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
    Ok(info)
}

/// Brings the Revo2 up to OP (identity, configuration, PDO assignment) with the master's
/// bring-up; returns the group and what configuration learned.
pub async fn bring_up(
    md: &MainDevice<'static>,
    config: &Revo2Config,
) -> anyhow::Result<(OpGroup, DeviceInfo)> {
    let mut driver = crate::driver::Revo2::new(config.clone());
    let group = teleop_ecat_master::bring_up(md, &mut driver).await?;
    Ok((group, driver.into_info()))
}
