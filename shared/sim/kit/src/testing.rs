//! A simulator process under test: started in a temporary directory of its own, waited for
//! until it prints the line saying where it serves, talked to on its control socket, stopped
//! with SIGINT when dropped; its `stats` read back.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use crate::control::Stats;

/// A running simulator process.
pub struct SimProcess {
    child: Child,
    dir: tempfile::TempDir,
    control: PathBuf,
}

impl SimProcess {
    /// Runs `program` with the arguments `args` makes from the process's own directory, then
    /// waits for its first line on stdout, which must start with `announce`; `control` is the
    /// control socket's name in that directory.
    ///
    /// # Panics
    /// When the process cannot start or announces something else (this is for tests).
    pub fn start(
        program: &Path,
        args: impl FnOnce(&Path) -> Vec<std::ffi::OsString>,
        announce: &str,
        control: &str,
    ) -> Self {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("temporary directory: {e}"));
        let mut child = Command::new(program)
            .args(args(dir.path()))
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("{}: {e}", program.display()));
        let mut line = String::new();
        if let Some(out) = child.stdout.take() {
            let _ = BufReader::new(out).read_line(&mut line);
        }
        let control = dir.path().join(control);
        let sim = Self {
            child,
            dir,
            control,
        };
        assert!(line.starts_with(announce), "announced {line:?}");
        sim
    }

    /// The process's directory.
    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// Sends one control line; the answer without its line end.
    ///
    /// # Panics
    /// When the control socket cannot be reached (this is for tests).
    pub fn control(&self, line: &str) -> String {
        let mut s = UnixStream::connect(&self.control)
            .unwrap_or_else(|e| panic!("{}: {e}", self.control.display()));
        let _ = writeln!(s, "{line}");
        let _ = s.shutdown(std::net::Shutdown::Write);
        let mut reply = String::new();
        let _ = BufReader::new(s).read_line(&mut reply);
        reply.trim_end().to_string()
    }

    /// The `stats` answer, read back.
    ///
    /// # Panics
    /// When the answer is no `ok key=value ...` (this is for tests).
    pub fn stats(&self) -> Stats {
        Stats::parse(&self.control("stats")).unwrap_or_else(|e| panic!("stats: {e}"))
    }
}

impl Drop for SimProcess {
    fn drop(&mut self) {
        if let Ok(pid) = libc::pid_t::try_from(self.child.id()) {
            // SAFETY: signalling the child this value owns (not yet waited for).
            unsafe {
                libc::kill(pid, libc::SIGINT);
            }
        }
        let _ = self.child.wait();
    }
}
