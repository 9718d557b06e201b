//! The one place the doctor reads the host: this process's capability sets and resource limits
//! (which the session's processes inherit), program file capabilities, the configured serial
//! ports and their adapters' latency timers (`teleop_runtime::serial_latency`), network
//! interfaces (sysfs, `getifaddrs`), whether the kernel has AF_CAN, the CPU frequency
//! governors, `/dev/shm` and the IPC root that holds the e-stop latches. Nothing here opens a
//! device or changes anything.

use std::collections::BTreeMap;
use std::ffi::{CStr, CString};
use std::net::IpAddr;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{FileTypeExt, MetadataExt};
use std::path::{Path, PathBuf};

use teleop_runtime::serial_latency::{slow_latency_timer, tty_name};
use teleop_runtime::{latch_path, IpcSettings};

use super::checks::{
    parse_file_caps, Facts, FileCaps, InterfaceFacts, Limit, Limits, PortState, ProcCaps,
    RootFacts, SerialFacts,
};
use super::plan::{Device, Plan};
use crate::launch::config::Launch;

/// Reads every fact the checks of `plan` need.
pub fn read(plan: &Plan, ipc: &IpcSettings, launch: &Launch) -> Facts {
    let mut serial = BTreeMap::new();
    let mut interfaces = BTreeMap::new();
    let mut af_can = None;
    let mut file_caps = BTreeMap::new();
    for p in &plan.processes {
        if let Some(caps) = program_caps(&p.program) {
            file_caps.insert(p.program.clone(), caps);
        }
        for e in &p.endpoints {
            match &e.device {
                Device::Serial(path) => {
                    serial.insert(path.clone(), serial_port(path));
                }
                Device::EtherCat(name) => {
                    interfaces.insert(name.clone(), interface(name));
                }
                Device::SocketCan(name) => {
                    af_can = Some(has_af_can());
                    interfaces.insert(name.clone(), interface(name));
                }
            }
        }
    }
    let namespaces = launch.namespaces();
    Facts {
        caps: proc_caps(),
        limits: Limits {
            rtprio: limit(libc::RLIMIT_RTPRIO),
            memlock: limit(libc::RLIMIT_MEMLOCK),
            nice: limit(libc::RLIMIT_NICE),
        },
        file_caps,
        allowed_cpus: allowed_cpus(),
        serial,
        interfaces,
        all_interfaces: all_interfaces(),
        af_can,
        governors: governors(),
        shm_free: shm_free(),
        root: (ipc.root_dir(), root(ipc)),
        engaged_latches: namespaces
            .iter()
            .map(|ns| latch_path(ipc, ns.as_ref()))
            .filter(|p| p.symlink_metadata().is_ok())
            .collect(),
        user: user_name().unwrap_or_else(|| "<user>".into()),
    }
}

/// This process's effective uid and its inheritable, bounding and ambient capability sets
/// (`/proc/self/status`, capabilities(7)).
fn proc_caps() -> ProcCaps {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| -> u64 {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| u64::from_str_radix(v.trim(), 16).ok())
            .unwrap_or(0)
    };
    ProcCaps {
        // SAFETY: geteuid has no preconditions.
        euid: unsafe { libc::geteuid() },
        inheritable: field("CapInh:"),
        bounding: field("CapBnd:"),
        ambient: field("CapAmb:"),
    }
}

/// The capabilities set on the program file (`security.capability`), if any.
fn program_caps(program: &Path) -> Option<FileCaps> {
    let path = CString::new(program.as_os_str().as_bytes()).ok()?;
    let mut buf = [0u8; 64];
    // SAFETY: both names are NUL-terminated; the buffer is valid for its length.
    let n = unsafe {
        libc::getxattr(
            path.as_ptr(),
            c"security.capability".as_ptr(),
            buf.as_mut_ptr().cast(),
            buf.len(),
        )
    };
    let n = usize::try_from(n).ok()?;
    parse_file_caps(buf.get(..n)?)
}

/// The soft value of resource limit `resource`.
fn limit(resource: libc::__rlimit_resource_t) -> Limit {
    let mut r = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `r` is a valid rlimit to write into.
    if unsafe { libc::getrlimit(resource, &mut r) } != 0 {
        return Limit::Value(0);
    }
    if r.rlim_cur == libc::RLIM_INFINITY {
        Limit::Unlimited
    } else {
        Limit::Value(r.rlim_cur)
    }
}

/// The CPUs this process may run on (its children inherit the mask).
fn allowed_cpus() -> Option<Vec<usize>> {
    // SAFETY: cpu_set_t is plain data; sched_getaffinity writes at most its size.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
            return None;
        }
        Some(
            (0..libc::CPU_SETSIZE as usize)
                .filter(|&c| libc::CPU_ISSET(c, &set))
                .collect(),
        )
    }
}

/// A configured serial port: there, a character device, readable and writable by this user
/// (`access`, which opens nothing), and its adapter's latency timer.
fn serial_port(path: &Path) -> SerialFacts {
    let state = match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => PortState::Missing,
        Err(e) => PortState::Denied {
            error: e.to_string(),
            group: None,
        },
        Ok(m) if !m.file_type().is_char_device() => PortState::NotDevice(
            if m.is_dir() {
                "a folder"
            } else if m.is_file() {
                "a regular file"
            } else {
                "not a character device"
            }
            .into(),
        ),
        Ok(m) => match CString::new(path.as_os_str().as_bytes()) {
            // SAFETY: the path is NUL-terminated.
            Ok(c) if unsafe { libc::access(c.as_ptr(), libc::R_OK | libc::W_OK) } == 0 => {
                PortState::Usable
            }
            _ => PortState::Denied {
                error: std::io::Error::last_os_error().to_string(),
                group: group_name(m.gid()),
            },
        },
    };
    SerialFacts {
        state,
        slow_timer: tty_name(path).and_then(|tty| slow_latency_timer(Path::new("/sys"), &tty)),
    }
}

/// The name of group `gid` (`/etc/group`).
fn group_name(gid: u32) -> Option<String> {
    name_of_id("/etc/group", gid)
}

/// The name of this process's effective user (`/etc/passwd`), for limits.conf lines.
fn user_name() -> Option<String> {
    // SAFETY: geteuid has no preconditions.
    name_of_id("/etc/passwd", unsafe { libc::geteuid() })
}

/// The name whose third field is `id` in `file` (`/etc/passwd` or `/etc/group`: `name:x:id:...`).
fn name_of_id(file: &str, id: u32) -> Option<String> {
    let text = std::fs::read_to_string(file).ok()?;
    text.lines().find_map(|l| {
        let mut f = l.split(':');
        let name = f.next()?;
        (f.nth(1)? == id.to_string()).then(|| name.to_string())
    })
}

/// A network interface from sysfs (`/sys/class/net/NAME/{flags,operstate,type}`) and its
/// addresses from `getifaddrs`.
fn interface(name: &str) -> InterfaceFacts {
    // A name with a slash or a dot-only name would leave /sys/class/net.
    if name.contains('/') || name.chars().all(|c| c == '.') {
        return InterfaceFacts::default();
    }
    let dir = Path::new("/sys/class/net").join(name);
    let read = |file: &str| std::fs::read_to_string(dir.join(file)).map(|s| s.trim().to_string());
    if !dir.exists() {
        return InterfaceFacts::default();
    }
    let flags = read("flags")
        .ok()
        .and_then(|f| u32::from_str_radix(f.trim_start_matches("0x"), 16).ok())
        .unwrap_or(0);
    InterfaceFacts {
        exists: true,
        up: flags & libc::IFF_UP as u32 != 0,
        carrier: matches!(read("operstate").as_deref(), Ok("up") | Ok("unknown")),
        link_type: read("type").ok().and_then(|t| t.parse().ok()),
        addresses: addresses(name),
    }
}

/// The IPv4 and IPv6 addresses configured on interface `name`.
fn addresses(name: &str) -> Vec<IpAddr> {
    let mut out = Vec::new();
    let mut list: *mut libc::ifaddrs = std::ptr::null_mut();
    // SAFETY: getifaddrs writes a list head we free below with freeifaddrs.
    if unsafe { libc::getifaddrs(&mut list) } != 0 {
        return out;
    }
    let mut at = list;
    while !at.is_null() {
        // SAFETY: `at` is a node of the list getifaddrs made, alive until freeifaddrs.
        let ifa = unsafe { &*at };
        at = ifa.ifa_next;
        // SAFETY: ifa_name is a NUL-terminated string of the list.
        let this = unsafe { CStr::from_ptr(ifa.ifa_name) };
        if ifa.ifa_addr.is_null() || this.to_bytes() != name.as_bytes() {
            continue;
        }
        // SAFETY: ifa_addr points to a sockaddr whose family says its real type.
        unsafe {
            match i32::from((*ifa.ifa_addr).sa_family) {
                libc::AF_INET => {
                    let a = &*ifa.ifa_addr.cast::<libc::sockaddr_in>();
                    out.push(IpAddr::from(u32::from_be(a.sin_addr.s_addr).to_be_bytes()));
                }
                libc::AF_INET6 => {
                    let a = &*ifa.ifa_addr.cast::<libc::sockaddr_in6>();
                    out.push(IpAddr::from(a.sin6_addr.s6_addr));
                }
                _ => {}
            }
        }
    }
    // SAFETY: `list` came from getifaddrs and is freed once.
    unsafe { libc::freeifaddrs(list) };
    out
}

/// Every network interface of this host (network namespace).
fn all_interfaces() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir("/sys/class/net")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| e.file_name().to_str().map(String::from))
        .collect();
    names.sort();
    names
}

/// Whether this kernel has SocketCAN: a raw CAN socket can be made (and is closed again).
fn has_af_can() -> bool {
    // SAFETY: socket(2) with constant arguments; the descriptor is closed at once.
    unsafe {
        let fd = libc::socket(libc::AF_CAN, libc::SOCK_RAW, libc::CAN_RAW);
        if fd < 0 {
            return false;
        }
        libc::close(fd);
    }
    true
}

/// Each CPU's frequency governor, by CPU number order.
fn governors() -> Vec<(String, String)> {
    let mut found: Vec<(usize, String, String)> = std::fs::read_dir("/sys/devices/system/cpu")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_str()?.to_string();
            let n: usize = name.strip_prefix("cpu")?.parse().ok()?;
            let gov = std::fs::read_to_string(e.path().join("cpufreq/scaling_governor")).ok()?;
            Some((n, name, gov.trim().to_string()))
        })
        .collect();
    found.sort();
    found.into_iter().map(|(_, cpu, gov)| (cpu, gov)).collect()
}

/// Free bytes in `/dev/shm` for this user (statvfs).
fn shm_free() -> Result<u64, String> {
    // SAFETY: statvfs is plain data; all-zero is a valid value.
    let mut s: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: the path is NUL-terminated; `s` is valid to write.
    if unsafe { libc::statvfs(c"/dev/shm".as_ptr(), &mut s) } != 0 {
        return Err(std::io::Error::last_os_error().to_string());
    }
    Ok(s.f_bavail.saturating_mul(s.f_frsize))
}

/// The IPC root: when it exists, the runtime's own check of it (the one every node makes) and
/// whether this user may write in it; when not, the closest existing folder above it.
fn root(ipc: &IpcSettings) -> RootFacts {
    let dir = ipc.root_dir();
    let writable = |p: &Path| {
        CString::new(p.as_os_str().as_bytes())
            // SAFETY: the path is NUL-terminated.
            .is_ok_and(|c| unsafe { libc::access(c.as_ptr(), libc::W_OK) } == 0)
    };
    if dir.exists() {
        // It exists, so `config` makes nothing: it only checks it.
        return RootFacts::Exists {
            refused: ipc.config().err().map(|e| e.to_string()),
            writable: writable(&dir),
        };
    }
    let ancestor = dir
        .ancestors()
        .skip(1)
        .find(|a| a.is_dir())
        .map_or_else(|| PathBuf::from("/"), Path::to_path_buf);
    RootFacts::Missing {
        writable: writable(&ancestor),
        ancestor,
    }
}
