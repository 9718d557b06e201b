//! `teleop`: the one command users run. `teleop launch` starts the pipeline described in
//! `launch.toml` as separate processes; `nodes`, `topics`, `echo`, `stats` and `estop` inspect and
//! steer a running pipeline (every side of it, or the namespaces given with `--namespace`);
//! `top` is the operator's console over it (a terminal UI);
//! `calibrate` records an operator calibration profile.
//!
//! `glove`, `revo2`, `allegro`, `shadow` and `leap` are the devices' service commands: their arguments
//! and their I/O live with the device (`service` in each device node's library), and `teleop`
//! only dispatches to them.
//!
//! Owns the command line and the supervisor; it runs no control loop itself. Must not contain
//! device protocols, device I/O or control logic (those live in `shared/` and in the device
//! nodes).
//!
//! No argument makes it panic: times and speeds are checked when parsed
//! ([`teleop_runtime::args::parse_seconds`], [`parse_speed`]) and refused naming the argument, and a closed standard output (`teleop echo
//! glove/state | head`) ends the command quietly with success ([`out!`]).

/// `println!` that returns the write's error instead of panicking on it: a reader that closed
/// the pipe (`teleop echo ... | head`) ends the command, quietly and with success (see
/// [`is_broken_pipe`]).
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::print_line(format_args!($($arg)*))
    };
}

mod calibrate;
mod certs;
mod doctor;
mod echo;
mod episode;
mod export;
mod inspect;
mod launch;
mod profile;
mod recordings;
mod retarget_eval;
mod top;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};
use teleop_runtime::args::parse_seconds;
use teleop_runtime::{init_logging, IpcSettings, Namespace, ENV_IPC_PREFIX, ENV_IPC_ROOT};

#[derive(Parser)]
#[command(
    version,
    about = "Teleoperation of dexterous robot hands with force feedback"
)]
struct Cli {
    /// iceoryx2 root path of the pipeline to talk to.
    #[arg(long, global = true, env = ENV_IPC_ROOT)]
    ipc_root: Option<String>,
    /// iceoryx2 prefix of the pipeline to talk to (default `teleop_`).
    #[arg(long, global = true, env = ENV_IPC_PREFIX)]
    ipc_prefix: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Start every process of a launch file and supervise them until Ctrl-C.
    Launch {
        /// The launch file.
        #[arg(default_value = "launch.toml")]
        file: PathBuf,
        /// Stop after this many seconds.
        #[arg(long, value_parser = parse_seconds, allow_hyphen_values = true)]
        duration: Option<Duration>,
        /// Check the launch file and exit.
        #[arg(long)]
        check: bool,
    },
    /// List the pipeline's processes (iceoryx2 nodes): name, alive or dead, pid.
    Nodes {
        /// Only this namespace (repeatable); without it, every namespace found.
        #[arg(long = "namespace", value_name = "NS")]
        namespaces: Vec<Namespace>,
    },
    /// List the topics with their payload, size, and publishers/subscribers.
    Topics {
        /// Only this namespace (repeatable); without it, every namespace found.
        #[arg(long = "namespace", value_name = "NS")]
        namespaces: Vec<Namespace>,
    },
    /// Print decoded samples of a topic as they arrive: the used joints and fingertips named
    /// by the hand profile, the glove's fingers by name; YAML, JSON Lines or CSV.
    Echo {
        /// Topic name, e.g. `glove/state` (see `teleop topics`).
        topic: String,
        /// Stop after this many samples.
        #[arg(long, short = 'n')]
        count: Option<u64>,
        /// The topic's namespace (or name it in the topic: `left/hand/command`).
        #[arg(long, value_name = "NS")]
        namespace: Option<Namespace>,
        /// `yaml` (a document per sample), `json` (an object per line) or `csv` (a header
        /// line, a row per sample).
        #[arg(long, value_enum, default_value_t = echo::Format::Yaml)]
        format: echo::Format,
        /// A hand profile file naming the joints and fingertips of hand samples (default: the
        /// shipped profile of each sample's hand model).
        #[arg(long)]
        profile: Option<PathBuf>,
    },
    /// Per-topic rate, drops and latency (from the sample headers) over a window.
    Stats {
        /// Measurement window in seconds.
        #[arg(long, default_value = "2", value_parser = parse_seconds, allow_hyphen_values = true)]
        seconds: Duration,
        /// Only this namespace (repeatable); without it, every namespace found.
        #[arg(long = "namespace", value_name = "NS")]
        namespaces: Vec<Namespace>,
    },
    /// Engage (or release) the emergency stop, latched until `--release`: all glove forces go
    /// to zero and the hands hold their last target, on every side. Lists the nodes that
    /// acknowledged it; exits 1 when none did, or when a release did not reach every node that
    /// obeys the e-stop within 5 s (those stay engaged).
    Estop {
        /// Release instead of engage.
        #[arg(long)]
        release: bool,
        /// Only this namespace (repeatable); without it, the topics without a namespace and
        /// every namespace found.
        #[arg(long = "namespace", value_name = "NS")]
        namespaces: Vec<Namespace>,
    },
    /// Talk to the EH55BF1 glove directly (with the glove node stopped).
    Glove {
        #[command(flatten)]
        target: teleop_glove::service::Target,
        #[command(subcommand)]
        command: teleop_glove::service::GloveCommand,
    },
    /// Talk to the Revo2 directly over EtherCAT (with the Revo2 node stopped).
    Revo2 {
        #[command(flatten)]
        target: teleop_revo2::service::Target,
        #[command(subcommand)]
        command: teleop_revo2::service::Revo2Command,
    },
    /// Talk to the Allegro Hand directly over CAN (with the Allegro node stopped).
    Allegro {
        #[command(flatten)]
        target: teleop_allegro::service::Target,
        #[command(subcommand)]
        command: teleop_allegro::service::AllegroCommand,
    },
    /// Talk to the LEAP Hand's servos directly over their serial bus (with the LEAP node
    /// stopped): info, reboot, home, move.
    Leap {
        #[command(flatten)]
        target: teleop_leap::service::Target,
        #[command(subcommand)]
        command: teleop_leap::service::LeapCommand,
    },
    /// Talk to the Shadow Hand's palm directly over EtherCAT (with the Shadow node stopped):
    /// info, motor-board flashing, a crafted CAN message, ADC channel numbers.
    Shadow {
        #[command(flatten)]
        target: teleop_shadow::service::Target,
        #[command(subcommand)]
        command: teleop_shadow::service::ShadowCommand,
    },
    /// Make a session's certificate authority and station certificates for the bridge's
    /// mutual TLS (`ca.pem`, `ca.key`, `<station>.pem`, `<station>.key`); an existing CA in the
    /// folder signs added stations. Nothing is overwritten.
    Certs {
        /// Output folder.
        #[arg(long, default_value = "certs")]
        out: PathBuf,
        /// A station: `NAME` or `NAME=ADDRESS[,ADDRESS...]`, the addresses its peer connects to
        /// (repeatable).
        #[arg(long = "station", value_name = "NAME=ADDR", required = true)]
        stations: Vec<certs::StationSpec>,
        /// Validity in days (1 to 36500).
        #[arg(long, default_value_t = 825, value_parser = clap::value_parser!(u32).range(1..=36500))]
        days: u32,
    },
    /// Record the pipeline's topics into MCAP until Ctrl-C (nothing else is started).
    Record {
        /// Output file (default: `recordings/<UTC date>_<time>.<ms>.mcap`, `-2`, `-3`, ... added
        /// when another recorder took the name).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Record only these topics.
        #[arg(long, num_args = 1..)]
        topics: Option<Vec<String>>,
        /// Stop after this many seconds.
        #[arg(long, value_parser = parse_seconds, allow_hyphen_values = true)]
        duration: Option<Duration>,
        /// Record this namespace's topics into channels `NS/<topic>` (repeatable); without it,
        /// the topics without a namespace.
        #[arg(long = "namespace", value_name = "NS")]
        namespaces: Vec<Namespace>,
    },
    /// Republish a recording's samples on their topics with the recorded timing.
    Replay {
        /// The recording.
        file: PathBuf,
        /// Playback speed (1 = real time; 0.001 to 1000).
        #[arg(long, default_value = "1", conflicts_with = "max_speed", value_parser = parse_speed,
               allow_hyphen_values = true)]
        speed: f64,
        /// As fast as possible.
        #[arg(long)]
        max_speed: bool,
        /// Start again at the end, until Ctrl-C.
        #[arg(long = "loop")]
        looped: bool,
        /// Replay only these channels (e.g. `glove/state` to drive the hand from a recorded
        /// operator; `left/glove/state` in a recording of several sides). Without it, the
        /// sensor topics (glove/state, glove/diagnostics, hand/state, hand/tactile, device/info),
        /// never the commands or node health; `estop` and `estop/ack` never at all.
        #[arg(long, num_args = 1..)]
        topics: Option<Vec<String>>,
        /// Seconds from the start of the recording to begin at.
        #[arg(long, value_parser = parse_seconds, allow_hyphen_values = true)]
        start: Option<Duration>,
        /// Seconds from the start of the recording to end at.
        #[arg(long, value_parser = parse_seconds, allow_hyphen_values = true)]
        end: Option<Duration>,
        /// Replay only this namespace's channels (repeatable); without it, every channel.
        #[arg(long = "namespace", value_name = "NS")]
        namespaces: Vec<Namespace>,
        /// Publish a namespace's channels in another: `left=right`, `=left` (the channels
        /// without a namespace into `left`), `left=` (into the topics without a namespace).
        #[arg(long, value_name = "FROM=TO", value_parser = recordings::parse_remap)]
        remap: Vec<recordings::Remap>,
        /// Publish into topics that a running process publishes too (refused without it).
        #[arg(long)]
        allow_live: bool,
    },
    /// Hand profiles for other tools: `list` the builtin ones, or export one as `urdf`.
    Profile {
        #[command(subcommand)]
        command: profile::ProfileCommand,
    },
    /// Retargeting tools: `eval` measures modes on recorded glove trajectories.
    Retarget {
        #[command(subcommand)]
        command: RetargetCommand,
    },
    /// Inspect or repair recordings.
    Recordings {
        #[command(subcommand)]
        command: RecordingsCommand,
    },
    /// Export recordings' episodes to a LeRobot v3.0 dataset (new, or appended to): the kept
    /// episodes (not discarded, not left open) resampled to a fixed rate; an episode whose key
    /// topics ran below --min-rate-ratio of the recording's rate, or fell silent for longer
    /// than --max-gap-ms, is refused by name.
    Export {
        /// The recordings (one MCAP file each).
        #[arg(required = true)]
        recordings: Vec<PathBuf>,
        /// The dataset format.
        #[arg(long, value_enum)]
        format: ExportFormat,
        #[command(flatten)]
        options: export::ExportOptions,
    },
    /// Run retargeting and force feedback over a recording's inputs and compare with its outputs.
    Reprocess {
        /// The recording.
        file: PathBuf,
        /// Where to write inputs and recomputed outputs.
        #[arg(long)]
        out: PathBuf,
        /// Retargeting configuration (default: the node's defaults).
        #[arg(long)]
        retarget_config: Option<PathBuf>,
        /// Operator calibration profile.
        #[arg(long)]
        calibration: Option<PathBuf>,
        /// Force-feedback configuration.
        #[arg(long)]
        feedback_config: Option<PathBuf>,
        /// Hand profile (default: the one embedded in the recording, else the shipped profile of
        /// the recorded hand model).
        #[arg(long)]
        profile: Option<PathBuf>,
        /// The side to reprocess in a recording of several (channels `NS/<topic>`); without it,
        /// the channels without a namespace.
        #[arg(long, value_name = "NS")]
        namespace: Option<Namespace>,
    },
    /// Show the live pipeline or a recording in a rerun viewer (`teleop view --help`).
    ///
    /// Runs `teleop-viewer` with these arguments:
    /// `teleop view [FILE.mcap] [--spawn | --connect [URL] | --save FILE.rrd] [--profile FILE]
    /// [--namespace NS]`.
    #[command(disable_help_flag = true)]
    View {
        /// Arguments for `teleop-viewer`.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Mark episodes in the running session's recording: `start --task "..."`, `stop
    /// --success|--failure`, `discard`. Waits until the recorder counts the mark; fails when no
    /// recorder runs.
    Episode {
        #[command(subcommand)]
        command: EpisodeCommand,
    },
    /// Check this host for running a launch file's session on real hardware: real-time and
    /// memory-locking rights, serial ports and their latency timers, EtherCAT and CAN
    /// interfaces, the CPU governor, /dev/shm, the e-stop latch's directory. Prints each
    /// problem with its fix; exits 1 when something would stop a hardware session.
    Doctor {
        /// The launch file.
        #[arg(default_value = "launch.toml")]
        file: PathBuf,
    },
    /// The operator's console: every node, topic rates and latencies, the glove's positions and
    /// forces and the fingertips' tactile forces as bars, the link, the e-stop, the recording
    /// and its episode, refreshed live. Keys: e, space or Esc engage the e-stop; r then y
    /// release it; s starts an episode, k/f stop it with success/failure, d discards; q quits.
    Top {
        /// Only this namespace (repeatable); without it, the topics without a namespace and
        /// every namespace found (the e-stop keys then act on every side, as `teleop estop`).
        #[arg(long = "namespace", value_name = "NS")]
        namespaces: Vec<Namespace>,
        /// The task `s` starts episodes of (without it, `s` asks for it once).
        #[arg(long, value_parser = episode::parse_task)]
        task: Option<String>,
    },
    /// Record an operator calibration profile from the live glove.
    Calibrate {
        /// Where to write the profile.
        #[arg(long, default_value = "calibration.toml")]
        out: PathBuf,
        /// Do not wait for Enter: count down `--settle` seconds before each pose instead.
        #[arg(long)]
        yes: bool,
        /// Skip the pinch step (thumb to each finger, which fits the operator's thumb in the
        /// hand model); the profile then has no `[operator]` table.
        #[arg(long)]
        no_pinch: bool,
        /// Seconds to get into each pose when `--yes` is given.
        #[arg(long, default_value = "3", value_parser = parse_seconds, allow_hyphen_values = true)]
        settle: Duration,
        /// Seconds of glove samples averaged per pose.
        #[arg(long, default_value = "1", value_parser = parse_seconds, allow_hyphen_values = true)]
        capture: Duration,
    },
}

#[derive(Subcommand)]
enum EpisodeCommand {
    /// Begin an episode (an episode still open is closed first, unlabelled).
    Start {
        /// What the episode does, in words (the dataset's task).
        #[arg(long, value_parser = episode::parse_task)]
        task: String,
    },
    /// End the open episode; without a flag its outcome is unlabelled.
    Stop {
        /// The task was done.
        #[arg(long, conflicts_with = "failure")]
        success: bool,
        /// The task was not done.
        #[arg(long)]
        failure: bool,
    },
    /// Throw away the open episode, or else the last one closed (once).
    Discard,
}

#[derive(Subcommand)]
enum RetargetCommand {
    /// Run retargeting modes over recorded glove trajectories and print, side by side, the
    /// fingertip error, the pinch gap where the operator pinches, joint-limit saturation, jerk
    /// and step time (e.g. `teleop retarget eval recordings/trajectories/*.mcap --hand allegro`).
    Eval {
        /// Recordings with `glove/state` samples.
        #[arg(required = true)]
        recordings: Vec<PathBuf>,
        /// The robot hand: a shipped name (revo2, allegro, shadow, leap) or a profile file.
        #[arg(long)]
        hand: String,
        /// Modes to compare: comma-separated joint, vector, pinch, or all.
        #[arg(long, default_value = "all", value_parser = retarget_eval::parse_modes)]
        mode: std::vec::Vec<teleop_hand_profile::RetargetMode>,
        /// The retarget node's configuration (its `[retarget]` table; default: the defaults).
        #[arg(long)]
        config: Option<PathBuf>,
        /// The operator's calibration profile (default: the glove's full range, default model).
        #[arg(long)]
        calibration: Option<PathBuf>,
        /// The side to read in a recording of several (`NS/glove/state`).
        #[arg(long, value_name = "NS")]
        namespace: Option<Namespace>,
    },
}

/// Dataset formats of `teleop export`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum ExportFormat {
    /// LeRobot v3.0 (parquet frames, meta/info.json, tasks, episodes, stats).
    Lerobot,
}

#[derive(Subcommand)]
enum RecordingsCommand {
    /// Topics, message counts, rates, duration, drops and metadata.
    Info {
        /// The recording.
        file: PathBuf,
    },
    /// Make a killed recorder's file readable again (every closed chunk is kept).
    Repair {
        /// The damaged recording.
        file: PathBuf,
        /// Output file (default: FILE with `.repaired.mcap`).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Replace the output file if it exists (never the input itself).
        #[arg(long)]
        force: bool,
    },
}

fn main() -> ExitCode {
    init_logging();
    let cli = Cli::parse();
    let ipc = IpcSettings {
        root: cli.ipc_root.clone().filter(|s| !s.is_empty()),
        prefix: cli.ipc_prefix.clone().filter(|s| !s.is_empty()),
        namespace: None,
    };
    let result = match cli.command {
        Command::Launch {
            file,
            duration,
            check,
        } => run_launch(&file, &ipc, duration, check),
        Command::Nodes { namespaces } => inspect::nodes(&ipc, &namespaces),
        Command::Topics { namespaces } => inspect::topics(&ipc, &namespaces),
        Command::Echo {
            topic,
            count,
            namespace,
            format,
            profile,
        } => inspect::echo(
            &ipc,
            &topic,
            namespace.as_ref(),
            count,
            format,
            profile.as_deref(),
        ),
        Command::Stats {
            seconds,
            namespaces,
        } => inspect::stats(&ipc, seconds, &namespaces),
        Command::Estop {
            release,
            namespaces,
        } => inspect::estop(&ipc, !release, &namespaces),
        Command::Glove { target, command } => teleop_glove::service::run(&target, &command),
        Command::Certs {
            out,
            stations,
            days,
        } => certs::run(&out, &stations, days),
        Command::Record {
            out,
            topics,
            duration,
            namespaces,
        } => recordings::record_cmd(&ipc, out, topics, namespaces, duration),
        Command::Replay {
            file,
            speed,
            max_speed,
            looped,
            topics,
            start,
            end,
            namespaces,
            remap,
            allow_live,
        } => recordings::replay_cmd(
            &ipc,
            &file,
            &recordings::ReplayOptions {
                speed: (!max_speed).then_some(speed),
                looped,
                topics,
                start,
                end,
                namespaces,
                remap,
                allow_live,
            },
        ),
        Command::Recordings { command } => match command {
            RecordingsCommand::Info { file } => recordings::info_cmd(&file),
            RecordingsCommand::Repair { file, out, force } => {
                recordings::repair_cmd(&file, out, force)
            }
        },
        Command::Profile { command } => profile::run(&command),
        Command::Retarget {
            command:
                RetargetCommand::Eval {
                    recordings,
                    hand,
                    mode,
                    config,
                    calibration,
                    namespace,
                },
        } => retarget_eval::eval_cmd(&retarget_eval::EvalOptions {
            recordings,
            hand,
            modes: mode,
            config,
            calibration,
            namespace,
        }),
        Command::Reprocess {
            file,
            out,
            retarget_config,
            calibration,
            feedback_config,
            profile,
            namespace,
        } => recordings::reprocess_cmd(
            &file,
            &out,
            &recordings::ReprocessOptions {
                retarget_config,
                calibration,
                feedback_config,
                profile,
                namespace,
            },
        ),
        Command::Revo2 { target, command } => teleop_revo2::service::run(&target, &command),
        Command::Allegro { target, command } => teleop_allegro::service::run(&target, &command),
        Command::Shadow { target, command } => teleop_shadow::service::run(&target, &command),
        Command::Leap { target, command } => teleop_leap::service::run(&target, &command),
        Command::Calibrate {
            out,
            yes,
            no_pinch,
            settle,
            capture,
        } => calibrate::run(&ipc, &out, yes, !no_pinch, settle, capture),
        Command::View { args } => run_viewer(&ipc, &args),
        Command::Top { namespaces, task } => top::run(&ipc, &namespaces, task),
        Command::Doctor { file } => doctor::run(&file, &ipc),
        Command::Export {
            recordings,
            format: ExportFormat::Lerobot,
            options,
        } => export::run(&recordings, &options),
        Command::Episode { command } => {
            let mark = match command {
                EpisodeCommand::Start { task } => episode::Mark::Start { task },
                EpisodeCommand::Stop { success, failure } => episode::Mark::Stop {
                    outcome: episode::outcome(success, failure),
                },
                EpisodeCommand::Discard => episode::Mark::Discard,
            };
            episode::send(&ipc, &mark).and_then(|said| {
                out!("{said}")?;
                Ok(ExitCode::SUCCESS)
            })
        }
    };
    match result {
        Ok(code) => code,
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The replay speed: a finite factor from 0.001 to 1000 (`--max-speed` for as fast as
/// possible).
fn parse_speed(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| "not a number".to_string())?;
    if !(0.001..=1000.0).contains(&v) {
        return Err(
            "expected a factor from 0.001 to 1000 (--max-speed for as fast as possible)".into(),
        );
    }
    Ok(v)
}

/// Writes one line to standard output, returning the error instead of panicking like
/// `println!` (used through [`out!`]).
fn print_line(args: std::fmt::Arguments) -> std::io::Result<()> {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    stdout.write_fmt(args)?;
    stdout.write_all(b"\n")
}

/// Whether `e` is standard output's reader having gone away (`teleop echo ... | head`): the
/// command has nothing left to do, which is success.
fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

fn run_launch(
    file: &std::path::Path,
    ipc: &IpcSettings,
    duration: Option<Duration>,
    check: bool,
) -> anyhow::Result<ExitCode> {
    let launch = launch::config::load(file)?;
    if check {
        out!(
            "{}: {} processes: {}",
            file.display(),
            launch.processes.len(),
            launch
                .processes
                .iter()
                .map(|p| p.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )?;
        return Ok(ExitCode::SUCCESS);
    }
    match launch::supervisor::run(&launch, ipc, duration)? {
        launch::supervisor::Outcome::Stopped(_) => Ok(ExitCode::SUCCESS),
        launch::supervisor::Outcome::Failed(why) => {
            eprintln!("error: {why}");
            Ok(ExitCode::FAILURE)
        }
    }
}

/// `teleop view`: replaces this process with `teleop-viewer` (next to `teleop`, else from
/// PATH), passing the arguments on and the pipeline's IPC settings as environment variables.
/// The viewer lives in its own executable so that `teleop` does not depend on rerun.
fn run_viewer(ipc: &IpcSettings, args: &[String]) -> anyhow::Result<ExitCode> {
    use std::os::unix::process::CommandExt;
    const VIEWER: &str = "teleop-viewer";
    let program = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|dir| dir.join(VIEWER)))
        .filter(|p| p.is_file())
        .unwrap_or_else(|| PathBuf::from(VIEWER));
    let err = std::process::Command::new(&program)
        .args(args)
        .envs(ipc.to_env())
        .exec();
    anyhow::bail!(
        "could not run {}: {err} (build it with `cargo build -p teleop-viewer`; it is looked \
         for next to `teleop`, then in PATH)",
        program.display()
    )
}
