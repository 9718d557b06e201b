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
use std::time::{Duration, Instant};

use teleop_msgs::{fixed_text, EStop, EStopAck};
use teleop_namespace::Namespace;

use crate::ipc::{IpcSettings, NodeRuntime, RuntimeError};
use crate::ports::{Publisher, Subscriber};

/// The latch file of `namespace` for the pipeline of `settings`.
pub fn latch_path(settings: &IpcSettings, namespace: Option<&Namespace>) -> PathBuf {
    let prefix = settings.file_prefix();
    let name = match namespace {
        None => format!("{prefix}estop"),
        Some(ns) => format!("{prefix}estop.{}", ns.as_str().replace('/', ".")),
    };
    settings.root_dir().join(name)
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
///
/// Engaging is the easy direction: the latch is engaged as soon as the file exists, so the file
/// is created first and the text naming who engaged it is written after; when only the text
/// cannot be written (a full disk), the latch is still engaged and this returns `Ok` with a
/// warning. A symbolic link at `path` is never followed (its target is not touched); since it
/// already reads as engaged to every node, engaging over it succeeds, releasing it fails.
/// Both directions hold the latch directory's lock ([`LatchLock`]) while they change the file:
/// engaging goes on without it when it cannot be taken, releasing does not.
pub fn set_latch_by(path: &Path, engaged: bool, by: &str) -> io::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    if engaged {
        let _lock = LatchLock::take(path)
            .inspect_err(
                |e| tracing::warn!(path = %path.display(), "engaging without the latch lock: {e}"),
            )
            .ok();
        engage(path, by)?;
    } else {
        let _lock = LatchLock::take(path)?;
        remove(path)?;
    }
    sync_dir(path)
}

/// Releases the latch at `path` only when `by` engaged it (its text names `by`), under the latch
/// lock, so that a `teleop estop` engaged in between is never removed: returns whether it
/// released. A latch already released counts as released (`true`).
pub fn release_latch_held_by(path: &Path, by: &str) -> io::Result<bool> {
    let _lock = LatchLock::take(path)?;
    let holder = match read_latch(path) {
        Ok(text) => text,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(true),
        Err(e) => return Err(e),
    };
    if !holder.contains(&format!("engaged by {by} ")) {
        return Ok(false);
    }
    remove(path)?;
    sync_dir(path)?;
    Ok(true)
}

/// Creates the latch file (never through a symbolic link), then writes who engaged it.
fn engage(path: &Path, by: &str) -> io::Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .custom_flags(libc::O_NOFOLLOW)
        .mode(0o644)
        .open(path);
    let mut file = match file {
        Ok(file) => file,
        // ELOOP: a symbolic link is there. It reads as engaged (lstat), so the latch is engaged.
        Err(e) if e.raw_os_error() == Some(libc::ELOOP) => {
            tracing::warn!(
                path = %path.display(),
                "the e-stop latch path is a symbolic link: not followed; it reads as engaged; \
                 remove it before releasing"
            );
            return Ok(());
        }
        Err(e) => return Err(e),
    };
    let text = writeln!(
        file,
        "e-stop engaged by {by} (pid {}); release with `teleop estop --release`",
        std::process::id()
    )
    .and_then(|()| file.sync_all());
    if let Err(e) = text {
        tracing::warn!(
            path = %path.display(),
            "e-stop latch engaged, but who engaged it could not be written: {e}"
        );
    }
    Ok(())
}

/// Removes the latch file; a symbolic link is refused (it was not made by a latch writer).
fn remove(path: &Path) -> io::Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.file_type().is_symlink() => {
            return Err(io::Error::other(format!(
                "{} is a symbolic link, not an e-stop latch: refusing to release through it; \
                 remove it by hand if it is yours",
                path.display()
            )))
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
        _ => {}
    }
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    }
}

fn sync_dir(path: &Path) -> io::Result<()> {
    match path.parent() {
        Some(dir) => std::fs::File::open(dir)?.sync_all(),
        None => Ok(()),
    }
}

/// The latch file's text, never through a symbolic link.
fn read_latch(path: &Path) -> io::Result<String> {
    use std::io::Read;
    use std::os::unix::fs::OpenOptionsExt;
    let mut text = String::new();
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)?
        .read_to_string(&mut text)?;
    Ok(text)
}

/// An exclusive `flock` on the directory that holds the latch files: every writer of a latch
/// (`teleop estop`, a station's bridge) holds it while it reads and changes a latch, so a
/// release that checks who engaged the latch and then removes it cannot remove an e-stop
/// engaged in between. Locking the directory creates no file (it works on a full disk).
struct LatchLock {
    _dir: std::fs::File,
}

impl LatchLock {
    fn take(latch: &Path) -> io::Result<Self> {
        use std::os::fd::AsRawFd;
        let dir = latch.parent().unwrap_or(Path::new("."));
        let file = std::fs::File::open(dir)?;
        // SAFETY: flock(2) on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX) } != 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(Self { _dir: file })
    }
}

/// The text of the engaged latch at `path` (who engaged it), `None` when it is released or
/// cannot be read.
pub fn latch_holder(path: &Path) -> Option<String> {
    read_latch(path).ok()
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

/// How often a node reads its latch files even when the doorbell did not ring: an e-stop whose
/// doorbell could not be rung (iceoryx2 failing on a full disk) still stops it within this.
pub const LATCH_POLL: Duration = Duration::from_millis(50);

/// A node's e-stop input: the doorbell, the latch file and the acknowledgement it publishes.
pub struct EStopInput {
    doorbell: Subscriber<EStop>,
    ack: RefCell<Publisher<EStopAck>>,
    /// The latch of the node's namespace and, in a namespace, the plain latch too: `teleop
    /// estop` without a namespace stops every side, also sides that start later.
    paths: [Option<CString>; 2],
    engaged: Cell<bool>,
    /// When the latch files were last read.
    checked: Cell<Instant>,
    name: [u8; 32],
}

impl EStopInput {
    /// Subscribes to `estop` in the node's namespace, then reads the latch and the topic's
    /// history, and acknowledges the state found.
    pub fn new(runtime: &NodeRuntime) -> Result<Self, RuntimeError> {
        let doorbell = runtime.subscriber::<EStop>()?;
        let c_path = |path: &Path| {
            CString::new(path.as_os_str().as_bytes()).map_err(|_| RuntimeError::Settings {
                what: "e-stop latch path",
                value: path.display().to_string(),
                reason: "contains a NUL byte".into(),
            })
        };
        let plain = match runtime.namespace() {
            Some(_) => Some(c_path(runtime.plain_estop_latch())?),
            None => None,
        };
        let input = Self {
            doorbell,
            ack: RefCell::new(runtime.publisher()?),
            paths: [Some(c_path(runtime.estop_latch())?), plain],
            engaged: Cell::new(false),
            checked: Cell::new(Instant::now()),
            name: fixed_text(runtime.name()),
        };
        let newest = input.doorbell.poll_latest();
        input.engaged.set(decide(input.latched(), newest.as_ref()));
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

    /// True when a latch file of this node says engaged (or cannot be read).
    fn latched(&self) -> bool {
        self.checked.set(Instant::now());
        self.paths.iter().flatten().any(|p| latch_engaged(p))
    }

    /// Takes the pending `estop` samples without blocking; when there were any, reads the latch
    /// again and acknowledges. Without a sample, reads the latch files when [`LATCH_POLL`] has
    /// passed since they were last read, and engages (never releases) on what it finds: an
    /// e-stop whose doorbell could not be rung still stops the node. Returns the new state when
    /// it changed. Takes `&self`, so the input can be attached to an
    /// [`EventLoop`](crate::EventLoop) and updated from its callback. Allocates nothing.
    pub fn update(&self) -> Result<Option<bool>, RuntimeError> {
        let mut newest = None;
        if self.doorbell.drain(|e| newest = Some(*e)) == 0 {
            if self.engaged.get() || self.checked.get().elapsed() < LATCH_POLL || !self.latched() {
                return Ok(None);
            }
            tracing::warn!("e-stop latch found engaged without its doorbell: engaged");
            self.engaged.set(true);
            self.acknowledge()?;
            return Ok(Some(true));
        }
        let engaged = decide(self.latched(), newest.as_ref());
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
    fn a_symlink_at_the_latch_is_never_followed() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("precious");
        std::fs::write(&target, b"keep me").unwrap();
        let path = dir.path().join("p_estop");
        std::os::unix::fs::symlink(&target, &path).unwrap();
        let c = CString::new(path.as_os_str().as_bytes()).unwrap();
        assert!(latch_engaged(&c), "a link there reads as engaged");
        set_latch(&path, true).unwrap();
        assert_eq!(
            std::fs::read(&target).unwrap(),
            b"keep me",
            "target untouched"
        );
        assert_eq!(latch_holder(&path), None, "not read through the link");
        let e = set_latch(&path, false).unwrap_err().to_string();
        assert!(e.contains("is a symbolic link, not an e-stop latch"), "{e}");
        assert!(latch_engaged(&c), "release refused: still engaged");
        assert_eq!(std::fs::read(&target).unwrap(), b"keep me");
    }

    #[test]
    fn a_release_by_its_holder_leaves_an_e_stop_engaged_by_someone_else() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p_estop");
        assert!(
            release_latch_held_by(&path, "bridge").unwrap(),
            "nothing to release"
        );
        set_latch_by(&path, true, "bridge").unwrap();
        // A `teleop estop` engaged since: the bridge's release does not remove it.
        set_latch(&path, true).unwrap();
        assert!(!release_latch_held_by(&path, "bridge").unwrap());
        assert!(latch_holder(&path).unwrap().contains("`teleop estop`"));
        set_latch_by(&path, true, "bridge").unwrap();
        assert!(release_latch_held_by(&path, "bridge").unwrap());
        assert_eq!(latch_holder(&path), None);
        // While another writer holds the lock, the release waits for it.
        set_latch_by(&path, true, "bridge").unwrap();
        let lock = LatchLock::take(&path).unwrap();
        let p = path.clone();
        let releaser = std::thread::spawn(move || release_latch_held_by(&p, "bridge").unwrap());
        std::thread::sleep(std::time::Duration::from_millis(100));
        // The lock's holder engages (as `teleop estop` does under the lock).
        engage(&path, "`teleop estop`").unwrap();
        drop(lock);
        assert!(!releaser.join().unwrap());
        assert!(latch_holder(&path).unwrap().contains("`teleop estop`"));
    }

    #[test]
    fn a_latch_written_without_a_doorbell_engages_within_the_poll_and_a_namespace_obeys_the_plain_latch(
    ) {
        let dir = tempfile::tempdir().unwrap();
        let mut settings = IpcSettings::isolated(dir.path());
        settings.namespace = Some("left".into());
        let runtime = NodeRuntime::new("n", &settings).unwrap();
        let input = EStopInput::new(&runtime).unwrap();
        assert!(!input.engaged());
        // The plain latch (no namespace), written without ringing any doorbell.
        set_latch(runtime.plain_estop_latch(), true).unwrap();
        let deadline = Instant::now() + Duration::from_secs(2);
        while !input.engaged() && Instant::now() < deadline {
            input.update().unwrap();
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(input.engaged(), "engaged by reading the latch");
        // The poll never releases: removing the file without the doorbell changes nothing.
        set_latch(runtime.plain_estop_latch(), false).unwrap();
        std::thread::sleep(LATCH_POLL * 2);
        assert_eq!(input.update().unwrap(), None);
        assert!(input.engaged());
        // A node of the namespace that starts while the plain latch is engaged obeys it.
        set_latch(runtime.plain_estop_latch(), true).unwrap();
        let later = EStopInput::new(&NodeRuntime::new("m", &settings).unwrap()).unwrap();
        assert!(later.engaged());
        drop((input, later, runtime));
        settings.remove_shared_memory();
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
