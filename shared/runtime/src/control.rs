//! A simulator's control socket: a Unix stream socket taking one command per line and answering
//! each with one line, served on a thread of its own (`socat - UNIX-CONNECT:PATH`, or a test's
//! `UnixStream`).

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixListener;
use std::path::{Path, PathBuf};

/// Serves `path` (replacing a stale socket file there) on a thread named `control`; `answer`
/// turns each command line (trimmed) into its one-line answer. The error names the path.
pub fn spawn(
    path: &Path,
    mut answer: impl FnMut(&str) -> String + Send + 'static,
) -> std::io::Result<PathBuf> {
    let _ = std::fs::remove_file(path);
    let listener = UnixListener::bind(path).map_err(|e| {
        std::io::Error::new(
            e.kind(),
            format!("{}: cannot create control socket: {e}", path.display()),
        )
    })?;
    std::thread::Builder::new()
        .name("control".into())
        .spawn(move || {
            for stream in listener.incoming().flatten() {
                let Ok(mut reply) = stream.try_clone() else {
                    continue;
                };
                for line in BufReader::new(stream).lines() {
                    let Ok(line) = line else { break };
                    let _ = writeln!(reply, "{}", answer(line.trim()));
                }
            }
        })?;
    Ok(path.to_path_buf())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use std::os::unix::net::UnixStream;

    #[test]
    fn each_line_gets_its_answer_and_a_stale_socket_is_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sim.ctl");
        std::fs::write(&path, b"stale").unwrap();
        let mut count = 0;
        spawn(&path, move |line| {
            count += 1;
            format!("{count}: {line}")
        })
        .unwrap();
        let stream = UnixStream::connect(&path).unwrap();
        let mut w = stream.try_clone().unwrap();
        writeln!(w, "  stats ").unwrap();
        writeln!(w, "drop 0.5").unwrap();
        let mut lines = BufReader::new(stream).lines();
        assert_eq!(lines.next().unwrap().unwrap(), "1: stats");
        assert_eq!(lines.next().unwrap().unwrap(), "2: drop 0.5");
        let err = spawn(&dir.path().join("no/such/dir.ctl"), |_| String::new()).unwrap_err();
        assert!(
            err.to_string().contains("cannot create control socket"),
            "{err}"
        );
    }
}
