//! What a launch file's processes will open on this host: each device node's device (a serial
//! port, an EtherCAT interface, a CAN interface), read from its configuration file and its
//! arguments the way the node itself reads them (`--config FILE`, then `--port`, `--link` or
//! `--transport` overriding the file's key), and where each came from, for messages.
//!
//! A device another process of the launch file provides (a simulator's pseudo-terminal or
//! socket named in its arguments, an EtherCAT `sim:` socket, a CAN `local:` socket) is
//! simulated: it needs nothing of the host, and is only listed.

use std::fmt;
use std::path::{Path, PathBuf};

use teleop_allegro::can_link::LinkSpec;
use teleop_runtime::realtime::Realtime;
use teleop_runtime::{load_toml, ConfigFileError};

use super::Finding;
use crate::launch::config::{Launch, Process};

/// Where a setting comes from: a configuration file's key, a process argument in the launch
/// file, or a node's default.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Setting {
    /// The file (or `defaults`).
    pub origin: String,
    /// The key (`port`) or the argument (`args --port`).
    pub key: String,
}

impl fmt::Display for Setting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}, {}", self.origin, self.key)
    }
}

/// A real device a process opens.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Device {
    /// A serial port (the glove, the LEAP Hand's bus, an slcan adapter).
    Serial(PathBuf),
    /// A network interface the EtherCAT master opens a raw socket on.
    EtherCat(String),
    /// A SocketCAN interface.
    SocketCan(String),
}

/// A real device and the setting that names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Endpoint {
    /// The device.
    pub device: Device,
    /// Where it is configured.
    pub setting: Setting,
}

/// One process of the launch file, as far as the host checks go.
#[derive(Debug, Clone)]
pub struct ProcessPlan {
    /// Its name in the launch file.
    pub name: String,
    /// Its executable (resolved as `teleop launch` resolves it; a bare name when found
    /// nowhere but possibly in `PATH`).
    pub program: PathBuf,
    /// Its scheduling keys.
    pub realtime: Realtime,
    /// The real devices it opens.
    pub endpoints: Vec<Endpoint>,
    /// Simulated links it uses, described (`serial link /tmp/teleop-glove of sim-glove`).
    pub simulated: Vec<String>,
    /// It has an iceoryx2 node (and so shared memory).
    pub node: bool,
}

/// The launch file's processes and what reading their configurations found wrong.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Every process, in launch order.
    pub processes: Vec<ProcessPlan>,
    /// Processes whose device could not be told (an unreadable or invalid configuration): each
    /// would fail at start.
    pub problems: Vec<Finding>,
}

impl Plan {
    /// Whether any process opens a real device: then the launch file's real-time keys are
    /// requirements, not wishes.
    pub fn hardware(&self) -> bool {
        self.hardware_processes().next().is_some()
    }

    /// The names of the processes that open a real device.
    pub fn hardware_processes(&self) -> impl Iterator<Item = &str> {
        self.processes
            .iter()
            .filter(|p| !p.endpoints.is_empty())
            .map(|p| p.name.as_str())
    }
}

/// The device nodes and the argument that overrides their configuration's device key.
const DEVICE_NODES: [(&str, &str, &str); 5] = [
    ("teleop-glove", "--port", "port"),
    ("teleop-leap", "--port", "port"),
    ("teleop-allegro", "--link", "link"),
    ("teleop-revo2", "--transport", "transport"),
    ("teleop-shadow", "--transport", "transport"),
];

/// Reads what every process of `launch` will open.
pub fn plan(launch: &Launch) -> Plan {
    let mut plan = Plan {
        processes: Vec::new(),
        problems: Vec::new(),
    };
    for process in &launch.processes {
        let mut entry = ProcessPlan {
            name: process.name.clone(),
            program: program_path(launch, process),
            realtime: process.realtime.clone(),
            endpoints: Vec::new(),
            simulated: Vec::new(),
            node: process.node.is_some(),
        };
        if let Err(problem) = device_of(launch, process, &mut entry) {
            plan.problems.push(Finding::error(
                &process.name,
                format!("its device cannot be told: {problem}; the node would not start"),
                Some("correct the file or argument named".into()),
            ));
        }
        plan.processes.push(entry);
    }
    plan
}

/// Fills in the device of a device node (nothing for any other process).
fn device_of(launch: &Launch, process: &Process, entry: &mut ProcessPlan) -> Result<(), String> {
    let program = Path::new(&process.program)
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default();
    let Some(&(_, flag, key)) = DEVICE_NODES.iter().find(|(p, _, _)| *p == program) else {
        return Ok(());
    };
    let base = launch.base_dir();
    let config_file = arg_value(&process.args, "--config").map(|c| base.join(c));
    let (setting, value) = match arg_value(&process.args, flag) {
        Some(v) => (
            Setting {
                origin: launch.path.display().to_string(),
                key: format!("args {flag}"),
            },
            v.to_string(),
        ),
        None => {
            let value = config_value(program, config_file.as_deref()).map_err(|e| e.to_string())?;
            let origin = config_file
                .as_ref()
                .map_or_else(|| "defaults".to_string(), |f| f.display().to_string());
            (
                Setting {
                    origin,
                    key: key.to_string(),
                },
                value,
            )
        }
    };
    let provider = |path: &Path| provided_by(launch, process, path);
    let serial = |path: PathBuf, entry: &mut ProcessPlan, what: &str| {
        let path = base.join(path);
        match provider(&path) {
            Some(by) => entry
                .simulated
                .push(format!("{what} {} of {by}", path.display())),
            None => entry.endpoints.push(Endpoint {
                device: Device::Serial(path),
                setting: setting.clone(),
            }),
        }
    };
    match program {
        "teleop-glove" | "teleop-leap" => serial(PathBuf::from(value), entry, "serial link"),
        "teleop-allegro" => match value.parse::<LinkSpec>().map_err(|e| e.to_string())? {
            LinkSpec::Slcan { path, .. } => serial(path, entry, "slcan link"),
            LinkSpec::SocketCan { interface } => entry.endpoints.push(Endpoint {
                device: Device::SocketCan(interface),
                setting,
            }),
            LinkSpec::Local { socket } => entry
                .simulated
                .push(format!("CAN bus socket {}", base.join(socket).display())),
        },
        _ => match teleop_revo2::Transport::parse(&value)? {
            teleop_revo2::Transport::Sim(socket) => entry
                .simulated
                .push(format!("EtherCAT socket {}", base.join(socket).display())),
            teleop_revo2::Transport::Interface(name)
            | teleop_revo2::Transport::EthercrabInterface(name) => entry.endpoints.push(Endpoint {
                device: Device::EtherCat(name),
                setting,
            }),
        },
    }
    Ok(())
}

/// The device key of `program`'s configuration file (`None`: the node's defaults).
fn config_value(program: &str, file: Option<&Path>) -> Result<String, ConfigFileError> {
    fn load<C: serde::de::DeserializeOwned + Default>(
        file: Option<&Path>,
    ) -> Result<C, ConfigFileError> {
        file.map_or_else(|| Ok(C::default()), load_toml)
    }
    Ok(match program {
        "teleop-glove" => load::<teleop_glove::GloveConfig>(file)?
            .port
            .display()
            .to_string(),
        "teleop-leap" => load::<teleop_leap::LeapConfig>(file)?.port,
        "teleop-allegro" => load::<teleop_allegro::AllegroConfig>(file)?.link,
        "teleop-revo2" => load::<teleop_revo2::Revo2Config>(file)?.transport,
        _ => load::<teleop_shadow::ShadowConfig>(file)?.transport,
    })
}

/// The value of option `flag` in `args` (`--flag VALUE` or `--flag=VALUE`; the last one).
fn arg_value<'a>(args: &'a [String], flag: &str) -> Option<&'a str> {
    let mut found = None;
    let mut words = args.iter();
    while let Some(word) = words.next() {
        if word == flag {
            found = words.next().map(String::as_str);
        } else if let Some(v) = word.strip_prefix(flag).and_then(|r| r.strip_prefix('=')) {
            found = Some(v);
        }
    }
    found
}

/// The process of `launch` other than `user` that names `path` in its arguments (a simulator
/// serving the link there), if any.
fn provided_by(launch: &Launch, user: &Process, path: &Path) -> Option<String> {
    let base = launch.base_dir();
    launch
        .processes
        .iter()
        .filter(|p| p.name != user.name)
        .find(|p| {
            p.args.iter().any(|a| {
                let value = a.split_once('=').map_or(a.as_str(), |(_, v)| v);
                base.join(value) == path || base.join(a) == path
            })
        })
        .map(|p| p.name.clone())
}

/// Where `process`'s executable is: [`Launch::resolve_program`], then a `PATH` lookup of a
/// bare name (the file whose capabilities the process will have).
fn program_path(launch: &Launch, process: &Process) -> PathBuf {
    let resolved = launch.resolve_program(process);
    if resolved.components().count() > 1 {
        return resolved;
    }
    std::env::var_os("PATH")
        .into_iter()
        .flat_map(|paths| std::env::split_paths(&paths).collect::<Vec<_>>())
        .map(|dir| dir.join(&resolved))
        .find(|p| p.is_file())
        .unwrap_or(resolved)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn launch_in(dir: &Path, text: &str) -> Launch {
        let path = dir.join("launch.toml");
        std::fs::write(&path, text).unwrap();
        crate::launch::config::load(&path).unwrap()
    }

    #[test]
    fn arguments_are_read_as_the_nodes_read_them() {
        let args: Vec<String> = ["--config", "a.toml", "--port=/dev/x", "--port", "/dev/y"]
            .map(String::from)
            .to_vec();
        assert_eq!(arg_value(&args, "--config"), Some("a.toml"));
        assert_eq!(arg_value(&args, "--port"), Some("/dev/y"));
        assert_eq!(arg_value(&args, "--link"), None);
        assert_eq!(arg_value(&["--port".to_string()], "--port"), None);
    }

    #[test]
    fn a_simulators_link_is_simulated_and_a_real_port_is_named_with_its_setting() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("glove.toml"), "port = \"/dev/ttyUSB7\"\n").unwrap();
        std::fs::write(
            dir.path().join("revo2.toml"),
            "transport = \"interface:enp3s0\"\n",
        )
        .unwrap();
        let launch = launch_in(
            dir.path(),
            "[[process]]\nname = \"sim\"\nprogram = \"teleop-sim-glove\"\nargs = [\"--link\", \"/tmp/g\"]\n\
             [[process]]\nname = \"glove\"\nprogram = \"teleop-glove\"\nargs = [\"--config\", \"glove.toml\", \"--port\", \"/tmp/g\"]\n\
             [[process]]\nname = \"glove2\"\nprogram = \"teleop-glove\"\nargs = [\"--config\", \"glove.toml\"]\n\
             [[process]]\nname = \"hand\"\nprogram = \"./bin/teleop-revo2\"\nargs = [\"--config\", \"revo2.toml\"]\n\
             [[process]]\nname = \"allegro\"\nprogram = \"teleop-allegro\"\nargs = [\"--link\", \"socketcan:can1\"]\n\
             [[process]]\nname = \"retarget\"\nprogram = \"teleop-retarget\"\n",
        );
        let plan = plan(&launch);
        assert!(plan.problems.is_empty(), "{:?}", plan.problems);
        assert!(plan.hardware());
        let p = &plan.processes;
        assert!(p[1].endpoints.is_empty());
        assert_eq!(p[1].simulated, ["serial link /tmp/g of sim"]);
        let glove_file = dir.path().join("glove.toml").display().to_string();
        assert_eq!(
            p[2].endpoints,
            [Endpoint {
                device: Device::Serial("/dev/ttyUSB7".into()),
                setting: Setting {
                    origin: glove_file,
                    key: "port".into()
                }
            }]
        );
        assert_eq!(p[3].endpoints[0].device, Device::EtherCat("enp3s0".into()));
        assert_eq!(p[3].endpoints[0].setting.key, "transport");
        assert_eq!(p[4].endpoints[0].device, Device::SocketCan("can1".into()));
        assert_eq!(p[4].endpoints[0].setting.key, "args --link");
        assert!(p[5].endpoints.is_empty() && p[5].simulated.is_empty());
    }

    #[test]
    fn the_shipped_simulated_session_opens_no_real_device() {
        let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut files = vec![repo.join("launch.toml")];
        files.extend(
            std::fs::read_dir(repo.join("launch"))
                .unwrap()
                .map(|e| e.unwrap().path()),
        );
        for file in files {
            let launch = crate::launch::config::load(&file).unwrap();
            let plan = plan(&launch);
            assert!(
                plan.problems.is_empty(),
                "{}: {:?}",
                file.display(),
                plan.problems
            );
            assert!(!plan.hardware(), "{}: {:?}", file.display(), plan.processes);
        }
    }

    #[test]
    fn a_bad_configuration_is_a_problem_naming_the_process() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("revo2.toml"), "transport = \"eth0\"\n").unwrap();
        let launch = launch_in(
            dir.path(),
            "[[process]]\nname = \"hand\"\nprogram = \"teleop-revo2\"\nargs = [\"--config\", \"revo2.toml\"]\n\
             [[process]]\nname = \"glove\"\nprogram = \"teleop-glove\"\nargs = [\"--config\", \"missing.toml\"]\n",
        );
        let plan = plan(&launch);
        assert_eq!(plan.problems.len(), 2);
        assert_eq!(plan.problems[0].subject, "hand");
        assert!(plan.problems[0].text.contains("interface:NAME"));
        assert!(plan.problems[1].text.contains("missing.toml: cannot read"));
    }
}
