//! A control socket (a simulator's, whose vocabulary is `teleop-sim-kit`'s; the bridge's fault
//! injection): a Unix stream socket taking one command per line and answering each with one
//! line, served on threads of its own (`socat - UNIX-CONNECT:PATH`, or a test's
//! `UnixStream`). Each client has its own thread, so an idle one does not block the others; at
//! most [`MAX_CLIENTS`] at once, and one silent for [`IDLE`] is disconnected.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::fs::FileTypeExt;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Most clients served at once; more are answered `error: busy` and closed.
pub const MAX_CLIENTS: usize = 8;
/// A client that sends nothing for this long is disconnected.
pub const IDLE: Duration = Duration::from_secs(60);

/// Serves `path` on a thread named `control` (each client on a thread `control-client`);
/// `answer` turns each command line (trimmed) into its one-line answer. A stale socket at `path`
/// (left by a process that ended) is replaced; anything else there (a file that is not a socket,
/// or a socket another process serves) is left alone and refused. The error names the path.
pub fn spawn(
    path: &Path,
    answer: impl FnMut(&str) -> String + Send + 'static,
) -> std::io::Result<PathBuf> {
    let refuse = |kind: std::io::ErrorKind, why: String| {
        std::io::Error::new(
            kind,
            format!("{}: cannot create control socket: {why}", path.display()),
        )
    };
    match std::fs::symlink_metadata(path) {
        Ok(meta) if !meta.file_type().is_socket() => {
            return Err(refuse(
                std::io::ErrorKind::AlreadyExists,
                "a file that is not a socket is there (left alone: remove it or choose another \
                 path)"
                    .into(),
            ))
        }
        Ok(_) if UnixStream::connect(path).is_ok() => {
            return Err(refuse(
                std::io::ErrorKind::AddrInUse,
                "another process serves this socket".into(),
            ))
        }
        Ok(_) => {
            // A stale socket: nobody accepts on it.
            let _ = std::fs::remove_file(path);
        }
        Err(_) => {}
    }
    let listener = UnixListener::bind(path).map_err(|e| refuse(e.kind(), e.to_string()))?;
    let answer = Arc::new(Mutex::new(answer));
    let clients = Arc::new(AtomicUsize::new(0));
    std::thread::Builder::new()
        .name("control".into())
        .spawn(move || {
            for mut stream in listener.incoming().flatten() {
                if clients.load(Ordering::Acquire) >= MAX_CLIENTS {
                    let _ = writeln!(stream, "error: busy ({MAX_CLIENTS} clients connected)");
                    continue;
                }
                clients.fetch_add(1, Ordering::AcqRel);
                let (answer, done) = (Arc::clone(&answer), Arc::clone(&clients));
                let served = std::thread::Builder::new()
                    .name("control-client".into())
                    .spawn(move || {
                        serve(stream, &answer);
                        done.fetch_sub(1, Ordering::AcqRel);
                    });
                if served.is_err() {
                    // No thread, nothing ran: the client's stream is closed, its slot free.
                    clients.fetch_sub(1, Ordering::AcqRel);
                }
            }
        })?;
    Ok(path.to_path_buf())
}

/// One client's lines and answers, until it closes, errs or idles for [`IDLE`].
fn serve<F: FnMut(&str) -> String>(stream: UnixStream, answer: &Mutex<F>) {
    let _ = stream.set_read_timeout(Some(IDLE));
    let Ok(mut reply) = stream.try_clone() else {
        return;
    };
    for line in BufReader::new(stream).lines() {
        let Ok(line) = line else { break };
        let text = match answer.lock() {
            Ok(mut answer) => answer(line.trim()),
            Err(_) => break,
        };
        if writeln!(reply, "{text}").is_err() {
            break;
        }
    }
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
        // A socket whose process ended: its file stays, nobody accepts on it.
        drop(UnixListener::bind(&path).unwrap());
        assert!(path.exists());
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
        // A socket this process serves is not taken over.
        let err = spawn(&path, |_| String::new()).unwrap_err();
        assert!(err.to_string().contains("another process serves"), "{err}");
        let err = spawn(&dir.path().join("no/such/dir.ctl"), |_| String::new()).unwrap_err();
        assert!(
            err.to_string().contains("cannot create control socket"),
            "{err}"
        );
    }

    #[test]
    fn a_file_that_is_not_a_socket_is_left_alone() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("notes.txt");
        std::fs::write(&path, b"keep me").unwrap();
        let err = spawn(&path, |_| String::new()).unwrap_err();
        assert!(err.to_string().contains("not a socket"), "{err}");
        assert_eq!(std::fs::read(&path).unwrap(), b"keep me");
    }

    #[test]
    fn an_idle_client_does_not_block_the_next() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sim.ctl");
        spawn(&path, |line| format!("ok {line}")).unwrap();
        // Connected, says nothing, stays.
        let _idle = UnixStream::connect(&path).unwrap();
        let stream = UnixStream::connect(&path).unwrap();
        stream
            .set_read_timeout(Some(std::time::Duration::from_secs(5)))
            .unwrap();
        writeln!(&stream, "stats").unwrap();
        let mut line = String::new();
        let read = BufReader::new(&stream).read_line(&mut line);
        assert!(
            matches!(read, Ok(n) if n > 0) && line == "ok stats\n",
            "the second client got {read:?} {line:?}"
        );
    }
}
