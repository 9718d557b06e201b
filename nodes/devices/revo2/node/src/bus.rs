//! The Revo2 on the bus (on `teleop-ecat-master`'s bus and bring-up): the identity check,
//! configuration in PRE-OP with read-back, the PDO assignment (with an SDO-polling fallback for
//! tactile data) and the check of the PDO layout read back, and the string reads `teleop revo2`
//! and the firmware upgrade use too.

use ethercrab::MainDevice;
use teleop_ecat_master::Found;
pub use teleop_ecat_master::{connector, Bus, OpGroup, PreOpGroup};
use teleop_revo2_protocol::{
    mapping_entries, obj, UnitMode, DEFAULT_RX_ASSIGNMENT, JOINT_ONLY_TX_ASSIGNMENT, PRODUCT_CODE,
    REVISION, VENDOR_ID,
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
    /// Unit mode in effect (0 percent, 1 physical: bring-up refuses any other).
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

/// Reads a string object (see [`device_text`]).
pub async fn read_string(
    md: &MainDevice<'static>,
    group: &PreOpGroup,
    index: u16,
    sub: u8,
) -> anyhow::Result<String> {
    let sd = group.subdevice(md, 0)?;
    // Bytes, not a string: an unset string is 0xFF-filled (erased flash), not UTF-8.
    let bytes: heapless::Vec<u8, 64> = sd
        .sdo_read(index, sub)
        .await
        .map_err(|e| anyhow::anyhow!("SDO read {index:#06x}:{sub:#04x} failed: {e}"))?;
    Ok(device_text(&bytes))
}

/// A device string as text: NUL, space and 0xFF padding removed, bytes that are not UTF-8
/// replaced; `"(unset)"` for a string that is nothing but padding (0xFF-filled: never written).
pub fn device_text(bytes: &[u8]) -> String {
    let end = bytes
        .iter()
        .rposition(|b| !matches!(b, 0 | b' ' | 0xFF))
        .map_or(0, |i| i + 1);
    if end == 0 {
        return "(unset)".into();
    }
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

/// Reads the unit mode in effect (0x8000:05), trying a few times. A device whose unit mode
/// cannot be read or is unknown is refused: guessing would scale every command wrongly.
async fn read_unit_mode(md: &MainDevice<'static>, group: &PreOpGroup) -> anyhow::Result<UnitMode> {
    const TRIES: u32 = 3;
    let sd = group.subdevice(md, 0)?;
    let mut failure = String::new();
    for attempt in 1..=TRIES {
        match sd.sdo_read::<u8>(obj::CONFIG, 0x05).await {
            Ok(v) => {
                return UnitMode::from_u8(v).ok_or_else(|| {
                    anyhow::anyhow!(
                        "unit_mode (0x8000:05) reads {v}: not 0 (percent) or 1 (physical)"
                    )
                })
            }
            Err(e) => {
                tracing::warn!(attempt, "reading unit_mode (0x8000:05) failed: {e}");
                failure = e.to_string();
            }
        }
    }
    anyhow::bail!(
        "reading unit_mode (0x8000:05) failed {TRIES} times ({failure}): refusing to guess the \
         units of the hand's commands"
    )
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
        unit_mode: read_unit_mode(md, group).await?.to_u8(),
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
    check_pdo_layout(md, group, &assigned).await?;
    info.tx_assignment = assigned;
    Ok(info)
}

/// Reads back the PDO assignment (0x1C12, 0x1C13) and the mapping of every assigned PDO
/// (0x1600, 0x1A00, and 0x1A01 when tactile data is assigned) and refuses a device whose layout
/// differs from the one the driver packs and unpacks: in OP it would exchange data nobody
/// understands. The error names the object.
async fn check_pdo_layout(
    md: &MainDevice<'static>,
    group: &PreOpGroup,
    tx_assignment: &[u16],
) -> anyhow::Result<()> {
    let wide = |v: &[u16]| v.iter().map(|&x| u32::from(x)).collect::<Vec<_>>();
    let mut expected = vec![
        (obj::SM2_ASSIGN, wide(&DEFAULT_RX_ASSIGNMENT)),
        (obj::SM3_ASSIGN, wide(tx_assignment)),
    ];
    for &pdo in DEFAULT_RX_ASSIGNMENT.iter().chain(tx_assignment) {
        let entries = mapping_entries(pdo).ok_or_else(|| {
            anyhow::anyhow!("PDO {pdo:#06x} is assigned but has no mapping the driver knows")
        })?;
        expected.push((pdo, entries.iter().map(|m| m.encode()).collect()));
    }
    for (index, wanted) in expected {
        let found = read_list(md, group, index).await?;
        if let Some(mismatch) = layout_mismatch(index, &wanted, &found) {
            anyhow::bail!(
                "the Revo2's PDO layout is not the one this driver packs: {mismatch}; refusing OP"
            );
        }
    }
    Ok(())
}

/// The entries of a list object (a PDO assignment or mapping) read back.
async fn read_list(
    md: &MainDevice<'static>,
    group: &PreOpGroup,
    index: u16,
) -> anyhow::Result<Vec<u32>> {
    let sd = group.subdevice(md, 0)?;
    let failed = |sub: u8, e: ethercrab::error::Error| {
        anyhow::anyhow!("reading {index:#06x}:{sub:02x} back failed: {e}")
    };
    let count: u8 = sd.sdo_read(index, 0).await.map_err(|e| failed(0, e))?;
    let assignment = index == obj::SM2_ASSIGN || index == obj::SM3_ASSIGN;
    let mut values = Vec::with_capacity(usize::from(count));
    for sub in 1..=count {
        values.push(if assignment {
            u32::from(
                sd.sdo_read::<u16>(index, sub)
                    .await
                    .map_err(|e| failed(sub, e))?,
            )
        } else {
            sd.sdo_read::<u32>(index, sub)
                .await
                .map_err(|e| failed(sub, e))?
        });
    }
    Ok(values)
}

/// What differs between the entries of `index` the driver expects and those read back, naming
/// the object and subindex; `None` when they agree.
pub fn layout_mismatch(index: u16, expected: &[u32], found: &[u32]) -> Option<String> {
    if expected.len() != found.len() {
        return Some(format!(
            "{index:#06x}:00 has {} entries, expected {}",
            found.len(),
            expected.len()
        ));
    }
    let (sub, (e, f)) = expected
        .iter()
        .zip(found)
        .enumerate()
        .find(|(_, (e, f))| e != f)?;
    Some(format!(
        "{index:#06x}:{:02x} is {f:#010x}, expected {e:#010x}",
        sub + 1
    ))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_strings_lose_their_padding_and_unset_ones_say_so() {
        assert_eq!(device_text(b"RV2C2411\0\0\0"), "RV2C2411");
        assert_eq!(device_text(b"1.4.2 \xFF\xFF"), "1.4.2");
        assert_eq!(device_text(&[0xFF; 16]), "(unset)");
        assert_eq!(device_text(&[]), "(unset)");
        assert_eq!(device_text(b"\0\0"), "(unset)");
        assert_eq!(device_text(b"A\xFEB"), "A\u{FFFD}B");
    }

    #[test]
    fn a_layout_mismatch_names_the_object_and_subindex() {
        assert_eq!(layout_mismatch(0x1600, &[1, 2], &[1, 2]), None);
        assert_eq!(
            layout_mismatch(0x1A00, &[0x6000_0160, 2], &[0x6000_0160, 3]).unwrap(),
            "0x1a00:02 is 0x00000003, expected 0x00000002"
        );
        assert_eq!(
            layout_mismatch(0x1C13, &[0x1A00, 0x1A01], &[0x1A00]).unwrap(),
            "0x1c13:00 has 1 entries, expected 2"
        );
    }
}
