//! `teleop doctor [LAUNCH_FILE]`: checks this host for running a launch file's session on real
//! hardware and prints each problem with its fix.
//!
//! Three parts, kept apart so the rules are tested without the host:
//! - [`plan`]: what the launch file's processes will open (each device node's serial port,
//!   EtherCAT or CAN interface, read from its configuration and arguments), which of those a
//!   simulator of the same launch file provides, and the real-time keys;
//! - [`host`]: the one place that reads this host (capabilities, resource limits, sysfs, the
//!   interfaces' addresses, `/dev/shm`, the e-stop latch's directory);
//! - [`checks`]: pure rules from those facts to [`Finding`]s.
//!
//! An error is what would stop (or should stop) a session on real hardware: the exit status is
//! then 1. A warning only degrades it (a CPU governor not at `performance`, a slow USB-serial
//! latency timer) and leaves the status 0. The launch file's real-time keys are requirements
//! only when some process opens a real device; in a fully simulated session their refusal is a
//! warning (the nodes run on at normal priority, `teleop_runtime::realtime`).
//!
//! Owns no device I/O: it never opens a device (opening a serial port toggles its control
//! lines), it only looks at it.

mod checks;
mod host;
mod plan;

use std::path::Path;
use std::process::ExitCode;

use teleop_runtime::IpcSettings;

/// How much a finding matters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// A check that passed.
    Ok,
    /// Something worth knowing that needs nothing (a check that cannot be made here).
    Note,
    /// Degrades a session on real hardware; does not stop it.
    Warning,
    /// Would stop a session on real hardware (or make it unsafe to run).
    Error,
}

impl Severity {
    fn label(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::Note => "note",
            Self::Warning => "warning",
            Self::Error => "error",
        }
    }
}

/// One result of a check: what it is about, what was found, and the fix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Finding {
    /// How much it matters.
    pub severity: Severity,
    /// What it is about: a process of the launch file, or `host`.
    pub subject: String,
    /// What was found.
    pub text: String,
    /// What to do about it.
    pub fix: Option<String>,
}

impl Finding {
    fn new(severity: Severity, subject: &str, text: String, fix: Option<String>) -> Self {
        Self {
            severity,
            subject: subject.to_string(),
            text,
            fix,
        }
    }

    /// A passed check.
    pub fn ok(subject: &str, text: String) -> Self {
        Self::new(Severity::Ok, subject, text, None)
    }

    /// A note.
    pub fn note(subject: &str, text: String) -> Self {
        Self::new(Severity::Note, subject, text, None)
    }

    /// A warning with its fix.
    pub fn warning(subject: &str, text: String, fix: Option<String>) -> Self {
        Self::new(Severity::Warning, subject, text, fix)
    }

    /// An error with its fix.
    pub fn error(subject: &str, text: String, fix: Option<String>) -> Self {
        Self::new(Severity::Error, subject, text, fix)
    }
}

/// `teleop doctor FILE`: prints every finding, then a summary; exit status 1 when any is an
/// error.
pub fn run(file: &Path, ipc: &IpcSettings) -> anyhow::Result<ExitCode> {
    let launch = crate::launch::config::load(file)?;
    let plan = plan::plan(&launch);
    let hardware: Vec<&str> = plan.hardware_processes().collect();
    if hardware.is_empty() {
        out!(
            "{}: a simulated session (no process opens a real device): refused real-time \
             keys are warnings here, not errors",
            file.display()
        )?;
    } else {
        out!(
            "{}: real devices opened by {}",
            file.display(),
            hardware.join(", ")
        )?;
    }
    let facts = host::read(&plan, ipc, &launch);
    let findings = checks::all(&plan, &facts);
    for f in &findings {
        out!("{:<8}{}: {}", f.severity.label(), f.subject, f.text)?;
        if let Some(fix) = &f.fix {
            out!("        fix: {fix}")?;
        }
    }
    let count = |s: Severity| findings.iter().filter(|f| f.severity == s).count();
    let (errors, warnings) = (count(Severity::Error), count(Severity::Warning));
    if errors > 0 {
        out!(
            "{errors} error(s), {warnings} warning(s): this host is not ready for this session \
             on real hardware"
        )?;
        Ok(ExitCode::FAILURE)
    } else {
        out!("no errors, {warnings} warning(s): this host can run this session")?;
        Ok(ExitCode::SUCCESS)
    }
}
