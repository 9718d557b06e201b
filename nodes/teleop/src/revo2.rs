//! `teleop revo2 ...`: talk to the Revo2 directly over EtherCAT in PRE-OP (the Revo2 node must
//! not be running: a bus has one MainDevice).

use std::process::ExitCode;

use clap::Subcommand;
use futures_lite::future::block_on;
use teleop_revo2::bus::{self, Bus, PreOpGroup};
use teleop_revo2::Transport;
use teleop_revo2_protocol::{
    config_entries, decode_config_value, obj, parse_config_value, ConfigValue, Entry,
};

/// Where the hand is.
#[derive(clap::Args)]
pub struct Target {
    /// `interface:NAME` (real hand; needs CAP_NET_RAW) or `sim:SOCKET` (emulated Revo2).
    #[arg(
        long,
        env = "TELEOP_REVO2_TRANSPORT",
        default_value = "sim:/tmp/teleop-revo2.sock"
    )]
    transport: String,
}

/// The Revo2 commands.
#[derive(Subcommand)]
pub enum Revo2Command {
    /// Identity, firmware versions, serial numbers, and every readable configuration value.
    Info,
    /// Write a configuration value of 0x8000/0x8010 by its document name, then read it back.
    Set {
        /// Parameter name as in the document (e.g. `led_switch`, `thumb_flex_pro_cur`).
        name: String,
        /// The value.
        value: String,
    },
    /// Start the hand's position calibration (0x8000:06), and with `--tactile` the per-finger
    /// tactile calibration (0x8010:01..05).
    Calibrate {
        /// Also calibrate the fingertip tactile sensors (the fingers must touch nothing).
        #[arg(long)]
        tactile: bool,
    },
}

pub fn run(target: &Target, command: &Revo2Command) -> anyhow::Result<ExitCode> {
    let transport = Transport::parse(&target.transport).map_err(anyhow::Error::msg)?;
    let bus = Bus::open(bus::connector(&transport))?;
    let group = block_on(bus::discover(&bus.md)).map_err(|e| {
        anyhow::anyhow!(
            "{e:#} (on {}; is the Revo2 node running? stop it first)",
            target.transport
        )
    })?;
    match command {
        Revo2Command::Info => info(&bus, &group)?,
        Revo2Command::Set { name, value } => set(&bus, &group, name, value)?,
        Revo2Command::Calibrate { tactile } => calibrate(&bus, &group, *tactile)?,
    }
    Ok(ExitCode::SUCCESS)
}

async fn read_value(bus: &Bus, group: &PreOpGroup, e: &Entry) -> anyhow::Result<ConfigValue> {
    let sd = group.subdevice(&bus.md, 0)?;
    let raw: heapless::Vec<u8, 64> = sd
        .sdo_read(e.index, e.sub)
        .await
        .map_err(|err| anyhow::anyhow!("{:#06x}:{:02x} {}: {err}", e.index, e.sub, e.name))?;
    Ok(decode_config_value(e, &raw)?)
}

fn info(bus: &Bus, group: &PreOpGroup) -> anyhow::Result<()> {
    let sd = group.subdevice(&bus.md, 0)?;
    let id = sd.identity();
    println!("device        {}", sd.name());
    println!(
        "identity      vendor {:#010x} product {:#010x} revision {} serial {}",
        id.vendor_id, id.product_id, id.revision, id.serial
    );
    for e in config_entries().filter(|e| e.access.is_readable()) {
        match block_on(read_value(bus, group, e)) {
            Ok(v) => println!("{:#06x}:{:02x} {:<26} {v}", e.index, e.sub, e.name),
            Err(err) => println!(
                "{:#06x}:{:02x} {:<26} (unreadable: {err})",
                e.index, e.sub, e.name
            ),
        }
    }
    Ok(())
}

fn set(bus: &Bus, group: &PreOpGroup, name: &str, text: &str) -> anyhow::Result<()> {
    let (index, sub, value) = parse_config_value(name, text)?;
    if !value.fits_expedited() {
        anyhow::bail!(
            "{name} is a string: writing it needs a normal (segmented) SDO download, which ethercrab 0.7 does not implement (it writes expedited values of at most 4 bytes)"
        );
    }
    let sd = group.subdevice(&bus.md, 0)?;
    let result = block_on(async {
        match value {
            ConfigValue::U8(v) => sd.sdo_write(index, sub, v).await,
            ConfigValue::U16(v) => sd.sdo_write(index, sub, v).await,
            ConfigValue::U32(v) => sd.sdo_write(index, sub, v).await,
            ConfigValue::U16x2([a, b]) => {
                sd.sdo_write(index, sub, u32::from(a) | u32::from(b) << 16)
                    .await
            }
            ConfigValue::Str(_) => Ok(()),
        }
    });
    result.map_err(|e| anyhow::anyhow!("writing {name} ({index:#06x}:{sub:02x}) failed: {e}"))?;
    let entry = teleop_revo2_protocol::entry(index, sub)
        .ok_or_else(|| anyhow::anyhow!("{name}: not in the dictionary"))?;
    if entry.access.is_readable() {
        let back = block_on(read_value(bus, group, entry))?;
        println!("{name} = {back}");
        if back != value {
            anyhow::bail!("{name} reads back {back} after writing {value}");
        }
    } else {
        println!("{name} written (write-only: cannot be read back)");
    }
    Ok(())
}

fn calibrate(bus: &Bus, group: &PreOpGroup, tactile: bool) -> anyhow::Result<()> {
    let sd = group.subdevice(&bus.md, 0)?;
    block_on(sd.sdo_write(obj::CONFIG, 0x06, 1u8))
        .map_err(|e| anyhow::anyhow!("position calibration: {e}"))?;
    println!("position calibration started (0x8000:06): the fingers run to their end stops");
    if tactile {
        for (sub, finger) in (1u8..=5).zip(teleop_revo2_protocol::FINGERTIP_NAMES) {
            block_on(sd.sdo_write(obj::TACTILE_CONFIG, sub, 1u8))
                .map_err(|e| anyhow::anyhow!("tactile calibration of the {finger}: {e}"))?;
            println!("tactile calibration of the {finger} started (0x8010:{sub:02x})");
        }
    }
    Ok(())
}
