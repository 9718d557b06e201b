//! The glove's service commands, `teleop glove ...`: talk to the EH55BF1 glove directly over
//! its serial port (the glove node must not be running: the port is opened exclusively). The
//! command-line arguments ([`Target`], [`GloveCommand`]) are here; `teleop` only dispatches to
//! [`run`].

use std::io::{BufRead, Write};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Subcommand;
use teleop_glove_protocol::{reg, BaudRate, ErrorBits, CALIBRATION_STEPS, FINGERS};

use crate::link::{GloveLink, LinkError};

/// Where the glove is.
#[derive(clap::Args)]
pub struct Target {
    /// Serial port (USB serial, Bluetooth SPP such as /dev/rfcomm0, or the simulator's link).
    #[arg(long, env = "TELEOP_GLOVE_PORT", default_value = "/dev/ttyUSB0")]
    port: String,
    /// Line speed the glove is set to.
    #[arg(long, default_value_t = 115200)]
    baud: u32,
    /// The glove's device id.
    #[arg(long, default_value_t = 1)]
    id: u8,
    /// Answer timeout in milliseconds (1 to 60000).
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..=60_000))]
    timeout_ms: u64,
}

/// The glove commands.
#[derive(Subcommand)]
pub enum GloveCommand {
    /// List serial ports.
    Ports,
    /// Id, baud rate, supply voltage, positions, forces, currents, temperatures, decoded errors.
    Info,
    /// Run the glove's own five-step calibration, with the manual's prompts and timings.
    Calibrate {
        /// Do not ask whether the glove is worn.
        #[arg(long)]
        yes: bool,
    },
    /// Clear the clearable actuator errors (over-temperature clears itself when cool).
    ClearErrors,
    /// Give the glove a new device id (1..=254); `save` keeps it after power-off.
    SetId {
        /// The new id.
        new_id: u8,
    },
    /// Change the glove's baud rate (115200, 57600, 19200); `save` keeps it after power-off.
    SetBaud {
        /// The new rate.
        new_baud: u32,
    },
    /// Save id and baud rate to the glove's flash.
    Save,
    /// Restore the factory settings (id 1, 115200 baud).
    FactoryReset {
        /// Do not ask for confirmation.
        #[arg(long)]
        yes: bool,
    },
}

/// Runs one glove command against the glove at `target`.
pub fn run(target: &Target, command: &GloveCommand) -> anyhow::Result<ExitCode> {
    if let GloveCommand::Ports = command {
        return ports();
    }
    let mut link = GloveLink::open(
        &target.port,
        target.baud,
        target.id,
        Duration::from_millis(target.timeout_ms),
    )
    .map_err(|e| anyhow::anyhow!("{e} (is the glove node running? it holds the port)"))?;
    let context = |e: LinkError| {
        anyhow::anyhow!(
            "{} (id {}, {} baud): {e}",
            target.port,
            target.id,
            target.baud
        )
    };
    match command {
        // Answered above without opening the port.
        GloveCommand::Ports => {}
        GloveCommand::Info => info(&mut link).map_err(context)?,
        GloveCommand::Calibrate { yes } => calibrate(&mut link, *yes)?,
        GloveCommand::ClearErrors => {
            link.write_register(&reg::ERROR_CLEAR, &[1])
                .map_err(context)?;
            let errors = link.read_register(&reg::ERROR_CODE).map_err(context)?;
            println!("errors cleared; now:");
            print_errors(errors.as_slice());
        }
        GloveCommand::SetId { new_id } => {
            link.write_register(&reg::ID, &[i32::from(*new_id)])
                .map_err(context)?;
            link.set_id(*new_id);
            let id = link.read_register(&reg::ID).map_err(context)?;
            println!(
                "id is now {} (run `teleop glove --id {new_id} save` to keep it)",
                id.as_slice()[0]
            );
        }
        GloveCommand::SetBaud { new_baud } => {
            let baud = BaudRate::from_bps(*new_baud).ok_or_else(|| {
                anyhow::anyhow!("{new_baud}: the glove supports 115200, 57600 and 19200")
            })?;
            link.write_register(&reg::BAUD_RATE, &[i32::from(baud.code())])
                .map_err(context)?;
            link.set_baud(*new_baud).map_err(context)?;
            // Let the glove switch its UART after the acknowledge.
            std::thread::sleep(Duration::from_millis(50));
            link.read_register(&reg::ID).map_err(context)?;
            println!(
                "baud rate is now {new_baud} (run `teleop glove --baud {new_baud} save` to keep it, and set `baud` in the glove node's config)"
            );
        }
        GloveCommand::Save => {
            link.write_register(&reg::SAVE, &[1]).map_err(context)?;
            println!("saved to flash");
        }
        GloveCommand::FactoryReset { yes } => {
            if !yes && !confirm("Restore factory settings (id 1, 115200 baud)?")? {
                println!("nothing changed");
                return Ok(ExitCode::FAILURE);
            }
            link.write_register(&reg::FACTORY_RESET, &[1])
                .map_err(context)?;
            println!("factory settings restored: the glove now answers as id 1 at 115200 baud");
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn ports() -> anyhow::Result<ExitCode> {
    let ports = serialport::available_ports()?;
    if ports.is_empty() {
        println!("no serial ports found (Bluetooth SPP: bind one with `rfcomm bind`)");
    }
    for p in ports {
        let kind = match p.port_type {
            serialport::SerialPortType::UsbPort(_) => "usb",
            serialport::SerialPortType::BluetoothPort => "bluetooth",
            serialport::SerialPortType::PciPort => "pci",
            serialport::SerialPortType::Unknown => "",
        };
        println!("{:<24} {kind}", p.port_name);
    }
    Ok(ExitCode::SUCCESS)
}

fn info(link: &mut GloveLink) -> Result<(), LinkError> {
    let id = link.read_register(&reg::ID)?;
    let baud = link.read_register(&reg::BAUD_RATE)?;
    let voltage = link.read_register(&reg::VOLTAGE)?;
    let positions = link.read_register(&reg::POSITION_ACTUAL)?;
    let forces = link.read_register(&reg::FORCE_ACTUAL)?;
    let currents = link.read_register(&reg::CURRENT)?;
    let temperatures = link.read_register(&reg::TEMPERATURE)?;
    let errors = link.read_register(&reg::ERROR_CODE)?;
    let baud_code = baud.as_slice()[0];
    println!("port          {}", link.path());
    println!("id            {}", id.as_slice()[0]);
    println!(
        "baud rate     {}",
        BaudRate::from_code(baud_code as u8).map_or(format!("unknown code {baud_code}"), |b| b
            .bits_per_second()
            .to_string())
    );
    println!(
        "voltage       {} (raw register value; the manual gives no unit)",
        voltage.as_slice()[0]
    );
    println!(
        "positions     {:?}  (little..thumb, thumb rotation; 0 bent, 1000 open)",
        positions.as_slice()
    );
    println!("forces        {:?}", forces.as_slice());
    println!("currents mA   {:?}", currents.as_slice());
    println!("temperatures  {:?} degC", temperatures.as_slice());
    print_errors(errors.as_slice());
    Ok(())
}

fn print_errors(errors: &[i32]) {
    for (finger, &bits) in FINGERS.iter().zip(errors) {
        println!("error {finger:<7} {}", ErrorBits(bits as u8));
    }
}

fn calibrate(link: &mut GloveLink, yes: bool) -> anyhow::Result<()> {
    if !yes && !confirm("The operator must wear the glove. Start the glove's calibration?")? {
        anyhow::bail!("calibration not started");
    }
    link.write_register(&reg::CALIBRATION, &[1])?;
    println!("Calibration started.");
    for (i, (prompt, duration)) in CALIBRATION_STEPS.iter().enumerate() {
        println!("Step {}/{}: {prompt}", i + 1, CALIBRATION_STEPS.len());
        let end = Instant::now() + *duration;
        while Instant::now() < end {
            let left = end - Instant::now();
            print!("\r  {:.1} s ", left.as_secs_f32());
            std::io::stdout().flush()?;
            std::thread::sleep(left.min(Duration::from_millis(100)));
        }
        println!("\r  done   ");
    }
    // The device reports 1 while its calibration runs.
    let end = Instant::now() + Duration::from_secs(3);
    loop {
        let running = link.read_register(&reg::CALIBRATION)?.as_slice()[0];
        if running == 0 {
            println!("Calibration complete.");
            return Ok(());
        }
        if Instant::now() > end {
            anyhow::bail!("the glove still reports its calibration running");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn confirm(question: &str) -> anyhow::Result<bool> {
    print!("{question} [y/N] ");
    std::io::stdout().flush()?;
    let mut line = String::new();
    std::io::stdin().lock().read_line(&mut line)?;
    Ok(matches!(line.trim(), "y" | "Y" | "yes"))
}
