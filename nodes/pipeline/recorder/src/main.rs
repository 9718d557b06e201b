//! `teleop-recorder`: records every topic into MCAP until SIGINT/SIGTERM (see the
//! `teleop_recorder` library).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use teleop_recorder::{
    file_metadata, launch_session, record, report, standard_metadata, Output, RecordOptions,
    SESSION_METADATA,
};
use teleop_recording::WriterOptions;
use teleop_runtime::{IpcSettings, Namespace, NodeMain, NodeRuntime};

#[derive(Parser)]
#[command(version, about = "Record the pipeline's topics into MCAP")]
struct Args {
    /// Output file (default: `<dir>/<UTC date>_<time>.<ms>.mcap`, `-2`, `-3`, ... added when
    /// another recorder took the name).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Folder for the default output name.
    #[arg(long, default_value = "recordings")]
    dir: PathBuf,
    /// Record only these topics.
    #[arg(long, num_args = 1..)]
    topics: Option<Vec<String>>,
    /// Record the topics of this namespace (repeatable) into channels named `NS/<topic>`;
    /// without it, the topics without a namespace.
    #[arg(long = "namespace", value_name = "NS")]
    namespaces: Vec<Namespace>,
    /// Start a new file after this many megabytes (at least 1).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    rotate_mb: Option<u64>,
    /// Start a new file after this many seconds (at least 1).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    rotate_s: Option<u64>,
    /// Embed a file as a metadata record, e.g. `--metadata calibration=config/operator.toml`.
    #[arg(long, value_parser = parse_metadata)]
    metadata: Vec<(String, PathBuf)>,
    /// iceoryx2 node name.
    #[arg(long)]
    name: String,
}

fn parse_metadata(s: &str) -> Result<(String, PathBuf), String> {
    let (name, path) = s.split_once('=').ok_or("expected NAME=FILE")?;
    Ok((name.to_string(), PathBuf::from(path)))
}

fn main() -> ExitCode {
    // On failure the line `teleop launch` looks for to say RECORDING STOPPED in its summary.
    NodeMain::new("recorder")
        .failure_line("recording stopped")
        .run(|args: Args| run(&args))
}

fn run(args: &Args) -> anyhow::Result<()> {
    let mut metadata = standard_metadata();
    for (name, path) in &args.metadata {
        let m = file_metadata(path).ok_or_else(|| {
            anyhow::anyhow!("--metadata {name}={}: cannot read the file", path.display())
        })?;
        metadata.push((name.clone(), m));
    }
    // Started by `teleop launch`: which session, so that a restarted recorder finds the files
    // of the one before it.
    if let Some(session) = launch_session(&args.name) {
        metadata.push((SESSION_METADATA.to_string(), session));
    }
    let options = RecordOptions {
        out: args
            .out
            .clone()
            .map_or_else(|| Output::Timestamped(args.dir.clone()), Output::File),
        topics: args.topics.clone(),
        namespaces: args.namespaces.clone(),
        writer: WriterOptions {
            rotate_bytes: args.rotate_mb.map(|mb| mb.saturating_mul(1_000_000)),
            rotate_after: args.rotate_s.map(std::time::Duration::from_secs),
            ..WriterOptions::default()
        },
        metadata,
        duration: None,
        announce: true,
    };
    let runtime = NodeRuntime::new(&args.name, &IpcSettings::from_env())?;
    let recorded = record(&runtime, &options)?;
    eprint!("{}", report(&recorded.summary));
    match recorded.stopped {
        None => Ok(()),
        Some(why) => Err(anyhow::anyhow!(why)),
    }
}
