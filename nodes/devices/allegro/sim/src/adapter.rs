//! A simulated USB slcan adapter (CANable or CAN232/CANUSB style) as a pure state machine:
//! host command lines in, answer bytes and frames for the bus out. The pty and the bus around
//! it are in [`crate::serve`].
//!
//! Behaviour (docs/devices/allegro.md, "slcan"): `Sn`/`sxxyy` set the bit rate only while closed
//! (else BEL); `O`/`L` open (BEL when already open or no bit rate was set), `C` closes (BEL
//! when already closed); frames are refused with BEL while closed, listen-only or bus-off;
//! a frame sent at another bit rate than the bus's is taken by the adapter but never
//! acknowledged on the bus (error-passive flags, nothing passes); `F` answers the status flags
//! (bus-off: bus error + error passive) and clears the latched ones; `V`/`N` answer version
//! and serial; `Z0`/`Z1` timestamps; `M`/`m` are accepted (no filtering). Acks: CANable style
//! answers every line with CR (or BEL); Lawicel style answers `t`/`r` with `z\r` and `T`/`R`
//! with `Z\r`. Received frames go out as `t...` lines (with a 4-digit ms timestamp when on),
//! only while open at the bus's bit rate.

use teleop_can_link::slcan::{self, status, Command, Item};
use teleop_can_link::CanFrame;

/// How the adapter acknowledges a transmitted frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AckStyle {
    /// CANable: a bare CR for every accepted line, frames included.
    Canable,
    /// CAN232 / CANUSB (Lawicel): `z\r` for a standard frame, `Z\r` for an extended one.
    Lawicel,
}

impl std::str::FromStr for AckStyle {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "canable" => Ok(Self::Canable),
            "lawicel" => Ok(Self::Lawicel),
            other => Err(format!(
                "unknown ack style {other:?}: use canable or lawicel"
            )),
        }
    }
}

/// The slcan bit rate code of the Allegro's bus (1 Mbit/s).
pub const BUS_CODE: u8 = 8;

/// The adapter's state.
#[derive(Debug, Clone)]
pub struct Adapter {
    style: AckStyle,
    open: bool,
    listen_only: bool,
    /// `Sn` code set; `None` before any (or after `sxxyy`, a rate that is not the bus's).
    bitrate: Option<u8>,
    bitrate_set: bool,
    timestamps: bool,
    latched: u8,
    bus_off: bool,
    refused: u64,
}

impl Adapter {
    /// A closed adapter with no bit rate set.
    pub fn new(style: AckStyle) -> Self {
        Self {
            style,
            open: false,
            listen_only: false,
            bitrate: None,
            bitrate_set: false,
            timestamps: false,
            latched: 0,
            bus_off: false,
            refused: 0,
        }
    }

    /// Open (normal or listen-only).
    pub fn is_open(&self) -> bool {
        self.open
    }

    /// Frames pass between the host and the bus: open at the bus's bit rate, bus on.
    pub fn passes(&self) -> bool {
        self.open && self.bitrate == Some(BUS_CODE) && !self.bus_off
    }

    /// Lines answered with BEL so far.
    pub fn refused(&self) -> u64 {
        self.refused
    }

    /// The controller is bus-off (true) or back on the bus.
    pub fn set_bus_off(&mut self, off: bool) {
        self.bus_off = off;
        if off {
            self.latched |= status::BUS_ERROR | status::ERROR_PASSIVE;
        }
    }

    /// The status flags `F` would answer now.
    pub fn flags(&self) -> u8 {
        let live = if self.bus_off {
            status::BUS_ERROR | status::ERROR_PASSIVE
        } else {
            0
        };
        self.latched | live
    }

    fn refuse(&mut self, out: &mut Vec<u8>) {
        self.refused += 1;
        Item::Error.encode(out);
    }

    /// Takes one host line (or why it did not parse); writes the answer to `out`, returns the
    /// frame to put on the bus, if any.
    pub fn command(
        &mut self,
        line: Result<Command, String>,
        out: &mut Vec<u8>,
    ) -> Option<CanFrame> {
        let Ok(command) = line else {
            self.refuse(out);
            return None;
        };
        match command {
            Command::Bitrate(_) | Command::Btr(..) if self.open => self.refuse(out),
            Command::Bitrate(code) => {
                self.bitrate = Some(code);
                self.bitrate_set = true;
                Item::Ok.encode(out);
            }
            Command::Btr(..) => {
                // Raw timing registers: taken as some rate other than the bus's.
                self.bitrate = None;
                self.bitrate_set = true;
                Item::Ok.encode(out);
            }
            Command::Open | Command::ListenOnly if self.open || !self.bitrate_set => {
                self.refuse(out)
            }
            Command::Open | Command::ListenOnly => {
                self.open = true;
                self.listen_only = command == Command::ListenOnly;
                Item::Ok.encode(out);
            }
            Command::Close if !self.open => self.refuse(out),
            Command::Close => {
                self.open = false;
                self.listen_only = false;
                Item::Ok.encode(out);
            }
            Command::Transmit(frame) => {
                if !self.open || self.listen_only || self.bus_off {
                    self.refuse(out);
                    return None;
                }
                match self.style {
                    AckStyle::Canable => Item::Ok.encode(out),
                    AckStyle::Lawicel if frame.is_extended() => out.extend_from_slice(b"Z\r"),
                    AckStyle::Lawicel => Item::FrameAck.encode(out),
                }
                if self.bitrate != Some(BUS_CODE) {
                    // Nobody on the bus acknowledges a frame at the wrong bit rate.
                    self.latched |= status::ERROR_WARNING | status::ERROR_PASSIVE;
                    return None;
                }
                return Some(frame);
            }
            Command::Status => {
                Item::Status(self.flags()).encode(out);
                self.latched = 0;
            }
            Command::Version => Item::Version(match self.style {
                AckStyle::Canable => "sim-allegro-canable".to_string(),
                AckStyle::Lawicel => "1013".to_string(),
            })
            .encode(out),
            Command::Serial => Item::Serial("SIM1".to_string()).encode(out),
            Command::Timestamps(_) if self.open => self.refuse(out),
            Command::Timestamps(on) => {
                self.timestamps = on;
                Item::Ok.encode(out);
            }
            Command::AcceptanceCode(_) | Command::AcceptanceMask(_) => Item::Ok.encode(out),
        }
        None
    }

    /// Writes a frame received from the bus as the host sees it, if it passes; `now_ms` is
    /// the adapter's clock for timestamps.
    pub fn deliver(&self, frame: &CanFrame, now_ms: u64, out: &mut Vec<u8>) -> bool {
        if !self.passes() {
            return false;
        }
        if self.timestamps {
            slcan::encode_frame_timestamped(frame, (now_ms % 60_000) as u16, out);
        } else {
            slcan::encode_frame(frame, out);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use teleop_can_link::slcan::CommandDecoder;

    /// Feeds `text` (CR-separated lines); returns the answer bytes and the frames for the bus.
    fn feed(a: &mut Adapter, text: &str) -> (Vec<u8>, Vec<CanFrame>) {
        let mut out = Vec::new();
        let mut frames = Vec::new();
        let mut lines = Vec::new();
        CommandDecoder::new().push(text.as_bytes(), &mut |c| lines.push(c));
        for line in lines {
            frames.extend(a.command(line, &mut out));
        }
        (out, frames)
    }

    #[test]
    fn bit_rate_only_while_closed_then_open_and_frames_pass() {
        let mut a = Adapter::new(AckStyle::Canable);
        assert_eq!(feed(&mut a, "O\r").0, b"\x07", "no bit rate yet");
        assert_eq!(feed(&mut a, "t1000\r").0, b"\x07", "closed");
        assert_eq!(feed(&mut a, "S8\rO\r").0, b"\r\r");
        assert_eq!(feed(&mut a, "S6\r").0, b"\x07", "bit rate while open");
        let (out, frames) = feed(&mut a, "t2046030000000000\r");
        assert_eq!(out, b"\r");
        assert_eq!(
            frames,
            [CanFrame::standard(0x204, &[3, 0, 0, 0, 0, 0]).expect("frame")]
        );
        let mut line = Vec::new();
        assert!(a.deliver(&frames[0], 0, &mut line));
        assert_eq!(line, b"t2046030000000000\r");
        assert_eq!(feed(&mut a, "C\r").0, b"\r");
        assert_eq!(feed(&mut a, "C\r").0, b"\x07", "already closed");
        assert!(
            !a.deliver(&frames[0], 0, &mut line),
            "closed: nothing passes"
        );
        assert_eq!(a.refused(), 4);
    }

    #[test]
    fn lawicel_acks_z_for_standard_and_capital_z_for_extended() {
        let mut a = Adapter::new(AckStyle::Lawicel);
        feed(&mut a, "S8\rO\r");
        assert_eq!(feed(&mut a, "t04A0\r").0, b"z\r");
        assert_eq!(feed(&mut a, "r2000\r").0, b"z\r");
        assert_eq!(feed(&mut a, "T000001231AA\r").0, b"Z\r");
        assert_eq!(feed(&mut a, "V\r").0, b"V1013\r");
    }

    #[test]
    fn bad_lines_get_bel() {
        let mut a = Adapter::new(AckStyle::Canable);
        assert_eq!(feed(&mut a, "S9\rX\rt12\r").0, b"\x07\x07\x07");
    }

    #[test]
    fn bus_off_shows_in_the_status_flags_and_refuses_frames() {
        let mut a = Adapter::new(AckStyle::Canable);
        feed(&mut a, "S8\rO\r");
        assert_eq!(feed(&mut a, "F\r").0, b"F00\r");
        a.set_bus_off(true);
        assert!(!a.passes());
        assert_eq!(feed(&mut a, "t04A0\r").0, b"\x07");
        assert_eq!(feed(&mut a, "F\r").0, b"FA0\r");
        a.set_bus_off(false);
        assert_eq!(feed(&mut a, "F\r").0, b"F00\r");
        assert!(a.passes());
        // A bus-off shorter than the host's status polls stays latched until read.
        a.set_bus_off(true);
        a.set_bus_off(false);
        assert_eq!(feed(&mut a, "F\r").0, b"FA0\r", "latched until read");
        assert_eq!(feed(&mut a, "F\r").0, b"F00\r");
    }

    #[test]
    fn a_wrong_bit_rate_takes_frames_but_nothing_passes() {
        let mut a = Adapter::new(AckStyle::Canable);
        let (out, frames) = feed(&mut a, "S6\rO\rt04A0\r");
        assert_eq!(out, b"\r\r\r");
        assert!(frames.is_empty());
        assert!(!a.passes());
        assert_eq!(feed(&mut a, "F\r").0, b"F24\r");
    }

    #[test]
    fn timestamps_are_appended_when_on() {
        let mut a = Adapter::new(AckStyle::Canable);
        feed(&mut a, "Z1\rS8\rO\r");
        let mut line = Vec::new();
        let f = CanFrame::standard(0x3D3, &[1, 2]).expect("frame");
        assert!(a.deliver(&f, 61_234, &mut line));
        assert_eq!(line, b"t3D32010204D2\r");
    }
}
