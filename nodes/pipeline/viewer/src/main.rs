//! `teleop-viewer`: shows the live pipeline (or a recording) in a rerun viewer (see the
//! `teleop_viewer` library). `teleop view ARGS` runs this with the same arguments.

use std::net::{TcpStream, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use teleop_hand_profile::HandProfile;
use teleop_recording::Filter;
use teleop_runtime::{
    now_ns, qualified, IpcSettings, Namespace, NodeMain, NodeRuntime, ENV_IPC_PREFIX, ENV_IPC_ROOT,
    ENV_NAMESPACE,
};
use teleop_viewer::content::SceneConfig;
use teleop_viewer::kinematics::RobotHand;
use teleop_viewer::live::{run_live, LiveOptions};
use teleop_viewer::logger::RerunLogger;
use teleop_viewer::recording::view_recording;
use teleop_viewer::rerun::{self, RecordingStream, RecordingStreamBuilder};

/// How to install a viewer that reads what this SDK writes.
const INSTALL: &str =
    "`pip install rerun-sdk==0.36.3` (or `cargo install rerun-cli --version 0.36.3 --locked`)";

#[derive(Parser)]
#[command(
    version,
    about = "Show the live pipeline, or a recording, in a rerun viewer",
    after_help = "Without FILE: the live pipeline until Ctrl-C. Without --connect or --save: \
                  starts `rerun` from PATH (--spawn). The robot hand is drawn from --profile; \
                  else from the profile a recording embeds; else from the builtin profile of \
                  the first hand sample's model."
)]
struct Args {
    /// A recording (.mcap) to show instead of the live pipeline.
    file: Option<PathBuf>,
    /// The robot hand's profile (config/hands/<hand>.toml) to draw it with.
    #[arg(long, value_name = "FILE")]
    profile: Option<PathBuf>,
    /// The namespace of the topics to show (`left` shows `left/glove/state`, ...; a
    /// recording's channels `left/<topic>`); without it, the topics without a namespace.
    #[arg(long, value_name = "NS", env = ENV_NAMESPACE)]
    namespace: Option<Namespace>,
    /// Stream to a running viewer (default: rerun+http://127.0.0.1:9876/proxy).
    #[arg(
        long,
        value_name = "URL",
        num_args = 0..=1,
        default_missing_value = rerun::DEFAULT_CONNECT_URL,
        conflicts_with_all = ["spawn", "save"]
    )]
    connect: Option<String>,
    /// Start a viewer (`rerun` from PATH) and stream to it (the default).
    #[arg(long, conflicts_with = "save")]
    spawn: bool,
    /// Write an .rrd file instead (open it later with `rerun FILE.rrd`).
    #[arg(long, value_name = "FILE.rrd")]
    save: Option<PathBuf>,
    /// Recording: seconds from its start to begin at.
    #[arg(long, requires = "file")]
    start: Option<f64>,
    /// Recording: seconds from its start to end at.
    #[arg(long, requires = "file")]
    end: Option<f64>,
    /// Recording: only these topics (in --namespace).
    #[arg(long, num_args = 1.., requires = "file")]
    topics: Option<Vec<String>>,
    /// Most samples per second per topic and publisher shown as scalars (0: all).
    #[arg(long, default_value_t = 100.0)]
    scalar_hz: f64,
    /// Most 3D poses and bar chart updates per second per topic (0: all).
    #[arg(long, default_value_t = 30.0)]
    pose_hz: f64,
    /// Live: samples queued for the logging thread before new ones are dropped (and counted).
    #[arg(long, default_value_t = 4096)]
    queue: usize,
    /// Live: stop after this many seconds.
    #[arg(long)]
    duration: Option<f64>,
    /// Live: the viewer's iceoryx2 node name.
    #[arg(long)]
    name: String,
    /// Live: iceoryx2 root path of the pipeline.
    #[arg(long, env = ENV_IPC_ROOT)]
    ipc_root: Option<String>,
    /// Live: iceoryx2 prefix of the pipeline (default `teleop_`).
    #[arg(long, env = ENV_IPC_PREFIX)]
    ipc_prefix: Option<String>,
}

fn main() -> ExitCode {
    NodeMain::new("viewer")
        .failure_line("error")
        .run(|args: Args| run(&args))
}

fn run(args: &Args) -> anyhow::Result<()> {
    let scene = SceneConfig {
        scalar_hz: args.scalar_hz,
        pose_hz: args.pose_hz,
        time_origin_ns: now_ns(),
    };
    let robot = match &args.profile {
        Some(path) => Some(RobotHand::new(
            HandProfile::load(path)?,
            path.display().to_string(),
        )),
        None => None,
    };
    match &args.file {
        Some(file) => {
            let name = file
                .file_name()
                .map_or_else(|| "recording".into(), |n| n.to_string_lossy().into_owned());
            let rec = open_stream(args, &name)?;
            let logger = RerunLogger::new(rec.clone());
            let namespace = args.namespace.as_ref();
            let filter = Filter {
                topics: args
                    .topics
                    .as_ref()
                    .map(|topics| topics.iter().map(|t| qualified(namespace, t)).collect()),
                start: args.start.map(secs),
                end: args.end.map(secs),
            };
            let summary = view_recording(file, &filter, namespace, &logger, scene, robot, true)?;
            finish(args, &rec)?;
            eprintln!(
                "{}: {} messages, {} frames logged{}",
                file.display(),
                summary.messages,
                summary.frames,
                match &args.save {
                    Some(out) => format!(", written to {}", out.display()),
                    None => String::new(),
                }
            );
        }
        None => {
            // Viewing must never compete with the control loops for the CPU: lower this
            // process's priority (and that of a viewer it spawns) before anything starts.
            lower_priority();
            let settings = IpcSettings {
                root: args.ipc_root.clone().filter(|s| !s.is_empty()),
                prefix: args.ipc_prefix.clone().filter(|s| !s.is_empty()),
                namespace: None,
            };
            let runtime = NodeRuntime::new(&args.name, &settings)?;
            let rec = open_stream(args, "live")?;
            let options = LiveOptions {
                scene,
                queue: args.queue,
                duration: args
                    .duration
                    .map(|s| Duration::from_secs_f64(s.clamp(0.0, 1e6))),
                ..LiveOptions::default()
            };
            let summary = run_live(&runtime, RerunLogger::new(rec.clone()), &options, robot)?;
            finish(args, &rec)?;
            eprintln!(
                "viewed {} samples ({} frames); dropped {} (viewer behind), missed {}, \
                 decimated {}",
                summary.forwarded,
                summary.frames,
                summary.queue_full,
                summary.missed,
                summary.decimated
            );
        }
    }
    Ok(())
}

/// The recording stream for the chosen sink (the sources send the layout).
fn open_stream(args: &Args, recording_name: &str) -> anyhow::Result<RecordingStream> {
    let builder = RecordingStreamBuilder::new("teleop").recording_name(recording_name);
    if let Some(url) = &args.connect {
        check_listening(url)?;
        return Ok(builder.connect_grpc_opts(url.clone())?);
    }
    if let Some(path) = &args.save {
        return Ok(builder.save(path)?);
    }
    if find_in_path("rerun").is_none() {
        anyhow::bail!(
            "--spawn: the rerun viewer (`rerun`) is not on PATH; install a matching one with \
             {INSTALL}, or use --save FILE.rrd or --connect URL"
        );
    }
    builder.spawn().map_err(|e| {
        anyhow::anyhow!("--spawn: could not start the rerun viewer: {e}; install: {INSTALL}")
    })
}

/// Fails at once when nothing listens at a `--connect` URL (`rerun+http://HOST:PORT/proxy`),
/// rather than streaming into a connection that is retried in the background.
fn check_listening(url: &str) -> anyhow::Result<()> {
    let address = url
        .split_once("://")
        .map_or(url, |(_, rest)| rest)
        .split('/')
        .next()
        .unwrap_or_default();
    let reachable = address
        .to_socket_addrs()
        .ok()
        .and_then(|mut addrs| {
            addrs.find(|a| TcpStream::connect_timeout(a, Duration::from_secs(2)).is_ok())
        })
        .is_some();
    if !reachable {
        anyhow::bail!(
            "--connect: no rerun viewer is listening at {url}; start one with `rerun` \
             (install: {INSTALL}), or use --spawn or --save FILE.rrd"
        );
    }
    Ok(())
}

/// Waits until what was logged reached the sink (a file is finished when the stream is
/// dropped). A viewer that went away is not waited for any longer than that.
fn finish(args: &Args, rec: &RecordingStream) -> anyhow::Result<()> {
    let timeout = if args.save.is_some() {
        Duration::MAX
    } else {
        Duration::from_secs(10)
    };
    rec.flush_with_timeout(timeout).map_err(|e| {
        // Dropping the last handle would wait for the lost viewer once more: keep one alive
        // (the process is about to exit anyway).
        std::mem::forget(rec.clone());
        anyhow::anyhow!("sending the last data to the viewer failed: {e}")
    })
}

fn secs(s: f64) -> Duration {
    Duration::from_secs_f64(if s.is_finite() {
        s.clamp(0.0, 1e6)
    } else {
        0.0
    })
}

fn find_in_path(program: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(program))
        .find(|p| is_executable(p))
}

fn is_executable(p: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    p.metadata()
        .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

fn lower_priority() {
    // SAFETY: nice() only changes this process's scheduling priority.
    let r = unsafe { libc::nice(10) };
    if r == -1 {
        tracing::debug!("could not lower the viewer's priority");
    }
}
