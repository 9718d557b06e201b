//! `teleop-sim-revo2`: the emulated Revo2 as a process. It serves EtherCAT frames either on a
//! local socket (`--socket PATH`, the default simulated session, no privileges) or on a network
//! interface with a raw socket (`--interface IF`, e.g. one end of a veth pair; needs
//! CAP_NET_RAW), and takes commands at run time on a control socket:
//! `drop P`, `wrong-wkc P`, `watchdog`, `link-down SECONDS`, `refuse CODE`, `object ball|none`,
//! `foe-stall N|off` (the boot loader stops answering after N data packets of the next firmware
//! transfer), `flash-time ERASE_MS PER_KIB_MS`, `power-cycle SECONDS`, `versions`, `stats`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clap::Parser;
use teleop_ecat_link::Place;
use teleop_ecat_sim::SubDevice;
use teleop_sim_revo2::hand::VirtualObject;
use teleop_sim_revo2::{revo2_subdevice_with_loop, Revo2};

#[derive(Parser)]
#[command(version, about = "Emulated BrainCo Revo2 EtherCAT SubDevice")]
struct Args {
    /// Serve on this Unix socket (the Revo2 node connects with `transport = "sim:PATH"`).
    #[arg(long, conflicts_with = "interface")]
    socket: Option<PathBuf>,
    /// Serve on this network interface with a raw socket (needs CAP_NET_RAW).
    #[arg(long)]
    interface: Option<String>,
    /// Virtual object in the hand: `ball` or `none`.
    #[arg(long, default_value = "ball")]
    object: String,
    /// Serial number in the identity object.
    #[arg(long, default_value_t = 42)]
    serial: u32,
    /// Control socket (default: the socket path with `.ctl`, or /tmp/teleop-revo2-IF.ctl).
    #[arg(long)]
    control: Option<PathBuf>,
    /// Period of the firmware's main loop in microseconds: AL control is read once per loop,
    /// as a slave firmware does (0: every write acted on at once).
    #[arg(long, default_value_t = 1000)]
    firmware_loop_us: u64,
}

type Sim = Arc<Mutex<SubDevice<Revo2>>>;

fn main() -> ExitCode {
    teleop_runtime::init_logging();
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e:#}");
            ExitCode::FAILURE
        }
    }
}

fn object(name: &str) -> anyhow::Result<Option<VirtualObject>> {
    match name {
        "ball" => Ok(Some(VirtualObject::ball())),
        "none" => Ok(None),
        other => anyhow::bail!("unknown object {other:?}: use ball or none"),
    }
}

fn lock(sim: &Sim) -> std::sync::MutexGuard<'_, SubDevice<Revo2>> {
    sim.lock().unwrap_or_else(|e| e.into_inner())
}

fn run(args: Args) -> anyhow::Result<()> {
    teleop_runtime::install_stop_handlers();
    let sim: Sim = Arc::new(Mutex::new(revo2_subdevice_with_loop(
        object(&args.object)?,
        args.serial,
        Duration::from_micros(args.firmware_loop_us),
    )));
    let start = Instant::now();
    let place = Place::from_args(args.socket.clone(), args.interface.clone())
        .ok_or_else(|| anyhow::anyhow!("give --socket PATH or --interface IF"))?;
    let control = args
        .control
        .clone()
        .unwrap_or_else(|| place.default_control("revo2"));
    spawn_control(&control, sim.clone(), start)?;
    place.serve("revo2", &control, &*sim, start, &stopping)?;
    let _ = std::fs::remove_file(&control);
    tracing::info!("stopped");
    Ok(())
}

fn stopping() -> bool {
    teleop_runtime::stop_signal().is_some()
}

fn spawn_control(path: &Path, sim: Sim, start: Instant) -> anyhow::Result<()> {
    teleop_runtime::control::spawn(path, move |line| command(&sim, line, start))?;
    Ok(())
}

fn command(sim: &Sim, line: &str, start: Instant) -> String {
    let (word, rest) = line.split_once(' ').unwrap_or((line, ""));
    let rest = rest.trim();
    let mut dev = lock(sim);
    let prob = |s: &str| s.parse::<f32>().ok().filter(|p| (0.0..=1.0).contains(p));
    match word {
        "drop" => match prob(rest) {
            Some(p) => {
                dev.faults().drop_probability = p;
                format!("ok drop {p}")
            }
            None => "error: drop PROBABILITY (0..1)".into(),
        },
        "wrong-wkc" => match prob(rest) {
            Some(p) => {
                dev.faults().wrong_wkc_probability = p;
                format!("ok wrong-wkc {p}")
            }
            None => "error: wrong-wkc PROBABILITY (0..1)".into(),
        },
        "watchdog" => {
            dev.trip_watchdog();
            "ok watchdog tripped".into()
        }
        "link-down" => match rest.parse::<f64>() {
            Ok(s) if (0.0..3600.0).contains(&s) => {
                dev.faults().link_down = true;
                drop(dev);
                let sim = sim.clone();
                let _ = std::thread::Builder::new()
                    .name("link-up".into())
                    .spawn(move || {
                        std::thread::sleep(Duration::from_secs_f64(s));
                        lock(&sim).faults().link_down = false;
                        tracing::info!("link up again");
                    });
                tracing::warn!("link down for {s} s");
                "ok".into()
            }
            _ => "error: link-down SECONDS".into(),
        },
        "refuse" => match u16::from_str_radix(rest.trim_start_matches("0x"), 16) {
            Ok(code) => {
                dev.faults().refuse_next_transition = Some(code);
                format!("ok refusing the next transition with {code:#06x}")
            }
            Err(_) => "error: refuse CODE (hex, e.g. 0x0011)".into(),
        },
        "object" => match object(rest) {
            Ok(o) => {
                dev.app_mut().hand_mut().set_object(o);
                "ok".into()
            }
            Err(e) => format!("error: {e}"),
        },
        "foe-stall" => match rest {
            "off" => {
                dev.app_mut().upgrade_mut().stall_after = None;
                "ok foe-stall off".into()
            }
            n => match n.parse::<u32>() {
                Ok(n) => {
                    dev.app_mut().upgrade_mut().stall_after = Some(n);
                    format!("ok the boot loader stops answering after {n} data packets")
                }
                Err(_) => "error: foe-stall PACKETS|off".into(),
            },
        },
        "flash-time" => {
            let ms: Vec<u64> = rest
                .split_whitespace()
                .filter_map(|w| w.parse().ok())
                .collect();
            match ms[..] {
                [erase, per_kib] => {
                    let timing = &mut dev.app_mut().upgrade_mut().timing;
                    timing.erase = Duration::from_millis(erase);
                    timing.per_kib = Duration::from_millis(per_kib);
                    format!("ok flash erase {erase} ms, {per_kib} ms per KiB")
                }
                _ => "error: flash-time ERASE_MS PER_KIB_MS".into(),
            }
        }
        "power-cycle" => match rest.parse::<f64>() {
            Ok(s) if (0.0..3600.0).contains(&s) => {
                dev.restart(start.elapsed(), Duration::from_secs_f64(s));
                format!("ok restarting, off the bus for {s} s")
            }
            _ => "error: power-cycle SECONDS".into(),
        },
        "versions" => {
            let (control, wrist) = dev.app().firmware_versions();
            format!("control {control} wrist {wrist}")
        }
        "stats" => {
            let (state, error, code) = dev.al_state();
            format!(
                "state {state} error {error} code {code:#06x} up {:.1}s {:?}",
                start.elapsed().as_secs_f32(),
                dev.stats()
            )
        }
        _ => format!("error: unknown command {word:?}"),
    }
}
