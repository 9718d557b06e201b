//! `teleop-sim-shadow`: the emulated Shadow Hand E as a process. It serves EtherCAT frames on a
//! local socket (`--socket PATH`, no privileges) or on a network interface with a raw socket
//! (`--interface IF`, e.g. one end of a veth pair; needs CAP_NET_RAW), and takes commands at
//! run time on a control socket: `drop P`, `link-down SECONDS`, `silent MOTOR|none` (a motor
//! board stops answering), `overheat MOTOR`, `flash-stall MOTOR N|off` (a board stops acking
//! after N more messages), `object ball|none`, `joints`, `stats`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clap::Parser;
use teleop_ecat_link::Place;
use teleop_shadow_protocol::layout::MOTORS;
use teleop_shadow_protocol::mapping::Mapping;
use teleop_sim_shadow::ethercat::ShadowBus;
use teleop_sim_shadow::hand::{Hand, Object, JOINTS};
use teleop_sim_shadow::palm::{Palm, CUT_OUT_C};

#[derive(Parser)]
#[command(version, about = "Emulated Shadow Hand E (EtherCAT bridge and palm)")]
struct Args {
    /// Serve on this Unix socket (the Shadow node connects with `transport = "sim:PATH"`).
    #[arg(long, conflicts_with = "interface")]
    socket: Option<PathBuf>,
    /// Serve on this network interface with a raw socket (needs CAP_NET_RAW).
    #[arg(long)]
    interface: Option<String>,
    /// Virtual object: `ball` (under the middle finger) or `none`.
    #[arg(long, default_value = "ball")]
    object: String,
    /// Joint -> motor mapping of the hand: `E_v3`, `E_v4` or `E_v5`.
    #[arg(long, default_value = "E_v3")]
    mapping: String,
    /// Serial number of the palm (names the hand on a real system).
    #[arg(long, default_value_t = 1178)]
    serial: u32,
    /// Control socket (default: the socket path with `.ctl`, or /tmp/teleop-shadow-IF.ctl).
    #[arg(long)]
    control: Option<PathBuf>,
    /// Period of the firmware's main loop in microseconds: AL control is read once per loop.
    #[arg(long, default_value_t = 1000)]
    firmware_loop_us: u64,
}

type Sim = Arc<Mutex<ShadowBus>>;

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

fn object(name: &str) -> anyhow::Result<Option<Object>> {
    match name {
        "ball" => Ok(Some(Object::ball())),
        "none" => Ok(None),
        other => anyhow::bail!("unknown object {other:?}: use ball or none"),
    }
}

fn mapping(name: &str) -> anyhow::Result<Mapping> {
    match name {
        "E_v3" => Ok(Mapping::EV3),
        "E_v4" => Ok(Mapping::EV4),
        "E_v5" => Ok(Mapping::EV5),
        other => anyhow::bail!("unknown mapping {other:?}: use E_v3, E_v4 or E_v5"),
    }
}

fn lock(sim: &Sim) -> std::sync::MutexGuard<'_, ShadowBus> {
    sim.lock().unwrap_or_else(|e| e.into_inner())
}

fn run(args: Args) -> anyhow::Result<()> {
    teleop_runtime::install_stop_handlers();
    let hand = Hand::new(mapping(&args.mapping)?, object(&args.object)?);
    let sim: Sim = Arc::new(Mutex::new(ShadowBus::new(
        Palm::with_hand(hand),
        args.serial,
        Duration::from_micros(args.firmware_loop_us),
    )));
    let start = Instant::now();
    let place = Place::from_args(args.socket.clone(), args.interface.clone())
        .ok_or_else(|| anyhow::anyhow!("give --socket PATH or --interface IF"))?;
    let control = args
        .control
        .clone()
        .unwrap_or_else(|| place.default_control("shadow"));
    spawn_control(&control, sim.clone(), start)?;
    place.serve("shadow", &control, &*sim, start, &stopping)?;
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

fn motor(s: &str) -> Option<usize> {
    s.parse::<usize>().ok().filter(|m| *m < MOTORS)
}

fn command(sim: &Sim, line: &str, start: Instant) -> String {
    let (word, rest) = line.split_once(' ').unwrap_or((line, ""));
    let rest = rest.trim();
    let mut dev = lock(sim);
    match word {
        "drop" => match rest.parse::<f32>().ok().filter(|p| (0.0..=1.0).contains(p)) {
            Some(p) => {
                dev.bridge.faults().drop_probability = p;
                format!("ok drop {p}")
            }
            None => "error: drop PROBABILITY (0..1)".into(),
        },
        "link-down" => match rest.parse::<f64>() {
            Ok(s) if (0.0..3600.0).contains(&s) => {
                dev.bridge.faults().link_down = true;
                drop(dev);
                let sim = sim.clone();
                let _ = std::thread::Builder::new()
                    .name("link-up".into())
                    .spawn(move || {
                        std::thread::sleep(Duration::from_secs_f64(s));
                        lock(&sim).bridge.faults().link_down = false;
                        tracing::info!("link up again");
                    });
                tracing::warn!("link down for {s} s");
                "ok".into()
            }
            _ => "error: link-down SECONDS".into(),
        },
        "silent" => match rest {
            "none" => {
                for b in &mut dev.palm_mut().boards {
                    b.silent = false;
                }
                "ok every motor answers".into()
            }
            m => match motor(m) {
                Some(m) => {
                    dev.palm_mut().boards[m].silent = true;
                    format!("ok motor {m} stops answering")
                }
                None => "error: silent MOTOR (0..19)|none".into(),
            },
        },
        "overheat" => match motor(rest) {
            Some(m) => {
                dev.palm_mut().motors[m].temperature = CUT_OUT_C + 5.0;
                format!("ok motor {m} at {} C", CUT_OUT_C + 5.0)
            }
            None => "error: overheat MOTOR (0..19)".into(),
        },
        "flash-stall" if rest.ends_with(" off") => match motor(rest.trim_end_matches(" off")) {
            Some(m) => {
                dev.palm_mut().boards[m].stop_after = None;
                format!("ok motor {m} acks again")
            }
            None => "error: flash-stall MOTOR off".into(),
        },
        "flash-stall" => {
            let words: Vec<usize> = rest
                .split_whitespace()
                .filter_map(|w| w.parse().ok())
                .collect();
            match words[..] {
                [m, n] if m < MOTORS => {
                    dev.palm_mut().boards[m].stop_after = Some(n as u64);
                    format!("ok motor {m} stops acking after {n} messages")
                }
                _ => "error: flash-stall MOTOR MESSAGES".into(),
            }
        }
        "object" => match object(rest) {
            Ok(o) => {
                dev.palm_mut().hand.object = o;
                "ok".into()
            }
            Err(e) => format!("error: {e}"),
        },
        "joints" => {
            let hand = &dev.palm().hand;
            JOINTS
                .iter()
                .zip(hand.angles)
                .map(|(j, a)| format!("{j} {a:.3}"))
                .collect::<Vec<_>>()
                .join(" ")
        }
        "stats" => {
            let (state, error, code) = dev.palm.al_state();
            format!(
                "palm {state} error {error} code {code:#06x} up {:.1}s {:?} esc {:?}",
                start.elapsed().as_secs_f32(),
                dev.palm.app().stats,
                dev.palm.stats()
            )
        }
        _ => format!("error: unknown command {word:?}"),
    }
}
