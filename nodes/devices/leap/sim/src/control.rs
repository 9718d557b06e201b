//! The simulated LEAP Hand's control socket: the simulator kit's common words (`unplug MS`
//! pulls the USB cable, servos powered off; `drop P` loses each status with probability P;
//! `clear` ends every fault: probabilities back to 0, silent servos answering; `stats`, see
//! [`Sim::stats_answer`]; `object ball|bar|none`) and the hand's own:
//!
//! | line | what |
//! |---|---|
//! | `silent ID [MS]` | servo ID neither hears nor answers (for MS ms; without MS until `clear`) |
//! | `crc P` | each status gets one corrupted byte with probability P |
//! | `noise [N]` | a burst of N random bytes on the line (default 64, at most 4096) |
//! | `overload ID` | servo ID's Overload bit (5) set: shutdown, Alert, until a reboot |
//! | `overheat ID` | servo ID heated to 80 deg C, over its Temperature Limit: Overheating (bit 2) |

use std::time::Duration;

use teleop_leap_protocol::packet::MAX_ID;
use teleop_leap_protocol::xc330::HardwareError;
use teleop_sim_kit::command::{Args, DeviceCommand, ParseError, MAX_MS};
use teleop_sim_kit::{Object, Simulator, Stats};

use crate::bus::Faults;
use crate::serve::MAX_NOISE;
use crate::Sim;

/// Temperature `overheat` puts a servo at, deg C (over the default Temperature Limit, 70).
pub const OVERHEAT_TO_C: f64 = 80.0;
/// Bytes of `noise` without a count.
pub const NOISE_BYTES: usize = 64;

/// The hand's own control commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LeapCommand {
    /// `silent ID [MS]`.
    Silent(u8, Option<Duration>),
    /// `crc P`.
    Crc(f64),
    /// `noise [N]`.
    Noise(usize),
    /// `overload ID`.
    Overload(u8),
    /// `overheat ID`.
    Overheat(u8),
}

fn id(args: &mut Args<'_>) -> Result<u8, ParseError> {
    args.value("ID (0..=252)", |id: &u8| *id <= MAX_ID)
}

impl DeviceCommand for LeapCommand {
    const WORDS: &'static str = "silent ID [MS], crc P, noise [N], overload ID, overheat ID";

    fn parse(word: &str, args: &mut Args<'_>) -> Option<Result<Self, ParseError>> {
        Some(match word {
            "silent" => id(args).and_then(|id| match args.optional() {
                None => Ok(Self::Silent(id, None)),
                Some(ms) => ms
                    .parse::<u64>()
                    .ok()
                    .filter(|ms| *ms <= MAX_MS)
                    .map(|ms| Self::Silent(id, Some(Duration::from_millis(ms))))
                    .ok_or_else(|| args.error(&format!("MS (0..={MAX_MS})"), ms)),
            }),
            "crc" => args.probability().map(Self::Crc),
            "noise" => match args.optional() {
                None => Ok(Self::Noise(NOISE_BYTES)),
                Some(n) => n
                    .parse::<usize>()
                    .ok()
                    .filter(|n| (1..=MAX_NOISE).contains(n))
                    .map(Self::Noise)
                    .ok_or_else(|| args.error(&format!("N (1..={MAX_NOISE})"), n)),
            },
            "overload" => id(args).map(Self::Overload),
            "overheat" => id(args).map(Self::Overheat),
            _ => return None,
        })
    }
}

impl Simulator for Sim {
    type Command = LeapCommand;

    fn unplug(&self, pause: Duration) -> Result<String, String> {
        Sim::unplug(self, pause);
        tracing::warn!("unplugged for {} ms", pause.as_millis());
        Ok(format!("unplug {} ms", pause.as_millis()))
    }

    fn set_drop(&self, p: f64) -> Result<String, String> {
        self.with_bus(|bus, _| {
            let faults = bus.faults();
            bus.set_faults(Faults { drop: p, ..faults });
        });
        tracing::warn!("drop {p}");
        Ok(format!("drop {p}"))
    }

    fn clear(&self) -> Result<String, String> {
        self.with_bus(|bus, _| {
            bus.set_faults(Faults {
                drop: 0.0,
                crc: 0.0,
            });
            bus.unsilence_all();
        });
        Ok(String::new())
    }

    fn stats(&self) -> Stats {
        self.stats_answer()
    }

    fn set_object(&self, object: Option<Object>) -> Result<String, String> {
        self.with_bus(|bus, _| bus.hand_mut().set_object(object));
        Ok(format!("object {}", object.map_or("none", Object::name)))
    }

    fn command(&self, command: LeapCommand) -> Result<String, String> {
        let known = |id: u8| {
            self.with_bus(|bus, _| bus.servo_mut(id).is_some())
                .then_some(())
                .ok_or_else(|| format!("no servo with ID {id}"))
        };
        Ok(match command {
            LeapCommand::Silent(id, pause) => {
                self.with_bus(|bus, now| {
                    let until = pause.map_or(f64::INFINITY, |d| now + d.as_secs_f64());
                    bus.set_silent(id, until);
                });
                tracing::warn!("servo {id} silent");
                match pause {
                    Some(d) => format!("silent {id} {} ms", d.as_millis()),
                    None => format!("silent {id}"),
                }
            }
            LeapCommand::Crc(p) => {
                self.with_bus(|bus, _| {
                    let faults = bus.faults();
                    bus.set_faults(Faults { crc: p, ..faults });
                });
                tracing::warn!("crc {p}");
                format!("crc {p}")
            }
            LeapCommand::Noise(n) => {
                self.noise(n);
                format!("noise {n} bytes")
            }
            LeapCommand::Overload(id) => {
                known(id)?;
                self.with_bus(|bus, _| {
                    if let Some(s) = bus.servo_mut(id) {
                        s.raise(HardwareError::OVERLOAD);
                    }
                });
                tracing::warn!("servo {id} overloaded");
                format!("overload {id}")
            }
            LeapCommand::Overheat(id) => {
                known(id)?;
                self.with_bus(|bus, _| {
                    if let Some(s) = bus.servo_mut(id) {
                        s.heat(OVERHEAT_TO_C);
                    }
                });
                tracing::warn!("servo {id} at {OVERHEAT_TO_C} C");
                format!("overheat {id} {OVERHEAT_TO_C} C")
            }
        })
    }
}
