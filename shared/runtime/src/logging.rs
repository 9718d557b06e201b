//! Logging setup shared by every executable.

use std::io::IsTerminal;

use tracing_subscriber::EnvFilter;

/// Sends `tracing` events to stderr, filtered by `TELEOP_LOG` (default `info`), e.g.
/// `TELEOP_LOG=debug` or `TELEOP_LOG=teleop_runtime=trace`. Also quiets iceoryx2's own
/// logger to warnings. Safe to call more than once.
pub fn init_logging() {
    let filter = EnvFilter::try_from_env("TELEOP_LOG").unwrap_or_else(|_| EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
}
