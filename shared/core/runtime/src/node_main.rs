//! The opening every node's `main` shares: logging, the arguments, the configuration file, the
//! node's IPC and the exit status, so that a node's `main.rs` is its own arguments and a call
//! into its library.
//!
//! - [`node_main`]: sets up logging ([`init_logging`](crate::init_logging)), parses the
//!   arguments (clap: `--help`, `--version`, and usage errors with status 2), runs the node and
//!   exits 0 when it returns, 1 when it fails, with the error logged as `stopping: <error>` (or,
//!   with [`NodeMain::failure_line`], printed as one line another program reads). SIGINT and
//!   SIGTERM are a clean stop: the node's loop returns ([`EventLoop`](crate::EventLoop),
//!   [`stop_signal`](crate::stop_signal)) and the process exits 0.
//! - [`NodeArgs`]: the arguments every node with a configuration file takes (`--config FILE`,
//!   `--name NAME`, whose default is the node's name), flattened into its own; the file loaded
//!   with its defaults when none is given, checks that name the file, the node's
//!   [`NodeRuntime`] in the IPC settings `teleop launch` gives it.

use std::fmt::Display;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use serde::de::DeserializeOwned;

use crate::{init_logging, load_toml, ConfigFileError, IpcSettings, NodeRuntime, RuntimeError};

/// The arguments every node with a configuration file takes; `#[command(flatten)]` them into
/// the node's own.
#[derive(Args, Debug, Clone)]
pub struct NodeArgs {
    /// Node configuration (TOML); defaults are used without it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// iceoryx2 node name.
    #[arg(long)]
    pub name: String,
}

impl NodeArgs {
    /// Where the configuration comes from, for messages: the file, or `defaults`.
    pub fn config_origin(&self) -> String {
        self.config
            .as_ref()
            .map_or_else(|| "defaults".to_string(), |p| p.display().to_string())
    }

    /// The configuration file `--config` names, or the defaults without one.
    pub fn load_config<C: DeserializeOwned + Default>(&self) -> Result<C, ConfigFileError> {
        self.config
            .as_deref()
            .map_or_else(|| Ok(C::default()), load_toml)
    }

    /// The result of checking the configuration, its error prefixed with where the
    /// configuration came from (`FILE: what is wrong`, or `defaults: ...`).
    pub fn check<T, E: Display>(&self, checked: Result<T, E>) -> Result<T, ConfigFileError> {
        checked.map_err(|e| ConfigFileError::Parse {
            origin: self.config_origin(),
            message: e.to_string(),
        })
    }

    /// The node's runtime: its name, in the IPC settings and namespace of the environment
    /// (`teleop launch` sets them).
    pub fn runtime(&self) -> Result<NodeRuntime, RuntimeError> {
        NodeRuntime::new(&self.name, &IpcSettings::from_env())
    }
}

/// How a node's `main` runs; [`node_main`] is the usual one.
#[derive(Debug, Clone, Copy)]
pub struct NodeMain {
    name: &'static str,
    failure_line: Option<&'static str>,
}

impl NodeMain {
    /// The `main` of node `name`: the default of its `--name` argument.
    pub const fn new(name: &'static str) -> Self {
        Self {
            name,
            failure_line: None,
        }
    }

    /// On failure, prints `PREFIX: <error>` as one line on stderr (for a program that reads it,
    /// e.g. the supervisor's `recording stopped: `, or a tool's `error: `) instead of logging
    /// `stopping: <error>`.
    pub const fn failure_line(self, prefix: &'static str) -> Self {
        Self {
            failure_line: Some(prefix),
            ..self
        }
    }

    /// Sets up logging, parses the arguments `A` (their `--name` defaults to the node's name),
    /// runs `run` with them and gives the exit status: success when it returns, failure when it
    /// fails (the error said once, see [`failure_line`](Self::failure_line)).
    pub fn run<A, E>(self, run: impl FnOnce(A) -> Result<(), E>) -> ExitCode
    where
        A: clap::Parser,
        E: Display,
    {
        init_logging();
        let matches = command::<A>(self.name).get_matches();
        let args = A::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
        match run(args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                match self.failure_line {
                    Some(prefix) => eprintln!("{prefix}: {e:#}"),
                    None => tracing::error!("stopping: {e:#}"),
                }
                ExitCode::FAILURE
            }
        }
    }
}

/// The command line of `A`, its `--name` defaulting to `name`.
fn command<A: clap::CommandFactory>(name: &'static str) -> clap::Command {
    A::command().mut_arg("name", |a| a.required(false).default_value(name))
}

/// The `main` of node `name` (see [`NodeMain::run`]): logging, the arguments `A`, `run`, and
/// the exit status, the error logged as `stopping: <error>`.
pub fn node_main<A, E>(name: &'static str, run: impl FnOnce(A) -> Result<(), E>) -> ExitCode
where
    A: clap::Parser,
    E: Display,
{
    NodeMain::new(name).run(run)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{FromArgMatches, Parser};

    #[derive(Parser, Debug)]
    struct Args {
        #[command(flatten)]
        node: NodeArgs,
        #[arg(long)]
        port: Option<String>,
    }

    fn parse(name: &'static str, argv: &[&str]) -> Result<Args, clap::Error> {
        let matches = command::<Args>(name)
            .try_get_matches_from(std::iter::once("teleop-test").chain(argv.iter().copied()))?;
        Args::from_arg_matches(&matches)
    }

    #[derive(serde::Deserialize, Default, Debug, PartialEq)]
    #[serde(deny_unknown_fields, default)]
    struct Config {
        rate_hz: u32,
    }

    #[test]
    fn the_name_defaults_to_the_node_s_and_the_flags_are_the_node_s_own() {
        let args = parse("glove", &["--port", "/dev/x"]).unwrap();
        assert_eq!(args.node.name, "glove");
        assert_eq!(args.node.config, None);
        assert_eq!(args.port.as_deref(), Some("/dev/x"));
        let args = parse("glove", &["--name", "left-glove", "--config", "g.toml"]).unwrap();
        assert_eq!(args.node.name, "left-glove");
        assert_eq!(args.node.config_origin(), "g.toml");
        assert!(parse("glove", &["--bogus"]).is_err());
    }

    #[test]
    fn a_configuration_is_its_file_or_the_defaults_and_its_errors_name_it() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("node.toml");
        let none = parse("n", &[]).unwrap().node;
        assert_eq!(none.load_config::<Config>().unwrap(), Config::default());
        let err = none.check(Err::<(), _>("rate_hz: must be positive"));
        assert_eq!(
            err.unwrap_err().to_string(),
            "defaults: rate_hz: must be positive"
        );
        std::fs::write(&file, "rate_hz = 5\n").unwrap();
        let args = parse("n", &["--config", file.to_str().unwrap()])
            .unwrap()
            .node;
        assert_eq!(args.load_config::<Config>().unwrap().rate_hz, 5);
        let err = args.check(Err::<(), _>("rate_hz: too fast")).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!("{}: rate_hz: too fast", file.display())
        );
        std::fs::write(&file, "rate = 5\n").unwrap();
        let err = args.load_config::<Config>().unwrap_err().to_string();
        assert!(err.starts_with(&format!("{}: ", file.display())) && err.contains("rate"));
    }
}
