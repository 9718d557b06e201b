//! Frames over a Unix stream socket, each behind its length as a little-endian u16.

use std::io::{ErrorKind, Read, Write};
use std::os::fd::AsRawFd;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::{FrameLink, LinkError, MAX_FRAME};

/// The master's end: connects to an emulator's [`StreamServer`].
pub struct StreamLink {
    stream: UnixStream,
    path: PathBuf,
}

impl StreamLink {
    /// Connects to the emulator listening at `path`.
    pub fn connect(path: &Path) -> Result<Self, LinkError> {
        let stream = UnixStream::connect(path)
            .map_err(|e| LinkError::Down(format!("cannot connect to {}: {e}", path.display())))?;
        Ok(Self {
            stream,
            path: path.to_path_buf(),
        })
    }
}

impl FrameLink for StreamLink {
    fn send(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        write_frame(&mut self.stream, frame).map_err(|e| down(&self.path, e))
    }

    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> Result<Option<usize>, LinkError> {
        read_frame(&mut self.stream, buf, timeout).map_err(|e| down(&self.path, e))
    }

    fn fd(&self) -> Option<std::os::fd::RawFd> {
        Some(self.stream.as_raw_fd())
    }
}

fn down(path: &Path, e: std::io::Error) -> LinkError {
    LinkError::Down(format!("{}: {e}", path.display()))
}

/// The emulator's end: listens at a path and serves one master connection at a time.
pub struct StreamServer {
    listener: UnixListener,
    path: PathBuf,
}

impl StreamServer {
    /// Listens at `path` (an old socket file there is replaced).
    pub fn bind(path: &Path) -> Result<Self, LinkError> {
        let _ = std::fs::remove_file(path);
        let listener = UnixListener::bind(path).map_err(|source| LinkError::Io {
            context: format!("cannot listen at {}", path.display()),
            source,
        })?;
        listener
            .set_nonblocking(true)
            .map_err(|source| LinkError::Io {
                context: "socket setup".into(),
                source,
            })?;
        Ok(Self {
            listener,
            path: path.to_path_buf(),
        })
    }

    /// The socket path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// A waiting master connection, if any (does not block).
    pub fn accept(&self) -> Result<Option<ServerConnection>, LinkError> {
        match self.listener.accept() {
            Ok((stream, _)) => {
                stream
                    .set_nonblocking(false)
                    .map_err(|source| LinkError::Io {
                        context: "socket setup".into(),
                        source,
                    })?;
                Ok(Some(ServerConnection { stream }))
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => Ok(None),
            Err(source) => Err(LinkError::Io {
                context: format!("accept on {}", self.path.display()),
                source,
            }),
        }
    }
}

impl Drop for StreamServer {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// One master connected to a [`StreamServer`].
pub struct ServerConnection {
    stream: UnixStream,
}

impl FrameLink for ServerConnection {
    fn send(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        write_frame(&mut self.stream, frame).map_err(|e| LinkError::Down(e.to_string()))
    }

    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> Result<Option<usize>, LinkError> {
        read_frame(&mut self.stream, buf, timeout).map_err(|e| LinkError::Down(e.to_string()))
    }

    fn fd(&self) -> Option<std::os::fd::RawFd> {
        Some(self.stream.as_raw_fd())
    }
}

fn write_frame(stream: &mut UnixStream, frame: &[u8]) -> std::io::Result<()> {
    if frame.len() > MAX_FRAME {
        return Err(std::io::Error::new(
            ErrorKind::InvalidInput,
            "frame too long",
        ));
    }
    let mut msg = [0u8; 2 + MAX_FRAME];
    msg[..2].copy_from_slice(&(frame.len() as u16).to_le_bytes());
    msg[2..2 + frame.len()].copy_from_slice(frame);
    stream.write_all(&msg[..2 + frame.len()])
}

/// Reads one length-prefixed frame. Nothing before `timeout` is `Ok(None)`; once a frame has
/// started, the rest is read without a timeout (it is already on its way). Waits with `ppoll`:
/// socket receive timeouts are rounded up to scheduler ticks (4 ms at 250 Hz).
fn read_frame(
    stream: &mut UnixStream,
    buf: &mut [u8],
    timeout: Duration,
) -> std::io::Result<Option<usize>> {
    if crate::wait_readable(&[stream.as_raw_fd()], timeout)? == 0 {
        return Ok(None);
    }
    let mut len = [0u8; 2];
    match stream.read(&mut len[..1]) {
        Ok(0) => {
            return Err(std::io::Error::new(
                ErrorKind::UnexpectedEof,
                "connection closed",
            ))
        }
        Ok(_) => {}
        Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
            return Ok(None)
        }
        Err(e) => return Err(e),
    }
    stream.read_exact(&mut len[1..])?;
    let n = usize::from(u16::from_le_bytes(len));
    if n > MAX_FRAME {
        return Err(std::io::Error::new(
            ErrorKind::InvalidData,
            format!("frame length {n}"),
        ));
    }
    let mut frame = [0u8; MAX_FRAME];
    stream.read_exact(&mut frame[..n])?;
    let copy = n.min(buf.len());
    buf[..copy].copy_from_slice(&frame[..copy]);
    Ok(Some(copy))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_cross_the_socket_whole_and_a_closed_peer_is_link_down() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ecat.sock");
        let server = StreamServer::bind(&path).unwrap();
        let mut client = StreamLink::connect(&path).unwrap();
        let mut conn = loop {
            if let Some(c) = server.accept().unwrap() {
                break c;
            }
        };
        let mut buf = [0u8; MAX_FRAME];
        assert_eq!(conn.recv(&mut buf, Duration::from_millis(5)).unwrap(), None);
        client.send(&[0xAA; 60]).unwrap();
        client.send(&[0xBB; 1514]).unwrap();
        assert_eq!(
            conn.recv(&mut buf, Duration::from_secs(1)).unwrap(),
            Some(60)
        );
        assert_eq!(
            conn.recv(&mut buf, Duration::from_secs(1)).unwrap(),
            Some(1514)
        );
        assert_eq!(buf[1513], 0xBB);
        conn.send(&[1, 2, 3]).unwrap();
        assert_eq!(
            client.recv(&mut buf, Duration::from_secs(1)).unwrap(),
            Some(3)
        );
        assert!(client.send(&[0; 1515]).is_err());
        drop(conn);
        assert!(matches!(
            client.recv(&mut buf, Duration::from_secs(1)),
            Err(LinkError::Down(_))
        ));
        drop(server);
        assert!(StreamLink::connect(&path).is_err());
    }
}
