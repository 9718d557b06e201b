//! The latched e-stop: a latch file per namespace that outlives every process (the state), the
//! `estop` topic that tells running nodes it changed (the doorbell), and `estop/ack`, on which
//! every node that obeys it answers with the state it now holds.
//!
//! The latch file lives next to the pipeline's iceoryx2 files (`<root>/<prefix>estop`, in a
//! namespace `<root>/<prefix>estop.left`, `/` of a nested namespace as `.`): it exists while the
//! e-stop is engaged. `teleop estop` creates it (and syncs it to disk) before it rings the
//! doorbell and removes it only on `--release`. A node subscribes to the doorbell before it
//! reads the file, so an e-stop is never lost between the two: a node that starts (or restarts)
//! while the e-stop is engaged finds the file; a running node is woken by the doorbell.
//!
//! Engaging is easy, releasing is not: the node is engaged when the file exists, when it cannot
//! tell (any error but "not found"), or when the newest `estop` sample says engaged (a tool that
//! only publishes still stops the pipeline); a released sample releases only when the file is
//! gone.

use std::cell::{Cell, RefCell};
use std::ffi::{CStr, CString};
use std::io;
use std::os::unix::ffi::OsStrExt;
use std::path::{Path, PathBuf};

use teleop_msgs::{fixed_text, EStop, EStopAck};
use teleop_namespace::Namespace;

use crate::ipc::{IpcSettings, NodeRuntime, RuntimeError};
use crate::ports::{Publisher, Subscriber};

/// iceoryx2's root directory when the settings name none.
const DEFAULT_ROOT: &str = "/tmp/iceoryx2/";

/// The latch file of `namespace` for the pipeline of `settings`.
pub fn latch_path(settings: &IpcSettings, namespace: Option<&Namespace>) -> PathBuf {
    let root = settings.root.as_deref().unwrap_or(DEFAULT_ROOT);
    let prefix = settings.prefix.as_deref().unwrap_or("teleop_");
    let name = match namespace {
        None => format!("{prefix}estop"),
        Some(ns) => format!("{prefix}estop.{}", ns.as_str().replace('/', ".")),
    };
    Path::new(root).join(name)
}

/// The namespaces whose latch is engaged in the pipeline of `settings` (not the topics without
/// a namespace), sorted: `teleop estop --release` releases them even when none of their nodes
/// runs.
pub fn latched_namespaces(settings: &IpcSettings) -> Vec<Namespace> {
    let plain = latch_path(settings, None);
    let (Some(dir), Some(stem)) = (plain.parent(), plain.file_name()) else {
        return Vec::new();
    };
    let mut stem = stem.to_os_string();
    stem.push(".");
    let stem = stem.as_bytes();
    let mut found: Vec<Namespace> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|entry| {
            let name = entry.file_name();
            let rest = name.as_bytes().strip_prefix(stem)?;
            Namespace::new(&std::str::from_utf8(rest).ok()?.replace('.', "/")).ok()
        })
        .collect();
    found.sort();
    found
}

/// Engages (creates and syncs the file) or releases (removes it) the latch at `path`, as
/// `teleop estop` does.
pub fn set_latch(path: &Path, engaged: bool) -> io::Result<()> {
    set_latch_by(path, engaged, "`teleop estop`")
}

/// [`set_latch`] naming who engaged it in the file (`by`), so that a process that engages the
/// latch for someone else (the robot station's bridge, for the operator's e-stop) can later tell
/// whether the latch is still the one it engaged ([`latch_holder`]).
pub fn set_latch_by(path: &Path, engaged: bool, by: &str) -> io::Result<()> {
    use std::io::Write;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    if engaged {
        let mut file = std::fs::File::create(path)?;
        writeln!(
            file,
            "e-stop engaged by {by} (pid {}); release with `teleop estop --release`",
            std::process::id()
        )?;
        file.sync_all()?;
    } else {
        match std::fs::remove_file(path) {
            Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
            _ => {}
        }
    }
    if let Some(dir) = path.parent() {
        std::fs::File::open(dir)?.sync_all()?;
    }
    Ok(())
}

/// The text of the engaged latch at `path` (who engaged it), `None` when it is released or
/// cannot be read.
pub fn latch_holder(path: &Path) -> Option<String> {
    std::fs::read_to_string(path).ok()
}

/// True when the latch at `path` is engaged: the file exists, or whether it does cannot be told
/// (an error other than "not found": fail safe). Allocates nothing (called from control loops).
pub fn latch_engaged(path: &CStr) -> bool {
    // SAFETY: `path` is NUL-terminated; `stat` is a plain struct that lstat(2) fills.
    let mut stat: libc::stat = unsafe { core::mem::zeroed() };
    // SAFETY: both pointers are valid for the call.
    if unsafe { libc::lstat(path.as_ptr(), &mut stat) } == 0 {
        return true;
    }
    let error = io::Error::last_os_error();
    if error.kind() == io::ErrorKind::NotFound {
        return false;
    }
    tracing::warn!(path = ?path, %error, "cannot read the e-stop latch: engaged");
    true
}

/// A node's e-stop input: the doorbell, the latch file and the acknowledgement it publishes.
pub struct EStopInput {
    doorbell: Subscriber<EStop>,
    ack: RefCell<Publisher<EStopAck>>,
    path: CString,
    engaged: Cell<bool>,
    name: [u8; 32],
}

impl EStopInput {
    /// Subscribes to `estop` in the node's namespace, then reads the latch and the topic's
    /// history, and acknowledges the state found.
    pub fn new(runtime: &NodeRuntime) -> Result<Self, RuntimeError> {
        let doorbell = runtime.subscriber::<EStop>()?;
        let input = Self {
            doorbell,
            ack: RefCell::new(runtime.publisher()?),
            path: CString::new(runtime.estop_latch().as_os_str().as_bytes()).map_err(|_| {
                RuntimeError::Settings {
                    what: "e-stop latch path",
                    value: runtime.estop_latch().display().to_string(),
                    reason: "contains a NUL byte".into(),
                }
            })?,
            engaged: Cell::new(false),
            name: fixed_text(runtime.name()),
        };
        let newest = input.doorbell.poll_latest();
        input
            .engaged
            .set(decide(latch_engaged(&input.path), newest.as_ref()));
        input.acknowledge()?;
        Ok(input)
    }

    /// The doorbell's event port (for an [`EventLoop`](crate::EventLoop)).
    pub fn listener(&self) -> &iceoryx2::port::listener::Listener<crate::Service> {
        self.doorbell.listener()
    }

    /// True while the e-stop is engaged.
    pub fn engaged(&self) -> bool {
        self.engaged.get()
    }

    /// Takes the pending `estop` samples without blocking; when there were any, reads the latch
    /// again and acknowledges. Returns the new state when it changed. Takes `&self`, so the
    /// input can be attached to an [`EventLoop`](crate::EventLoop) and updated from its callback.
    pub fn update(&self) -> Result<Option<bool>, RuntimeError> {
        let mut newest = None;
        if self.doorbell.drain(|e| newest = Some(*e)) == 0 {
            return Ok(None);
        }
        let engaged = decide(latch_engaged(&self.path), newest.as_ref());
        let changed = (engaged != self.engaged.get()).then_some(engaged);
        self.engaged.set(engaged);
        self.acknowledge()?;
        Ok(changed)
    }

    fn acknowledge(&self) -> Result<(), RuntimeError> {
        self.ack.borrow_mut().publish(&EStopAck {
            engaged: u8::from(self.engaged.get()),
            node_name: self.name,
            ..Default::default()
        })?;
        Ok(())
    }
}

/// The e-stop state from the latch and the newest sample: engaged if either says so.
fn decide(latched: bool, newest: Option<&EStop>) -> bool {
    latched || newest.is_some_and(|e| e.engaged != 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latch_file_per_namespace_next_to_the_ipc_files() {
        let settings = IpcSettings {
            root: Some("/r".into()),
            prefix: Some("p_".into()),
            namespace: None,
        };
        let ns = Namespace::new("cell2/left").unwrap();
        assert_eq!(latch_path(&settings, None), Path::new("/r/p_estop"));
        assert_eq!(
            latch_path(&settings, Some(&ns)),
            Path::new("/r/p_estop.cell2.left")
        );
    }

    #[test]
    fn latched_namespaces_are_found_by_their_files() {
        let dir = tempfile::tempdir().unwrap();
        let settings = IpcSettings::isolated(dir.path());
        assert!(latched_namespaces(&settings).is_empty());
        let left = Namespace::new("cell2/left").unwrap();
        let right = Namespace::new("right").unwrap();
        for ns in [None, Some(&left), Some(&right)] {
            set_latch(&latch_path(&settings, ns), true).unwrap();
        }
        std::fs::write(dir.path().join("unrelated"), b"").unwrap();
        assert_eq!(latched_namespaces(&settings), vec![left.clone(), right]);
        set_latch(&latch_path(&settings, Some(&left)), false).unwrap();
        assert_eq!(latched_namespaces(&settings).len(), 1);
    }

    #[test]
    fn set_and_read_the_latch() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub").join("p_estop");
        let c = CString::new(path.as_os_str().as_bytes()).unwrap();
        assert!(!latch_engaged(&c));
        set_latch(&path, true).unwrap();
        assert!(latch_engaged(&c));
        assert!(latch_holder(&path)
            .unwrap()
            .contains("engaged by `teleop estop` (pid"));
        set_latch_by(&path, true, "teleop-bridge for station operator").unwrap();
        assert!(latch_holder(&path)
            .unwrap()
            .contains("engaged by teleop-bridge for station operator"));
        set_latch(&path, true).unwrap();
        set_latch(&path, false).unwrap();
        assert_eq!(latch_holder(&path), None);
        assert!(!latch_engaged(&c));
        set_latch(&path, false).unwrap();
    }

    #[test]
    fn an_unreadable_latch_counts_as_engaged() {
        let dir = tempfile::tempdir().unwrap();
        // A path through a regular file: ENOTDIR, neither present nor absent.
        let file = dir.path().join("f");
        std::fs::write(&file, b"").unwrap();
        let c = CString::new(file.join("estop").as_os_str().as_bytes()).unwrap();
        assert!(latch_engaged(&c));
    }

    #[test]
    fn engaging_is_easy_releasing_needs_the_latch_gone() {
        let on = EStop {
            engaged: 1,
            ..Default::default()
        };
        let off = EStop::default();
        assert!(decide(true, None));
        assert!(decide(true, Some(&off)));
        assert!(decide(false, Some(&on)));
        assert!(!decide(false, Some(&off)));
        assert!(!decide(false, None));
    }
}
