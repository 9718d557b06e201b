//! The Revo2's service commands, `teleop revo2 ...`: talk to the Revo2 directly over EtherCAT in
//! PRE-OP (the Revo2 node must not be running: a bus has one MainDevice), and upgrade its
//! firmware over FoE in BOOT. The command-line arguments ([`Target`], [`Revo2Command`]) are
//! here; `teleop` only dispatches to [`run`]. The SDO I/O goes through [`crate::bus`], the
//! upgrade through [`crate::flash`].

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Subcommand;
use futures_lite::future::block_on;
use teleop_revo2_protocol::{
    config_entries, decode_config_value, obj, parse_config_value, Board, ConfigValue, Entry,
};

use crate::bus::{self, Bus, PreOpGroup};
use crate::flash::{self, version_text, Firmware, FlashError, FlashEvent, FlashOptions, Progress};
use crate::Transport;

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
    /// Upgrade the firmware of the wrist or control board over FoE: the file is checked first,
    /// then upgrade type and authentication code are written, the device goes to BOOT, takes
    /// the file, restarts, and its new version is read back.
    Flash {
        /// The firmware file, named as the document requires (case-sensitive):
        /// `Revo2EC_x.y.z_TIME.bin` (wrist board) or `Revo2_Vx.y.z_TIME.bin` (control board).
        file: PathBuf,
        /// The board the file is for.
        #[arg(long, value_enum)]
        board: BoardArg,
        /// Authentication code for 0x8000:16 instead of the document's (BRCW2025 for the wrist
        /// board, BRCC2025 for the control board).
        #[arg(long)]
        auth_code: Option<String>,
    },
}

/// A Revo2 board, on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BoardArg {
    /// The wrist board (magic and authentication code BRCW2025).
    Wrist,
    /// The control board (magic and authentication code BRCC2025).
    Control,
}

impl From<BoardArg> for Board {
    fn from(b: BoardArg) -> Self {
        match b {
            BoardArg::Wrist => Board::Wrist,
            BoardArg::Control => Board::Control,
        }
    }
}

/// Runs one Revo2 command against the hand at `target`.
pub fn run(target: &Target, command: &Revo2Command) -> anyhow::Result<ExitCode> {
    if let Revo2Command::Flash {
        file,
        board,
        auth_code,
    } = command
    {
        return flash_file(target, file, (*board).into(), auth_code.clone());
    }
    let transport = Transport::parse(&target.transport).map_err(anyhow::Error::msg)?;
    let bus = Bus::open(bus::connector(&transport))?;
    let group = block_on(bus::discover(bus.md())).map_err(|e| {
        anyhow::anyhow!(
            "{e:#} (on {}; is the Revo2 node running? stop it first)",
            target.transport
        )
    })?;
    match command {
        Revo2Command::Info => info(&bus, &group)?,
        Revo2Command::Set { name, value } => set(&bus, &group, name, value)?,
        Revo2Command::Calibrate { tactile } => calibrate(&bus, &group, *tactile)?,
        // Handled above, before the bus is opened.
        Revo2Command::Flash { .. } => {}
    }
    Ok(ExitCode::SUCCESS)
}

async fn read_value(bus: &Bus, group: &PreOpGroup, e: &Entry) -> anyhow::Result<ConfigValue> {
    let sd = group.subdevice(bus.md(), 0)?;
    let raw: heapless::Vec<u8, 64> = sd
        .sdo_read(e.index, e.sub)
        .await
        .map_err(|err| anyhow::anyhow!("{:#06x}:{:02x} {}: {err}", e.index, e.sub, e.name))?;
    Ok(decode_config_value(e, &raw)?)
}

fn info(bus: &Bus, group: &PreOpGroup) -> anyhow::Result<()> {
    let sd = group.subdevice(bus.md(), 0)?;
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
    let sd = group.subdevice(bus.md(), 0)?;
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
    let sd = group.subdevice(bus.md(), 0)?;
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

/// `teleop revo2 flash`: the file is checked before the bus is even opened.
fn flash_file(
    target: &Target,
    file: &Path,
    board: Board,
    auth_code: Option<String>,
) -> anyhow::Result<ExitCode> {
    let firmware = Firmware::load(file, board)?;
    let transport = Transport::parse(&target.transport).map_err(anyhow::Error::msg)?;
    println!(
        "{}: {board} firmware {} ({} bytes)",
        firmware.name(),
        version_text(firmware.version()),
        firmware.bytes().len()
    );
    let bus = Bus::open(bus::connector(&transport))?;
    let options = FlashOptions {
        auth_code,
        ..FlashOptions::default()
    };
    let mut bar = ProgressBar::new(std::io::stderr().is_terminal());
    let result = flash::flash(bus.md(), &firmware, &options, &mut |event| match event {
        FlashEvent::Step(text) => {
            bar.end_line();
            println!("{text}");
        }
        FlashEvent::Transfer(progress) => bar.show(progress),
    });
    bar.end_line();
    let report = result.map_err(|e| match e {
        FlashError::Bus(_) => anyhow::anyhow!(
            "{e} (on {}; is the Revo2 node running? stop it first)",
            target.transport
        ),
        other => anyhow::anyhow!("{other}"),
    })?;
    let t = report.transfer;
    println!(
        "{} firmware {} -> {} ({} bytes in {:.1} s, {:.1} KiB/s; device busy writing flash {} times; back on the bus after {:.1} s)",
        report.board,
        report.before,
        report.after,
        t.bytes,
        t.elapsed.as_secs_f64(),
        t.bytes as f64 / 1024.0 / t.elapsed.as_secs_f64().max(1e-3),
        t.busy,
        report.restart.as_secs_f64(),
    );
    Ok(ExitCode::SUCCESS)
}

/// A transfer progress bar on stderr: bytes, percentage, rate, and the device's BUSY text. On a
/// terminal it is redrawn in place (at most every 50 ms); otherwise a line every 25 %.
struct ProgressBar {
    terminal: bool,
    start: Option<Instant>,
    last_draw: Option<Instant>,
    last_quarter: u64,
    busy_reported: bool,
    drawn: bool,
}

impl ProgressBar {
    const WIDTH: usize = 30;

    fn new(terminal: bool) -> Self {
        Self {
            terminal,
            start: None,
            last_draw: None,
            last_quarter: 0,
            busy_reported: false,
            drawn: false,
        }
    }

    fn show(&mut self, p: &Progress) {
        let now = Instant::now();
        let start = *self.start.get_or_insert(now);
        let percent = (p.acknowledged * 100).checked_div(p.total).unwrap_or(100);
        let done = p.acknowledged >= p.total;
        let elapsed = now.duration_since(start).as_secs_f64().max(1e-3);
        let rate = p.acknowledged as f64 / 1024.0 / elapsed;
        let filled = (percent as usize * Self::WIDTH / 100).min(Self::WIDTH);
        let busy = p
            .busy
            .as_ref()
            .map(|b| format!("  device busy: {} {}/{}", b.text, b.done, b.entire))
            .unwrap_or_default();
        let line = format!(
            "[{}{}] {:>3}%  {:.1}/{:.1} KiB  {rate:.1} KiB/s{busy}",
            "#".repeat(filled),
            ".".repeat(Self::WIDTH - filled),
            percent,
            p.acknowledged as f64 / 1024.0,
            p.total as f64 / 1024.0,
        );
        let mut err = std::io::stderr();
        if self.terminal {
            let due = self
                .last_draw
                .is_none_or(|t| now.duration_since(t) >= Duration::from_millis(50));
            if due || done || p.busy.is_some() {
                let _ = write!(err, "\r{line:<100}");
                let _ = err.flush();
                self.last_draw = Some(now);
                self.drawn = true;
            }
        } else {
            let quarter = percent / 25;
            let first_busy = p.busy.is_some() && !self.busy_reported;
            if quarter > self.last_quarter || first_busy {
                let _ = writeln!(err, "{line}");
                self.last_quarter = quarter;
                self.busy_reported |= first_busy;
            }
        }
    }

    /// Ends the line the bar is drawn on (before other output).
    fn end_line(&mut self) {
        if self.terminal && self.drawn {
            let _ = writeln!(std::io::stderr());
        }
        self.drawn = false;
    }
}
