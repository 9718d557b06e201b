//! Low-latency serial: what a serial device node (the glove's link, the LEAP Hand's bus) asks
//! of the port's driver when it opens the port ([`tune`]).
//!
//! Every exchange is a short question and answer, so the delay a serial driver adds before it
//! hands received bytes over counts in full, twice per exchange. Two knobs matter on Linux:
//!
//! - the `ASYNC_LOW_LATENCY` flag of the tty (TIOCGSERIAL / TIOCSSERIAL), which
//!   [`request_low_latency`] sets on the port's file descriptor. A pseudo-terminal (the
//!   simulator) and Bluetooth SPP refuse it; that is no error;
//! - the latency timer of USB-serial adapters (FTDI and others; 16 ms by default on many
//!   kernels), a sysfs attribute only root may change. [`slow_latency_timer`] reads it so the
//!   link can say once which file to fix and how.

use std::os::fd::RawFd;
use std::path::{Path, PathBuf};

/// The largest adapter latency timer that does not slow a question-and-answer link down,
/// milliseconds.
pub const MAX_LATENCY_TIMER_MS: u32 = 1;

/// Sets `ASYNC_LOW_LATENCY` on the tty open at `fd` (a no-op when it is already set). The error
/// is the driver's refusal (`ENOTTY` on a pseudo-terminal, `EINVAL` on some others).
pub fn request_low_latency(fd: RawFd) -> std::io::Result<()> {
    sys::request_low_latency(fd)
}

#[cfg(target_os = "linux")]
mod sys {
    use std::os::fd::RawFd;

    /// `ASYNCB_LOW_LATENCY` of `<linux/tty_flags.h>`.
    const ASYNC_LOW_LATENCY: libc::c_int = 1 << 13;

    /// `struct serial_struct` of `<linux/serial.h>` (libc does not define it). Only `flags` is
    /// used; the rest is carried from TIOCGSERIAL back to TIOCSSERIAL unchanged.
    #[repr(C)]
    struct SerialStruct {
        kind: libc::c_int,
        line: libc::c_int,
        port: libc::c_uint,
        irq: libc::c_int,
        flags: libc::c_int,
        xmit_fifo_size: libc::c_int,
        custom_divisor: libc::c_int,
        baud_base: libc::c_int,
        close_delay: libc::c_ushort,
        io_type: libc::c_char,
        reserved_char: [libc::c_char; 1],
        hub6: libc::c_int,
        closing_wait: libc::c_ushort,
        closing_wait2: libc::c_ushort,
        iomem_base: *mut libc::c_uchar,
        iomem_reg_shift: libc::c_ushort,
        port_high: libc::c_uint,
        iomap_base: libc::c_ulong,
    }

    // The layout gcc gives <linux/serial.h> on 64-bit Linux.
    #[cfg(target_pointer_width = "64")]
    const _: () = {
        assert!(core::mem::size_of::<SerialStruct>() == 72);
        assert!(core::mem::offset_of!(SerialStruct, flags) == 16);
        assert!(core::mem::offset_of!(SerialStruct, iomem_base) == 48);
        assert!(core::mem::offset_of!(SerialStruct, iomap_base) == 64);
    };

    pub(super) fn request_low_latency(fd: RawFd) -> std::io::Result<()> {
        // SAFETY: all-zero bytes are a valid SerialStruct (integers and a null pointer).
        let mut serial: SerialStruct = unsafe { core::mem::zeroed() };
        // SAFETY: TIOCGSERIAL writes one serial_struct to the pointer, which is valid for it;
        // a bad fd or a tty without the ioctl only makes it fail.
        if unsafe { libc::ioctl(fd, libc::TIOCGSERIAL, &mut serial as *mut SerialStruct) } < 0 {
            return Err(std::io::Error::last_os_error());
        }
        if serial.flags & ASYNC_LOW_LATENCY != 0 {
            return Ok(());
        }
        serial.flags |= ASYNC_LOW_LATENCY;
        // SAFETY: TIOCSSERIAL reads one serial_struct from the pointer, valid for it.
        if unsafe { libc::ioctl(fd, libc::TIOCSSERIAL, &serial as *const SerialStruct) } < 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(())
    }
}

#[cfg(not(target_os = "linux"))]
mod sys {
    use std::os::fd::RawFd;

    pub(super) fn request_low_latency(_fd: RawFd) -> std::io::Result<()> {
        Err(std::io::ErrorKind::Unsupported.into())
    }
}

/// A USB-serial adapter's latency timer that is too slow for a question-and-answer link.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlowLatencyTimer {
    /// The sysfs attribute (symlinks resolved).
    pub path: PathBuf,
    /// Its value, milliseconds.
    pub ms: u32,
}

impl SlowLatencyTimer {
    /// The command that sets it to 1 ms (until the adapter is plugged in again).
    pub fn fix(&self) -> String {
        format!("echo 1 | sudo tee {}", self.path.display())
    }
}

/// The name under `/sys/class/tty` of the tty behind `port` (symlinks such as
/// `/dev/serial/by-id/...` resolved), e.g. `ttyUSB0`.
pub fn tty_name(port: &Path) -> Option<String> {
    let device = std::fs::canonicalize(port).ok()?;
    Some(device.file_name()?.to_str()?.to_string())
}

/// The latency timer of the adapter behind `tty` when it is above [`MAX_LATENCY_TIMER_MS`].
/// `sysfs` is the sysfs root (`/sys`). The attribute is `class/tty/<tty>/device/latency_timer`
/// with `device` resolved (a symlink in sysfs), or one directory above that. `None` when the
/// tty has no latency timer (not a USB-serial adapter, a pseudo-terminal, Bluetooth) or it is
/// fast enough.
pub fn slow_latency_timer(sysfs: &Path, tty: &str) -> Option<SlowLatencyTimer> {
    let device = std::fs::canonicalize(sysfs.join("class/tty").join(tty).join("device")).ok()?;
    let path = [Some(device.as_path()), device.parent()]
        .into_iter()
        .flatten()
        .map(|dir| dir.join("latency_timer"))
        .find(|p| p.is_file())?;
    let text = std::fs::read_to_string(&path).ok()?;
    let ms = match text.trim().parse::<u32>() {
        Ok(ms) => ms,
        Err(e) => {
            tracing::debug!(path = %path.display(), "unreadable latency timer {text:?}: {e}");
            return None;
        }
    };
    (ms > MAX_LATENCY_TIMER_MS).then_some(SlowLatencyTimer { path, ms })
}

/// Sysfs latency-timer files already warned about: once per process, not on every reopen.
static WARNED: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

/// Tunes the serial port `port` (open at `fd`) for short questions and answers: asks for
/// [`request_low_latency`] (a refusal, as by a pseudo-terminal, is a debug note) and warns once
/// per adapter, naming the fix, when its latency timer is above [`MAX_LATENCY_TIMER_MS`]
/// (every answer waits for it). True when the driver took low-latency mode.
pub fn tune(fd: RawFd, port: &Path) -> bool {
    let low_latency = match request_low_latency(fd) {
        Ok(()) => true,
        Err(e) => {
            tracing::debug!(port = %port.display(), "no low-latency mode: {e}");
            false
        }
    };
    if let Some(slow) = tty_name(port).and_then(|tty| slow_latency_timer(Path::new("/sys"), &tty)) {
        let mut warned = WARNED.lock().unwrap_or_else(|e| e.into_inner());
        if !warned.contains(&slow.path) {
            tracing::warn!(
                port = %port.display(),
                "the USB-serial adapter's latency timer is {} ms ({}): every answer waits for \
                 it; for 1 ms run `{}`",
                slow.ms,
                slow.path.display(),
                slow.fix()
            );
            warned.push(slow.path);
        }
    }
    low_latency
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A fake sysfs with `class/tty/<tty>/device` a symlink to `devices/<device>`, and a
    /// latency timer holding `value` at `devices/<timer_dir>/latency_timer`.
    fn sysfs(tty: &str, device: &str, timer_dir: Option<&str>, value: &str) -> tempfile::TempDir {
        let root = tempfile::tempdir().unwrap();
        let device_dir = root.path().join("devices").join(device);
        std::fs::create_dir_all(&device_dir).unwrap();
        let class = root.path().join("class/tty").join(tty);
        std::fs::create_dir_all(&class).unwrap();
        std::os::unix::fs::symlink(&device_dir, class.join("device")).unwrap();
        if let Some(dir) = timer_dir {
            std::fs::write(
                root.path().join("devices").join(dir).join("latency_timer"),
                value,
            )
            .unwrap();
        }
        root
    }

    #[test]
    fn a_slow_timer_of_the_resolved_device_is_reported_with_its_fix() {
        let root = sysfs(
            "ttyUSB0",
            "usb1/1-1/1-1:1.0/ttyUSB0",
            Some("usb1/1-1/1-1:1.0/ttyUSB0"),
            "16\n",
        );
        let slow = slow_latency_timer(root.path(), "ttyUSB0").unwrap();
        assert_eq!(slow.ms, 16);
        let expected = std::fs::canonicalize(root.path())
            .unwrap()
            .join("devices/usb1/1-1/1-1:1.0/ttyUSB0/latency_timer");
        assert_eq!(slow.path, expected);
        assert_eq!(
            slow.fix(),
            format!("echo 1 | sudo tee {}", expected.display())
        );
    }

    #[test]
    fn the_timer_may_sit_one_level_above_the_device() {
        let root = sysfs(
            "ttyUSB1",
            "usb1/1-2/1-2:1.0/ttyUSB1",
            Some("usb1/1-2/1-2:1.0"),
            "8",
        );
        let slow = slow_latency_timer(root.path(), "ttyUSB1").unwrap();
        assert_eq!(slow.ms, 8);
        assert!(slow.path.ends_with("usb1/1-2/1-2:1.0/latency_timer"));
    }

    #[test]
    fn a_fast_missing_or_unreadable_timer_gives_no_warning() {
        for value in ["1", "0\n"] {
            let root = sysfs("ttyUSB0", "usb/ttyUSB0", Some("usb/ttyUSB0"), value);
            assert_eq!(slow_latency_timer(root.path(), "ttyUSB0"), None, "{value}");
        }
        let root = sysfs("ttyUSB0", "usb/ttyUSB0", Some("usb/ttyUSB0"), "fast");
        assert_eq!(slow_latency_timer(root.path(), "ttyUSB0"), None);
        // An on-board UART: a device without a latency timer.
        let root = sysfs("ttyS0", "platform/serial8250/ttyS0", None, "");
        assert_eq!(slow_latency_timer(root.path(), "ttyS0"), None);
        // A tty without a device (pseudo-terminals, Bluetooth RFCOMM).
        assert_eq!(slow_latency_timer(root.path(), "rfcomm0"), None);
    }

    #[test]
    fn the_tty_name_follows_symlinks() {
        let dir = tempfile::tempdir().unwrap();
        let device = dir.path().join("ttyUSB3");
        std::fs::write(&device, "").unwrap();
        let by_id = dir.path().join("usb-FTDI_FT232R-if00-port0");
        std::os::unix::fs::symlink(&device, &by_id).unwrap();
        assert_eq!(tty_name(&by_id).as_deref(), Some("ttyUSB3"));
        assert_eq!(tty_name(&dir.path().join("missing")), None);
    }
}
