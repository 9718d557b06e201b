//! The doctor's rules: facts read from the host ([`Facts`], filled by `host`) and the launch
//! file's [`Plan`] in, [`Finding`]s out. Pure: tests give them any host they like.

use std::collections::BTreeMap;
use std::net::IpAddr;
use std::path::{Path, PathBuf};

use teleop_runtime::realtime::SchedPolicy;
use teleop_runtime::serial_latency::SlowLatencyTimer;

use super::plan::{Device, Endpoint, Plan, ProcessPlan};
use super::Finding;

/// `CAP_NET_RAW` (capability numbers of `<linux/capability.h>`): raw sockets (the EtherCAT
/// master's).
pub const CAP_NET_RAW: u32 = 13;
/// `CAP_IPC_LOCK`: `mlockall` beyond `RLIMIT_MEMLOCK`.
pub const CAP_IPC_LOCK: u32 = 14;
/// `CAP_SYS_NICE`: real-time policies and negative nice values beyond the limits.
pub const CAP_SYS_NICE: u32 = 23;

/// `ARPHRD_CAN` of `<linux/if_arp.h>`: the link type of a CAN interface.
pub const ARPHRD_CAN: u32 = 280;

/// Shared memory a node of a session takes in `/dev/shm`, bytes: about twice the measured
/// 4.2 MB (the simulated session of `launch.toml`, debug build: 20.8 MB in its prefix's files in
/// `/dev/shm` while its five nodes ran). Rough on purpose: it tells a container's 64 MB
/// `/dev/shm` from one with room.
pub const SHM_PER_NODE: u64 = 8 << 20;

/// Memory a node maps, bytes, which `mlockall` must be allowed to lock: the largest `VmSize`
/// of the simulated session's nodes was 240 MB (`teleop-revo2`, debug build), rounded up.
pub const LOCKED_PER_NODE: u64 = 512 << 20;

/// The capability sets of this process that an `execve` by the same user starts from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ProcCaps {
    /// Effective user id.
    pub euid: u32,
    /// Inheritable set.
    pub inheritable: u64,
    /// Bounding set.
    pub bounding: u64,
    /// Ambient set.
    pub ambient: u64,
}

/// A program file's capabilities (`setcap`, the `security.capability` attribute).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FileCaps {
    /// Permitted set.
    pub permitted: u64,
    /// Inheritable set.
    pub inheritable: u64,
    /// The effective bit (`+e`).
    pub effective: bool,
}

/// Parses a `security.capability` attribute (`struct vfs_cap_data` of
/// `<linux/capability.h>`: a little-endian `magic_etc`, then permitted/inheritable pairs, one
/// for revision 1, two for revisions 2 and 3, which adds a root id). `None` for anything else.
pub fn parse_file_caps(bytes: &[u8]) -> Option<FileCaps> {
    const REVISION_MASK: u32 = 0xFF00_0000;
    const FLAGS_EFFECTIVE: u32 = 0x0000_0001;
    let word = |i: usize| -> Option<u64> {
        let b = bytes.get(i * 4..i * 4 + 4)?;
        Some(u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])))
    };
    let magic = u32::try_from(word(0)?).ok()?;
    let (permitted, inheritable) = match (magic & REVISION_MASK, bytes.len()) {
        (0x0100_0000, 12) => (word(1)?, word(2)?),
        (0x0200_0000, 20) | (0x0300_0000, 24) => {
            (word(1)? | word(3)? << 32, word(2)? | word(4)? << 32)
        }
        _ => return None,
    };
    Some(FileCaps {
        permitted,
        inheritable,
        effective: magic & FLAGS_EFFECTIVE != 0,
    })
}

/// The effective set a process of `proc` gets by executing a program with `file`'s
/// capabilities: capabilities(7), "Transformation of capabilities during execve()". For root
/// the file sets count as full; otherwise P'(permitted) = (P(inh) & F(inh)) | (F(perm) &
/// P(bnd)) | P'(amb), effective only with the file's effective bit (else the ambient set).
pub fn exec_effective(proc: &ProcCaps, file: Option<&FileCaps>) -> u64 {
    if proc.euid == 0 {
        return proc.inheritable | proc.bounding;
    }
    let Some(file) = file else {
        return proc.ambient;
    };
    let permitted = (proc.inheritable & file.inheritable) | (file.permitted & proc.bounding);
    if file.effective {
        permitted
    } else {
        0
    }
}

fn has(caps: u64, cap: u32) -> bool {
    caps & (1 << cap) != 0
}

/// A resource limit's soft value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Limit {
    /// `RLIM_INFINITY`.
    Unlimited,
    /// A value.
    Value(u64),
}

impl Limit {
    fn at_least(self, v: u64) -> bool {
        match self {
            Self::Unlimited => true,
            Self::Value(x) => x >= v,
        }
    }
}

impl std::fmt::Display for Limit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Unlimited => f.write_str("unlimited"),
            Self::Value(v) => write!(f, "{v}"),
        }
    }
}

/// The resource limits the session's processes inherit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// `RLIMIT_RTPRIO`.
    pub rtprio: Limit,
    /// `RLIMIT_MEMLOCK`, bytes.
    pub memlock: Limit,
    /// `RLIMIT_NICE` (the lowest nice value allowed is 20 minus it).
    pub nice: Limit,
}

/// A configured serial port as found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PortState {
    /// Nothing at the path.
    Missing,
    /// Something that is not a character device (a regular file, a folder).
    NotDevice(String),
    /// A device this user may not read and write, and why.
    Denied {
        /// The error of `access(R_OK | W_OK)`.
        error: String,
        /// The group owning the device (`dialout`), if known.
        group: Option<String>,
    },
    /// A device this user may read and write.
    Usable,
}

/// A serial port: its state and its adapter's latency timer when that is too slow.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SerialFacts {
    /// The port.
    pub state: PortState,
    /// The adapter's latency timer, when above 1 ms.
    pub slow_timer: Option<SlowLatencyTimer>,
}

/// A network interface as found.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct InterfaceFacts {
    /// It exists.
    pub exists: bool,
    /// Administratively up (`IFF_UP`).
    pub up: bool,
    /// Has a link (operstate `up` or `unknown`).
    pub carrier: bool,
    /// Its link type (`ARPHRD_*`).
    pub link_type: Option<u32>,
    /// The IP addresses configured on it.
    pub addresses: Vec<IpAddr>,
}

/// The IPC root, which holds the e-stop latches (and iceoryx2's files).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RootFacts {
    /// It exists: the runtime's own check of it (`IpcSettings::config`), and whether this user
    /// may write in it.
    Exists {
        /// The runtime's refusal, if it refuses it.
        refused: Option<String>,
        /// `access(W_OK)`.
        writable: bool,
    },
    /// It does not exist yet; the first node makes it in `ancestor`, the closest existing
    /// folder.
    Missing {
        /// The closest existing folder above it.
        ancestor: PathBuf,
        /// Whether this user may write in it.
        writable: bool,
    },
}

/// Everything the checks need to know about the host.
#[derive(Debug, Clone)]
pub struct Facts {
    /// The capability sets processes start from.
    pub caps: ProcCaps,
    /// The resource limits.
    pub limits: Limits,
    /// Each process's program file capabilities (by the program's path).
    pub file_caps: BTreeMap<PathBuf, FileCaps>,
    /// The CPUs this process may run on (None: unknown).
    pub allowed_cpus: Option<Vec<usize>>,
    /// The configured serial ports.
    pub serial: BTreeMap<PathBuf, SerialFacts>,
    /// The configured network interfaces.
    pub interfaces: BTreeMap<String, InterfaceFacts>,
    /// The network interfaces that exist (for messages).
    pub all_interfaces: Vec<String>,
    /// Whether `socket(AF_CAN)` works (None: not tried, no CAN interface configured).
    pub af_can: Option<bool>,
    /// Each CPU's frequency governor (`cpu0`, `performance`); empty without cpufreq.
    pub governors: Vec<(String, String)>,
    /// Free bytes in `/dev/shm`, or why they cannot be told.
    pub shm_free: Result<u64, String>,
    /// The IPC root (the e-stop latches' directory).
    pub root: (PathBuf, RootFacts),
    /// The e-stop latches of the session's namespaces that are engaged.
    pub engaged_latches: Vec<PathBuf>,
    /// The user's name, for limits.conf lines.
    pub user: String,
}

/// Every finding, in order: the launch file's problems, each process's rights and devices,
/// then the host-wide checks.
pub fn all(plan: &Plan, facts: &Facts) -> Vec<Finding> {
    let hardware = plan.hardware();
    let mut out = plan.problems.clone();
    let nodes = plan.processes.iter().filter(|p| p.node).count();
    for p in &plan.processes {
        let caps = exec_effective(&facts.caps, facts.file_caps.get(&p.program));
        out.extend(scheduling(p, caps, facts, hardware));
        for e in &p.endpoints {
            out.extend(endpoint(p, e, caps, facts));
        }
        for s in &p.simulated {
            out.push(Finding::ok(
                &p.name,
                format!("{s}: simulated, needs nothing"),
            ));
        }
    }
    out.push(governor(&facts.governors));
    out.push(shared_memory(&facts.shm_free, nodes));
    out.extend(latch(&facts.root, &facts.engaged_latches));
    out
}

/// The capabilities `p` needs for what the launch file asks of it (`setcap` replaces a file's
/// set, so its fix names them all).
fn needed_caps(p: &ProcessPlan) -> Vec<&'static str> {
    let rt = &p.realtime;
    let mut caps = Vec::new();
    if p.endpoints
        .iter()
        .any(|e| matches!(e.device, Device::EtherCat(_)))
    {
        caps.extend(["cap_net_raw", "cap_net_admin"]);
    }
    if rt.policy != SchedPolicy::Other || rt.nice.is_some_and(|n| n < 0) {
        caps.push("cap_sys_nice");
    }
    if rt.lock_memory {
        caps.push("cap_ipc_lock");
    }
    caps
}

/// The fix for missing rights of `p`: root, `setcap` with every capability it needs, or the
/// limits.conf line `limit` (e.g. `rtprio 80`).
fn rights_fix(p: &ProcessPlan, user: &str, limit: Option<String>) -> String {
    let mut fix = format!(
        "run the session as root, or `sudo setcap {}=eip {}` (it replaces the file's \
         capabilities, so all it needs are listed; again after each build)",
        needed_caps(p).join(","),
        p.program.display()
    );
    if let Some(limit) = limit {
        fix.push_str(&format!(
            ", or `{user} - {limit}` in /etc/security/limits.conf (then log in again)"
        ));
    }
    fix
}

/// The launch file's scheduling keys of `p` against its rights (`caps`: the effective set its
/// program will have).
fn scheduling(p: &ProcessPlan, caps: u64, facts: &Facts, hardware: bool) -> Vec<Finding> {
    let rt = &p.realtime;
    let limits = &facts.limits;
    let mut out = Vec::new();
    let refused = |text: String, fix: String| {
        if hardware {
            Finding::error(&p.name, text, Some(fix))
        } else {
            Finding::warning(
                &p.name,
                format!("{text} (a simulated session runs on without it)"),
                Some(fix),
            )
        }
    };
    if rt.policy != SchedPolicy::Other {
        let asked = format!(
            "sched_policy \"{}\", sched_priority {}",
            rt.policy.name(),
            rt.priority
        );
        if has(caps, CAP_SYS_NICE) {
            out.push(Finding::ok(
                &p.name,
                format!("{asked}: allowed (CAP_SYS_NICE)"),
            ));
        } else if limits.rtprio.at_least(u64::from(rt.priority)) {
            out.push(Finding::ok(
                &p.name,
                format!("{asked}: allowed (RLIMIT_RTPRIO {})", limits.rtprio),
            ));
        } else {
            out.push(refused(
                format!(
                    "{asked} is not allowed: RLIMIT_RTPRIO is {} and CAP_SYS_NICE is not \
                     effective for {}; its time-critical threads would run at normal priority",
                    limits.rtprio,
                    p.program.display()
                ),
                rights_fix(p, &facts.user, Some(format!("rtprio {}", rt.priority))),
            ));
        }
    }
    if rt.lock_memory {
        if has(caps, CAP_IPC_LOCK) || limits.memlock.at_least(LOCKED_PER_NODE) {
            out.push(Finding::ok(
                &p.name,
                format!(
                    "lock_memory: allowed (RLIMIT_MEMLOCK {}{})",
                    limits.memlock,
                    if has(caps, CAP_IPC_LOCK) {
                        ", CAP_IPC_LOCK"
                    } else {
                        ""
                    }
                ),
            ));
        } else {
            out.push(refused(
                format!(
                    "lock_memory = true cannot lock the node's memory: RLIMIT_MEMLOCK is {} \
                     bytes (a node maps up to about {} MiB) and CAP_IPC_LOCK is not effective; \
                     a page fault could stall a cycle",
                    limits.memlock,
                    LOCKED_PER_NODE >> 20
                ),
                rights_fix(p, &facts.user, Some("memlock unlimited".into())),
            ));
        }
    }
    if let Some(nice) = rt.nice.filter(|n| *n < 0) {
        let floor = match limits.nice {
            Limit::Unlimited => -20,
            Limit::Value(v) => 20 - i64::try_from(v.min(40)).unwrap_or(40),
        };
        if !has(caps, CAP_SYS_NICE) && i64::from(nice) < floor {
            let allowed = if floor >= 0 {
                format!("RLIMIT_NICE {} allows no negative value", limits.nice)
            } else {
                format!("RLIMIT_NICE {} allows down to {floor}", limits.nice)
            };
            out.push(Finding::warning(
                &p.name,
                format!(
                    "nice = {nice} is not allowed ({allowed}, and CAP_SYS_NICE is not \
                     effective): it keeps the inherited nice value"
                ),
                Some(rights_fix(p, &facts.user, Some(format!("nice {nice}")))),
            ));
        }
    }
    if let Some(allowed) = &facts.allowed_cpus {
        let absent: Vec<String> = rt
            .cpus
            .iter()
            .filter(|c| !allowed.contains(c))
            .map(usize::to_string)
            .collect();
        if !absent.is_empty() {
            out.push(Finding::warning(
                &p.name,
                format!(
                    "cpu_affinity names CPU {} that this host (or its cpuset) does not offer: \
                     it would run on any CPU",
                    absent.join(", ")
                ),
                Some(format!(
                    "name CPUs of {}",
                    allowed
                        .iter()
                        .map(usize::to_string)
                        .collect::<Vec<_>>()
                        .join(",")
                )),
            ));
        }
    }
    out
}

/// One real device of `p`.
fn endpoint(p: &ProcessPlan, e: &Endpoint, caps: u64, facts: &Facts) -> Vec<Finding> {
    match &e.device {
        Device::Serial(path) => match facts.serial.get(path) {
            Some(s) => serial(p, e, path, s),
            None => Vec::new(),
        },
        Device::EtherCat(name) => {
            let i = facts.interfaces.get(name).cloned().unwrap_or_default();
            ethercat(p, e, name, &i, caps, &facts.all_interfaces)
        }
        Device::SocketCan(name) => {
            let i = facts.interfaces.get(name).cloned().unwrap_or_default();
            socketcan(p, e, name, &i, facts.af_can.unwrap_or(false))
        }
    }
}

/// A serial port: there, a device, readable and writable, its latency timer fast.
pub fn serial(p: &ProcessPlan, e: &Endpoint, path: &Path, s: &SerialFacts) -> Vec<Finding> {
    let port = format!("serial port {} ({})", path.display(), e.setting);
    let mut out = vec![match &s.state {
        PortState::Missing => Finding::error(
            &p.name,
            format!("{port} does not exist"),
            Some(format!(
                "plug the device in, or set {} to its port (`ls /dev/serial/by-id/` lists \
                 USB-serial adapters by a name that does not change)",
                e.setting.key
            )),
        ),
        PortState::NotDevice(kind) => Finding::error(
            &p.name,
            format!("{port} is {kind}, not a serial device"),
            Some(format!("set {} to the device's port", e.setting.key)),
        ),
        PortState::Denied { error, group } => Finding::error(
            &p.name,
            format!("{port} cannot be read and written by this user: {error}"),
            Some(match group {
                Some(g) => format!("`sudo usermod -aG {g} $USER`, then log in again"),
                None => "give this user read and write access to it (a udev rule)".into(),
            }),
        ),
        PortState::Usable => Finding::ok(&p.name, format!("{port}: readable and writable")),
    }];
    if let Some(slow) = &s.slow_timer {
        out.push(Finding::warning(
            &p.name,
            format!(
                "{port}: the USB-serial adapter's latency timer is {} ms ({}): every answer \
                 waits for it",
                slow.ms,
                slow.path.display()
            ),
            Some(format!(
                "`{}` (until it is plugged in again; a udev rule keeps it)",
                slow.fix()
            )),
        ));
    }
    out
}

/// An EtherCAT interface: the raw-socket right, there, up, with a link, and no IP on it.
pub fn ethercat(
    p: &ProcessPlan,
    e: &Endpoint,
    name: &str,
    i: &InterfaceFacts,
    caps: u64,
    all: &[String],
) -> Vec<Finding> {
    let what = format!("EtherCAT interface {name} ({})", e.setting);
    let mut out = vec![if has(caps, CAP_NET_RAW) {
        Finding::ok(
            &p.name,
            format!("{what}: raw sockets allowed (CAP_NET_RAW)"),
        )
    } else {
        Finding::error(
            &p.name,
            format!(
                "{what}: no raw socket without CAP_NET_RAW, which is not effective for {}",
                p.program.display()
            ),
            Some(rights_fix(p, "", None)),
        )
    }];
    if !i.exists {
        out.push(Finding::error(
            &p.name,
            format!(
                "{what} does not exist (this host has: {})",
                if all.is_empty() {
                    "none".to_string()
                } else {
                    all.join(", ")
                }
            ),
            Some(format!(
                "set {} to `interface:NAME` of the port the hand is plugged into",
                e.setting.key
            )),
        ));
        return out;
    }
    if !i.up {
        out.push(Finding::error(
            &p.name,
            format!("{what} is down"),
            Some(format!("`sudo ip link set {name} up`")),
        ));
    } else if !i.carrier {
        out.push(Finding::error(
            &p.name,
            format!("{what} is up but has no link"),
            Some("connect the hand's cable to it and power the hand".into()),
        ));
    }
    if i.addresses.is_empty() {
        out.push(Finding::ok(
            &p.name,
            format!("{what}: up, no IP address (nothing but EtherCAT on it)"),
        ));
    } else {
        let list: Vec<String> = i.addresses.iter().map(IpAddr::to_string).collect();
        let mut fix = format!("`sudo ip addr flush dev {name}`");
        if i.addresses.iter().any(IpAddr::is_ipv6) {
            fix.push_str(&format!(
                " and `sudo sysctl -w net.ipv6.conf.{name}.disable_ipv6=1` (IPv6 gives an \
                 up interface a link-local address again)"
            ));
        }
        fix.push_str(&format!(
            "; keep a network manager off it (`nmcli device set {name} managed no`)"
        ));
        out.push(Finding::error(
            &p.name,
            format!(
                "{what} also carries IP traffic (address {}): its frames share the EtherCAT \
                 wire and delay the cycle",
                list.join(", ")
            ),
            Some(fix),
        ));
    }
    out
}

/// A SocketCAN interface: the kernel has AF_CAN, the interface is there, a CAN one, up.
pub fn socketcan(
    p: &ProcessPlan,
    e: &Endpoint,
    name: &str,
    i: &InterfaceFacts,
    af_can: bool,
) -> Vec<Finding> {
    let what = format!("CAN interface {name} ({})", e.setting);
    if !af_can {
        return vec![Finding::error(
            &p.name,
            format!(
                "{what}: this kernel has no SocketCAN (socket(AF_CAN) fails: address family \
                 not supported)"
            ),
            Some(
                "`sudo modprobe can_raw` on a kernel built with CONFIG_CAN, or use an slcan \
                 adapter (link = \"slcan:/dev/ttyACM0\")"
                    .into(),
            ),
        )];
    }
    let finding = if !i.exists {
        Finding::error(
            &p.name,
            format!("{what} does not exist"),
            Some("plug the CAN adapter in (`ip link` lists the interfaces)".into()),
        )
    } else if i.link_type != Some(ARPHRD_CAN) {
        Finding::error(
            &p.name,
            format!("{what} is not a CAN interface"),
            Some(format!(
                "set {} to the CAN adapter's interface",
                e.setting.key
            )),
        )
    } else if !i.up {
        Finding::error(
            &p.name,
            format!("{what} is down"),
            Some(format!(
                "`sudo ip link set {name} up type can bitrate 1000000`"
            )),
        )
    } else {
        Finding::ok(&p.name, format!("{what}: up"))
    };
    vec![finding]
}

/// The CPU frequency governors: `performance` everywhere, or a warning.
pub fn governor(governors: &[(String, String)]) -> Finding {
    if governors.is_empty() {
        return Finding::note(
            "host",
            "CPU frequency governor: not available here (no cpufreq: a virtual machine or a \
             fixed clock), nothing to set"
                .into(),
        );
    }
    let slow: Vec<String> = governors
        .iter()
        .filter(|(_, g)| g != "performance")
        .map(|(cpu, g)| format!("{cpu} {g}"))
        .collect();
    if slow.is_empty() {
        return Finding::ok("host", "CPU frequency governor: performance".into());
    }
    Finding::warning(
        "host",
        format!(
            "CPU frequency governor not at performance ({}): the clock ramps up late after \
             idle, which delays cycles",
            slow.join(", ")
        ),
        Some(
            "`sudo cpupower frequency-set -g performance` (or `echo performance | sudo tee \
             /sys/devices/system/cpu/cpu*/cpufreq/scaling_governor`)"
                .into(),
        ),
    )
}

/// Room in `/dev/shm` for the session's iceoryx2 shared memory.
pub fn shared_memory(free: &Result<u64, String>, nodes: usize) -> Finding {
    let need = SHM_PER_NODE.saturating_mul(nodes as u64);
    let mib = |b: u64| b >> 20;
    match free {
        Err(e) => Finding::error(
            "host",
            format!("/dev/shm (iceoryx2's shared memory) cannot be used: {e}"),
            Some("mount a tmpfs there (`sudo mount -t tmpfs tmpfs /dev/shm`)".into()),
        ),
        Ok(free) if *free < need => Finding::error(
            "host",
            format!(
                "/dev/shm has {} MiB free; the session's {nodes} nodes need about {} MiB",
                mib(*free),
                mib(need)
            ),
            Some(
                "free it (`ls -la /dev/shm`: files of dead sessions) or enlarge it (`sudo mount \
                 -o remount,size=1G /dev/shm`)"
                    .into(),
            ),
        ),
        Ok(free) => Finding::ok(
            "host",
            format!(
                "/dev/shm: {} MiB free, about {} MiB needed",
                mib(*free),
                mib(need)
            ),
        ),
    }
}

/// The e-stop latch's directory (the IPC root) and the latches engaged now.
pub fn latch(root: &(PathBuf, RootFacts), engaged: &[PathBuf]) -> Vec<Finding> {
    let (path, facts) = root;
    let dir = format!("e-stop latch directory {}", path.display());
    let mut out = vec![match facts {
        RootFacts::Exists {
            refused: Some(why), ..
        } => Finding::error(
            "host",
            format!("{dir}: the nodes refuse it: {why}"),
            Some(
                "use a folder of your own (`--ipc-root DIR` or TELEOP_IPC_ROOT), or remove a \
                 stale one"
                    .into(),
            ),
        ),
        RootFacts::Exists {
            writable: false, ..
        } => Finding::error(
            "host",
            format!("{dir} is not writable by this user: `teleop estop` could not latch"),
            Some("use a folder of your own (`--ipc-root DIR` or TELEOP_IPC_ROOT)".into()),
        ),
        RootFacts::Exists { .. } => Finding::ok("host", format!("{dir}: writable")),
        RootFacts::Missing {
            ancestor,
            writable: true,
        } => Finding::ok(
            "host",
            format!(
                "{dir}: not there yet, can be made in {}",
                ancestor.display()
            ),
        ),
        RootFacts::Missing { ancestor, .. } => Finding::error(
            "host",
            format!(
                "{dir} does not exist and cannot be made: {} is not writable by this user",
                ancestor.display()
            ),
            Some("use a folder of your own (`--ipc-root DIR` or TELEOP_IPC_ROOT)".into()),
        ),
    }];
    for latch in engaged {
        out.push(Finding::warning(
            "host",
            format!(
                "the e-stop is engaged ({}): the hands will hold and the gloves push nothing",
                latch.display()
            ),
            Some("`teleop estop --release` once it is safe".into()),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::super::plan::Setting;
    use super::super::Severity;
    use super::*;
    use teleop_runtime::realtime::Realtime;

    fn process(rt: Realtime, endpoints: Vec<Endpoint>) -> ProcessPlan {
        ProcessPlan {
            name: "hand".into(),
            program: "/opt/teleop/teleop-revo2".into(),
            realtime: rt,
            endpoints,
            simulated: Vec::new(),
            node: true,
        }
    }

    fn fifo(priority: u8) -> Realtime {
        Realtime {
            policy: SchedPolicy::Fifo,
            priority,
            ..Realtime::default()
        }
    }

    fn ecat(name: &str) -> Endpoint {
        Endpoint {
            device: Device::EtherCat(name.into()),
            setting: Setting {
                origin: "config/revo2.toml".into(),
                key: "transport".into(),
            },
        }
    }

    fn facts(limits: Limits) -> Facts {
        Facts {
            caps: ProcCaps::default(),
            limits,
            file_caps: BTreeMap::new(),
            allowed_cpus: Some(vec![0, 1]),
            serial: BTreeMap::new(),
            interfaces: BTreeMap::new(),
            all_interfaces: vec!["lo".into(), "eth0".into()],
            af_can: None,
            governors: Vec::new(),
            shm_free: Ok(1 << 40),
            root: (
                "/tmp/iceoryx2".into(),
                RootFacts::Missing {
                    ancestor: "/tmp".into(),
                    writable: true,
                },
            ),
            engaged_latches: Vec::new(),
            user: "ana".into(),
        }
    }

    const NO_LIMITS: Limits = Limits {
        rtprio: Limit::Value(0),
        memlock: Limit::Value(8 << 20),
        nice: Limit::Value(0),
    };

    fn severities(f: &[Finding]) -> Vec<Severity> {
        f.iter().map(|f| f.severity).collect()
    }

    #[test]
    fn capabilities_after_exec_follow_the_man_page() {
        let all = (1u64 << 41) - 1;
        let root = ProcCaps {
            euid: 0,
            inheritable: 0,
            bounding: all,
            ambient: 0,
        };
        assert!(has(exec_effective(&root, None), CAP_SYS_NICE));
        let dropped = ProcCaps {
            bounding: all & !(1 << CAP_SYS_NICE),
            ..root
        };
        assert!(!has(exec_effective(&dropped, None), CAP_SYS_NICE));
        assert!(has(exec_effective(&dropped, None), CAP_NET_RAW));

        let user = ProcCaps {
            euid: 1000,
            bounding: all,
            ..ProcCaps::default()
        };
        assert_eq!(exec_effective(&user, None), 0);
        let setcap = FileCaps {
            permitted: 1 << CAP_NET_RAW | 1 << CAP_SYS_NICE,
            inheritable: 0,
            effective: true,
        };
        let caps = exec_effective(&user, Some(&setcap));
        assert!(has(caps, CAP_NET_RAW) && has(caps, CAP_SYS_NICE));
        // Permitted but not effective (`=ip`): a program unaware of capabilities has none.
        let not_effective = FileCaps {
            effective: false,
            ..setcap
        };
        assert_eq!(exec_effective(&user, Some(&not_effective)), 0);
        // The bounding set limits what a file grants.
        let bounded = ProcCaps {
            bounding: all & !(1 << CAP_SYS_NICE),
            ..user
        };
        assert!(!has(exec_effective(&bounded, Some(&setcap)), CAP_SYS_NICE));
    }

    #[test]
    fn file_capabilities_parse_by_revision() {
        // `setcap cap_net_raw,cap_sys_nice=eip`: revision 2, effective flag, 2 x (perm, inh).
        let mut v2 = vec![0x01, 0, 0, 0x02];
        for w in [1u32 << 13 | 1 << 23, 1 << 13 | 1 << 23, 0, 0] {
            v2.extend(w.to_le_bytes());
        }
        let caps = parse_file_caps(&v2).unwrap();
        assert!(caps.effective);
        assert_eq!(caps.permitted, 1 << 13 | 1 << 23);
        let mut v3 = v2.clone();
        v3[3] = 0x03;
        v3.extend(0u32.to_le_bytes());
        assert_eq!(parse_file_caps(&v3), Some(caps));
        // A capability above 31 lives in the second word.
        let mut high = vec![0, 0, 0, 0x02];
        for w in [0u32, 0, 1 << 8, 0] {
            high.extend(w.to_le_bytes());
        }
        assert_eq!(parse_file_caps(&high).unwrap().permitted, 1 << 40);
        assert!(!parse_file_caps(&high).unwrap().effective);
        assert_eq!(parse_file_caps(&v2[..19]), None);
        assert_eq!(parse_file_caps(&[]), None);
    }

    #[test]
    fn real_time_without_the_right_is_an_error_on_hardware_and_a_warning_in_simulation() {
        let p = process(fifo(80), vec![ecat("eth0")]);
        let f = facts(NO_LIMITS);
        let found = scheduling(&p, 0, &f, true);
        assert_eq!(severities(&found), [Severity::Error]);
        let text = &found[0].text;
        assert!(
            text.contains("\"fifo\", sched_priority 80") && text.contains("RLIMIT_RTPRIO is 0")
        );
        let fix = found[0].fix.as_deref().unwrap();
        assert!(
            fix.contains(
                "setcap cap_net_raw,cap_net_admin,cap_sys_nice=eip /opt/teleop/teleop-revo2"
            ) && fix.contains("`ana - rtprio 80` in /etc/security/limits.conf"),
            "{fix}"
        );
        let found = scheduling(&p, 0, &f, false);
        assert_eq!(severities(&found), [Severity::Warning]);
        // Either right is enough: the limit at or above the priority, or CAP_SYS_NICE.
        let enough = facts(Limits {
            rtprio: Limit::Value(80),
            ..NO_LIMITS
        });
        assert_eq!(
            severities(&scheduling(&p, 0, &enough, true)),
            [Severity::Ok]
        );
        let short = facts(Limits {
            rtprio: Limit::Value(79),
            ..NO_LIMITS
        });
        assert_eq!(
            severities(&scheduling(&p, 0, &short, true)),
            [Severity::Error]
        );
        assert_eq!(
            severities(&scheduling(&p, 1 << CAP_SYS_NICE, &f, true)),
            [Severity::Ok]
        );
        // Normal scheduling asks for nothing.
        assert!(scheduling(&process(Realtime::default(), vec![]), 0, &f, true).is_empty());
    }

    #[test]
    fn memory_locking_nice_and_affinity() {
        let rt = Realtime {
            lock_memory: true,
            nice: Some(-5),
            cpus: vec![1, 3],
            ..Realtime::default()
        };
        let p = process(rt, vec![]);
        let found = scheduling(&p, 0, &facts(NO_LIMITS), true);
        assert_eq!(
            severities(&found),
            [Severity::Error, Severity::Warning, Severity::Warning]
        );
        assert!(found[0].text.contains("RLIMIT_MEMLOCK is 8388608"));
        assert!(found[0]
            .fix
            .as_deref()
            .unwrap()
            .contains("memlock unlimited"));
        assert!(found[1].text.contains("nice = -5"));
        assert!(found[2].text.contains("CPU 3"));
        let generous = facts(Limits {
            rtprio: Limit::Value(0),
            memlock: Limit::Unlimited,
            nice: Limit::Value(25),
        });
        assert_eq!(
            severities(&scheduling(&p, 0, &generous, true)),
            [Severity::Ok, Severity::Warning]
        );
    }

    #[test]
    fn an_ethercat_interface_with_an_address_is_an_error_with_the_fix() {
        let p = process(Realtime::default(), vec![ecat("ecm0")]);
        let e = ecat("ecm0");
        let mut i = InterfaceFacts {
            exists: true,
            up: true,
            carrier: true,
            link_type: Some(1),
            addresses: vec![],
        };
        let raw = 1 << CAP_NET_RAW;
        assert_eq!(
            severities(&ethercat(&p, &e, "ecm0", &i, raw, &[])),
            [Severity::Ok, Severity::Ok]
        );
        i.addresses = vec!["192.0.2.1".parse().unwrap(), "fe80::1".parse().unwrap()];
        let found = ethercat(&p, &e, "ecm0", &i, raw, &[]);
        assert_eq!(severities(&found), [Severity::Ok, Severity::Error]);
        assert!(
            found[1].text.contains("192.0.2.1, fe80::1"),
            "{}",
            found[1].text
        );
        let fix = found[1].fix.as_deref().unwrap();
        assert!(fix.contains("ip addr flush dev ecm0") && fix.contains("disable_ipv6"));
        // No raw-socket right; down; missing.
        i.addresses.clear();
        i.up = false;
        let found = ethercat(&p, &e, "ecm0", &i, 0, &[]);
        assert_eq!(
            severities(&found),
            [Severity::Error, Severity::Error, Severity::Ok]
        );
        assert!(found[0].fix.as_deref().unwrap().contains("cap_net_raw"));
        assert!(found[1]
            .fix
            .as_deref()
            .unwrap()
            .contains("ip link set ecm0 up"));
        let found = ethercat(
            &p,
            &e,
            "ecm0",
            &InterfaceFacts::default(),
            raw,
            &["lo".into()],
        );
        assert_eq!(severities(&found), [Severity::Ok, Severity::Error]);
        assert!(found[1].text.contains("does not exist (this host has: lo)"));
    }

    #[test]
    fn serial_ports_and_their_latency_timer() {
        let e = Endpoint {
            device: Device::Serial("/dev/ttyUSB9".into()),
            setting: Setting {
                origin: "config/glove.toml".into(),
                key: "port".into(),
            },
        };
        let p = process(Realtime::default(), vec![e.clone()]);
        let path = Path::new("/dev/ttyUSB9");
        let missing = SerialFacts {
            state: PortState::Missing,
            slow_timer: None,
        };
        let found = serial(&p, &e, path, &missing);
        assert_eq!(severities(&found), [Severity::Error]);
        assert_eq!(
            found[0].text,
            "serial port /dev/ttyUSB9 (config/glove.toml, port) does not exist"
        );
        let denied = SerialFacts {
            state: PortState::Denied {
                error: "Permission denied".into(),
                group: Some("dialout".into()),
            },
            slow_timer: Some(SlowLatencyTimer {
                path: "/sys/x/latency_timer".into(),
                ms: 16,
            }),
        };
        let found = serial(&p, &e, path, &denied);
        assert_eq!(severities(&found), [Severity::Error, Severity::Warning]);
        assert!(found[0]
            .fix
            .as_deref()
            .unwrap()
            .contains("usermod -aG dialout"));
        assert!(found[1].text.contains("16 ms"));
        assert!(found[1]
            .fix
            .as_deref()
            .unwrap()
            .contains("echo 1 | sudo tee /sys/x/latency_timer"));
    }

    #[test]
    fn socketcan_without_af_can_says_so() {
        let e = Endpoint {
            device: Device::SocketCan("can0".into()),
            setting: Setting {
                origin: "config/allegro.toml".into(),
                key: "link".into(),
            },
        };
        let p = process(Realtime::default(), vec![e.clone()]);
        let found = socketcan(&p, &e, "can0", &InterfaceFacts::default(), false);
        assert_eq!(severities(&found), [Severity::Error]);
        assert!(found[0].text.contains("no SocketCAN"));
        let mut i = InterfaceFacts {
            exists: true,
            up: false,
            carrier: false,
            link_type: Some(ARPHRD_CAN),
            addresses: vec![],
        };
        let found = socketcan(&p, &e, "can0", &i, true);
        assert!(found[0].fix.as_deref().unwrap().contains("bitrate 1000000"));
        i.up = true;
        assert_eq!(
            severities(&socketcan(&p, &e, "can0", &i, true)),
            [Severity::Ok]
        );
        i.link_type = Some(1);
        assert_eq!(
            severities(&socketcan(&p, &e, "can0", &i, true)),
            [Severity::Error]
        );
    }

    #[test]
    fn host_wide_checks() {
        assert_eq!(governor(&[]).severity, Severity::Note);
        let g = |v: &[(&str, &str)]| -> Vec<(String, String)> {
            v.iter()
                .map(|(a, b)| (a.to_string(), b.to_string()))
                .collect()
        };
        assert_eq!(
            governor(&g(&[("cpu0", "performance")])).severity,
            Severity::Ok
        );
        let w = governor(&g(&[("cpu0", "performance"), ("cpu1", "powersave")]));
        assert_eq!(w.severity, Severity::Warning);
        assert!(w.text.contains("cpu1 powersave"));

        assert_eq!(shared_memory(&Ok(1 << 40), 6).severity, Severity::Ok);
        let short = shared_memory(&Ok(SHM_PER_NODE * 5), 6);
        assert_eq!(short.severity, Severity::Error);
        assert_eq!(
            shared_memory(&Err("no such file".into()), 6).severity,
            Severity::Error
        );

        let root = PathBuf::from("/tmp/iceoryx2");
        let refused = RootFacts::Exists {
            refused: Some("owned by uid 0".into()),
            writable: true,
        };
        let found = latch(&(root.clone(), refused), &[]);
        assert_eq!(severities(&found), [Severity::Error]);
        let fine = RootFacts::Exists {
            refused: None,
            writable: true,
        };
        let found = latch(&(root.clone(), fine), &[root.join("teleop_estop")]);
        assert_eq!(severities(&found), [Severity::Ok, Severity::Warning]);
        let stuck = RootFacts::Missing {
            ancestor: "/".into(),
            writable: false,
        };
        assert_eq!(severities(&latch(&(root, stuck), &[])), [Severity::Error]);
    }

    #[test]
    fn a_simulated_session_on_a_bare_host_has_no_error() {
        let mut p = process(fifo(70), vec![]);
        p.simulated.push("serial link /tmp/g of sim".into());
        let plan = Plan {
            processes: vec![p],
            problems: Vec::new(),
        };
        let found = all(&plan, &facts(NO_LIMITS));
        assert!(
            found.iter().all(|f| f.severity != Severity::Error),
            "{found:?}"
        );
        assert!(found.iter().any(|f| f.severity == Severity::Warning));
    }
}
