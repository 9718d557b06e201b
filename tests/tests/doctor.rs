//! `teleop doctor` against conditions it must catch, run as a user runs it (the built `teleop`
//! on launch files in a sandbox): no real-time right (`prlimit --rtprio=0`, and `setpriv`
//! dropping `sys_nice` as root), a missing serial port, an EtherCAT interface that carries an IP
//! address (a veth in a network namespace, as root); and the shipped simulated session passing.

use std::os::fd::{FromRawFd, OwnedFd};
use std::path::Path;
use std::process::Command;

use teleop_e2e::{bin, netns, rig, Sandbox};

/// Whether the doctor's output has an error line.
fn has_error(out: &str) -> bool {
    out.lines().any(|l| l.starts_with("error"))
}

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() == 0 }
}

/// A pseudo-terminal: the master (kept open while the test runs) and the slave's path, a real
/// serial device that no process of the test's launch file provides.
fn pty() -> (OwnedFd, String) {
    // SAFETY: posix_openpt/grantpt/unlockpt on the descriptor it returns; ptsname_r writes at
    // most the buffer's length.
    unsafe {
        let fd = libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY);
        assert!(fd >= 0, "posix_openpt: {}", std::io::Error::last_os_error());
        let master = OwnedFd::from_raw_fd(fd);
        assert_eq!(libc::grantpt(fd), 0);
        assert_eq!(libc::unlockpt(fd), 0);
        let mut name = [0 as libc::c_char; 128];
        assert_eq!(libc::ptsname_r(fd, name.as_mut_ptr(), name.len()), 0);
        let path = std::ffi::CStr::from_ptr(name.as_ptr())
            .to_string_lossy()
            .into_owned();
        (master, path)
    }
}

/// A launch file with one glove node at `fifo` 70 on the port `port` (its configuration
/// `glove.toml`), in the sandbox.
fn glove_session(sandbox: &Sandbox, port: &str) -> std::path::PathBuf {
    sandbox.write("glove.toml", &format!("port = {port:?}\n"));
    sandbox.write(
        "launch.toml",
        "[[process]]\nname = \"glove\"\nprogram = \"teleop-glove\"\n\
         args = [\"--config\", \"glove.toml\"]\nsched_policy = \"fifo\"\nsched_priority = 70\n",
    )
}

/// Runs `teleop doctor FILE` through `wrapper` (e.g. `prlimit --rtprio=0`), with the sandbox's
/// IPC settings: whether it succeeded, and its output.
fn doctor_via(sandbox: &Sandbox, wrapper: &[&str], file: &Path) -> (bool, String) {
    let mut cmd = match wrapper.split_first() {
        Some((first, rest)) => {
            let mut c = Command::new(first);
            c.args(rest).arg(bin("teleop"));
            c
        }
        None => Command::new(bin("teleop")),
    };
    cmd.arg("doctor")
        .arg(file)
        .envs(sandbox.ipc.to_env())
        .current_dir(sandbox.dir.path());
    rig::run(&mut cmd)
}

#[test]
fn no_real_time_right_is_an_error_naming_the_process_and_the_fix() {
    let sandbox = Sandbox::new();
    let (_master, port) = pty();
    let file = glove_session(&sandbox, &port);
    let wrapper: &[&str] = if is_root() {
        &[
            "prlimit",
            "--rtprio=0",
            "setpriv",
            "--inh-caps=-sys_nice",
            "--bounding-set=-sys_nice",
        ]
    } else {
        &["prlimit", "--rtprio=0"]
    };
    let (ok, out) = doctor_via(&sandbox, wrapper, &file);
    assert!(!ok, "{out}");
    assert!(
        out.contains("error   glove: sched_policy \"fifo\", sched_priority 70 is not allowed: RLIMIT_RTPRIO is 0"),
        "{out}"
    );
    assert!(
        out.contains("cap_sys_nice=eip")
            && out.contains("- rtprio 70` in /etc/security/limits.conf"),
        "{out}"
    );
    // The port itself is fine: the right is what fails.
    assert!(
        out.contains(&format!("ok      glove: serial port {port}")),
        "{out}"
    );
    if is_root() {
        // With the right (root's CAP_SYS_NICE), the same session passes.
        let (ok, out) = doctor_via(&sandbox, &[], &file);
        assert!(ok, "{out}");
        assert!(out.contains("allowed (CAP_SYS_NICE)"), "{out}");
    }
}

#[test]
fn a_missing_serial_port_is_an_error_naming_process_file_and_key() {
    let sandbox = Sandbox::new();
    let file = glove_session(&sandbox, "/nonexistent/ttyUSB9");
    let (ok, out) = doctor_via(&sandbox, &[], &file);
    assert!(!ok, "{out}");
    let config = sandbox.dir.path().join("glove.toml");
    assert!(
        out.contains(&format!(
            "error   glove: serial port /nonexistent/ttyUSB9 ({}, port) does not exist",
            config.display()
        )),
        "{out}"
    );
    assert!(
        out.contains("fix: plug the device in, or set port"),
        "{out}"
    );
}

#[test]
fn an_ethercat_interface_with_an_ip_address_is_an_error_with_the_fix() {
    teleop_e2e::skip_unless_privileged!();
    let ns = netns::Netns::new("tdoc");
    ns.ip(&["addr", "add", "192.0.2.7/24", "dev", "ecm0"]);
    let sandbox = Sandbox::new();
    sandbox.write("revo2.toml", "transport = \"interface:ecm0\"\n");
    let file = sandbox.write(
        "launch.toml",
        "[[process]]\nname = \"revo2\"\nprogram = \"teleop-revo2\"\n\
         args = [\"--config\", \"revo2.toml\"]\nsched_policy = \"fifo\"\nsched_priority = 80\n",
    );
    let doctor = || {
        let mut cmd = ns.command(bin("teleop"));
        cmd.arg("doctor")
            .arg(&file)
            .envs(sandbox.ipc.to_env())
            .current_dir(sandbox.dir.path());
        rig::run(&mut cmd)
    };
    let (ok, out) = doctor();
    assert!(!ok, "{out}");
    let config = sandbox.dir.path().join("revo2.toml");
    assert!(
        out.contains(&format!(
            "error   revo2: EtherCAT interface ecm0 ({}, transport) also carries IP traffic (address 192.0.2.7",
            config.display()
        )),
        "{out}"
    );
    assert!(out.contains("fix: `sudo ip addr flush dev ecm0`"), "{out}");
    assert!(
        out.contains("revo2: EtherCAT interface ecm0") && out.contains("raw sockets allowed"),
        "{out}"
    );
    // Without any address (IPv6 off, so no link-local one comes back), the same interface passes.
    netns::run(
        ns.command("sysctl")
            .args(["-w", "net.ipv6.conf.ecm0.disable_ipv6=1"]),
    );
    ns.ip(&["addr", "flush", "dev", "ecm0"]);
    let (ok, out) = doctor();
    assert!(ok, "{out}");
    assert!(out.contains("up, no IP address"), "{out}");
}

#[test]
fn the_shipped_simulated_session_passes() {
    let sandbox = Sandbox::new();
    let shipped = Sandbox::repo().join("launch.toml");
    let (ok, out) = doctor_via(&sandbox, &[], &shipped);
    assert!(ok, "{out}");
    assert!(out.contains("a simulated session"), "{out}");
    assert!(
        out.contains("ok      glove: serial link /tmp/teleop-glove of sim-glove: simulated"),
        "{out}"
    );
    assert!(!has_error(&out), "{out}");
    if is_root() {
        // As an ordinary user (nobody, without capabilities or real-time limits) too: the
        // refused real-time keys are warnings in a simulated session. `teleop` (hard-linked),
        // the launch file and its configurations go into a folder that user may read, since
        // the checkout may be in one only root may enter (/root); the IPC root is a path in
        // it that the doctor must not create.
        let world = world_readable_copy(&shipped);
        let root = world.path().join("ipc");
        let as_nobody = || {
            let mut cmd = Command::new("setpriv");
            cmd.args(["--reuid=65534", "--regid=65534", "--clear-groups"])
                .arg(world.path().join("teleop"))
                .env("TELEOP_IPC_ROOT", &root)
                .env("TELEOP_IPC_PREFIX", "doctor_")
                .current_dir("/");
            cmd
        };
        let (ok, out) = rig::run(
            as_nobody()
                .arg("doctor")
                .arg(world.path().join("launch.toml")),
        );
        assert!(ok, "{out}");
        assert!(!has_error(&out), "{out}");
        assert!(
            out.contains("(a simulated session runs on without it)"),
            "{out}"
        );
        assert!(!root.exists(), "the doctor made {}", root.display());
    }
}

/// A temporary folder every user may read and write, holding `teleop` (hard-linked), the
/// launch file `launch` and the repository's `config/` beside it.
fn world_readable_copy(launch: &Path) -> tempfile::TempDir {
    use std::os::unix::fs::PermissionsExt;
    let world = tempfile::Builder::new()
        .prefix("teleop-doctor-nobody")
        .tempdir()
        .expect("the world-readable copy for the run as nobody");
    let open = |path: &Path, mode: u32| {
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
            .expect("the world-readable copy for the run as nobody");
    };
    open(world.path(), 0o777);
    let teleop = world.path().join("teleop");
    if std::fs::hard_link(bin("teleop"), &teleop).is_err() {
        std::fs::copy(bin("teleop"), &teleop)
            .expect("the world-readable copy for the run as nobody");
    }
    open(&teleop, 0o755);
    std::fs::copy(launch, world.path().join("launch.toml"))
        .expect("the world-readable copy for the run as nobody");
    open(&world.path().join("launch.toml"), 0o644);
    fn copy_dir(from: &Path, to: &Path, open: &dyn Fn(&Path, u32)) {
        std::fs::create_dir_all(to).expect("the world-readable copy for the run as nobody");
        open(to, 0o755);
        for entry in std::fs::read_dir(from)
            .expect("the world-readable copy for the run as nobody")
            .flatten()
        {
            let target = to.join(entry.file_name());
            if entry
                .file_type()
                .expect("the world-readable copy for the run as nobody")
                .is_dir()
            {
                copy_dir(&entry.path(), &target, open);
            } else {
                std::fs::copy(entry.path(), &target)
                    .expect("the world-readable copy for the run as nobody");
                open(&target, 0o644);
            }
        }
    }
    copy_dir(
        &Sandbox::repo().join("config"),
        &world.path().join("config"),
        &open,
    );
    world
}
