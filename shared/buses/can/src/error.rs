//! The error type of every link: what failed, where, and whether reopening can help.

/// Why a link operation failed. Every variant names the link (`what`, as
/// [`crate::CanLink::describe`] gives it) and says what happened.
#[derive(thiserror::Error, Debug)]
pub enum LinkError {
    /// The adapter or interface is not there ("/dev/ttyACM0: no such device; is the adapter
    /// plugged in?").
    #[error("{what}: not found: {detail}")]
    NotFound {
        /// The link.
        what: String,
        /// What is missing and what to check.
        detail: String,
    },
    /// It went away while in use (EOF, EIO, hang-up): reopen to recover.
    #[error("{what}: disconnected: {detail}")]
    Disconnected {
        /// The link.
        what: String,
        /// What happened.
        detail: String,
    },
    /// The adapter refused a command (slcan BEL) or answered nonsense; names the command.
    #[error("{what}: adapter error: {detail}")]
    Adapter {
        /// The link.
        what: String,
        /// The command and the answer.
        detail: String,
    },
    /// Bus-off: the controller left the bus (reopen to restart it).
    #[error("{what}: bus-off: the CAN controller left the bus (wiring, termination, bit rate?)")]
    BusOff {
        /// The link.
        what: String,
    },
    /// Not possible on this system (SocketCAN without AF_CAN, another OS).
    #[error("{what}: unsupported: {detail}")]
    Unsupported {
        /// The link.
        what: String,
        /// What is missing.
        detail: String,
    },
    /// Another I/O error.
    #[error("{what}: I/O error: {source}")]
    Io {
        /// The link.
        what: String,
        /// The error.
        source: std::io::Error,
    },
    /// A link spec that does not parse.
    #[error("link spec {spec:?}: {detail}")]
    Spec {
        /// The text given.
        spec: String,
        /// What is wrong and what is expected.
        detail: String,
    },
}

impl LinkError {
    /// True when closing and reopening the link may help (disconnected, bus-off, I/O errors);
    /// false for errors that need a person (not found, unsupported, refused, bad spec).
    pub fn is_recoverable(&self) -> bool {
        matches!(
            self,
            LinkError::Disconnected { .. } | LinkError::BusOff { .. } | LinkError::Io { .. }
        )
    }
}
