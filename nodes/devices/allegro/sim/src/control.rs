//! The simulated Allegro Hand's control socket: the simulator kit's common words (`unplug MS`
//! pulls the slcan adapter, `drop P` loses frames from the hand, `stats` answers the hand's
//! state and the bus counters, see [`Sim::stats_answer`]) and the hand's own (`drop-in P`,
//! `stop-stream`, `resume-stream`, `bus-off MS`, `generation v1|v2|v3|v4`, `overheat [off]`,
//! `inject ID#DATA`, `garbage`, `gravity on|off`).

use std::time::Duration;

use teleop_allegro_protocol::Generation;
use teleop_can_link::CanFrame;
use teleop_sim_kit::command::{Args, DeviceCommand, ParseError, MAX_MS};
use teleop_sim_kit::{Object, Simulator, Stats};

use crate::hand::{HandParams, VirtualObject};
use crate::{parse_frame, Sim};

/// Temperature `overheat` puts the motors at, deg C.
pub const OVERHEAT_TO_C: f64 = 95.0;

/// The hand's own control commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AllegroCommand {
    /// `drop-in P`: a frame sent to the hand is lost with this probability.
    DropIn(f64),
    /// `stop-stream` (true), `resume-stream` (false).
    StopStream(bool),
    /// `bus-off MS`: the bus off for this long.
    BusOff(Duration),
    /// `generation v1|v2|v3|v4`: the firmware's protocol generation.
    Generation(Generation),
    /// `overheat` (true: motors at [`OVERHEAT_TO_C`]), `overheat off` (back to ambient).
    Overheat(bool),
    /// `inject ID#DATA`: the hand sends this frame (candump style, `ID#R` a remote frame).
    Inject(CanFrame),
    /// `garbage`: the adapter sends one unparsable line.
    Garbage,
    /// `gravity on|off`.
    Gravity(bool),
}

impl DeviceCommand for AllegroCommand {
    const WORDS: &'static str = "drop-in P, stop-stream, resume-stream, bus-off MS, \
         generation v1|v2|v3|v4, overheat [off], inject ID#DATA, garbage, gravity on|off";

    fn parse(word: &str, args: &mut Args<'_>) -> Option<Result<Self, ParseError>> {
        Some(match word {
            "drop-in" => args.probability().map(Self::DropIn),
            "stop-stream" => Ok(Self::StopStream(true)),
            "resume-stream" => Ok(Self::StopStream(false)),
            "bus-off" => args.millis(MAX_MS).map(Self::BusOff),
            "generation" => args
                .value("v1|v2|v3|v4", |_: &Generation| true)
                .map(Self::Generation),
            "overheat" => match args.optional() {
                None => Ok(Self::Overheat(true)),
                Some("off") => Ok(Self::Overheat(false)),
                Some(other) => Err(args.error("nothing or off", other)),
            },
            "inject" => args.text("ID#DATA").and_then(|text| {
                parse_frame(text)
                    .map(Self::Inject)
                    .map_err(|e| args.error("ID#DATA", &e))
            }),
            "garbage" => Ok(Self::Garbage),
            "gravity" => args
                .choice(&["on", "off"])
                .map(|w| Self::Gravity(w == "on")),
            _ => return None,
        })
    }
}

impl Simulator for Sim {
    type Command = AllegroCommand;

    fn unplug(&self, pause: Duration) -> Result<String, String> {
        if Sim::unplug(self, pause) {
            Ok(format!("unplug {} ms", pause.as_millis()))
        } else {
            Err("unplug: no slcan adapter (start with --slcan PATH)".into())
        }
    }

    fn set_drop(&self, p: f64) -> Result<String, String> {
        let mut f = self.faults();
        f.drop_out = p;
        self.set_faults(f);
        tracing::warn!("drop {p}");
        Ok(format!("drop {p}"))
    }

    fn clear(&self) -> Result<String, String> {
        self.set_faults(Default::default());
        Ok(String::new())
    }

    fn stats(&self) -> Stats {
        self.stats_answer()
    }

    fn set_object(&self, object: Option<Object>) -> Result<String, String> {
        self.with_firmware(|fw| fw.hand_mut().set_object(object.map(VirtualObject::of)));
        Ok(format!("object {}", object.map_or("none", Object::name)))
    }

    fn command(&self, command: AllegroCommand) -> Result<String, String> {
        Ok(match command {
            AllegroCommand::DropIn(p) => {
                let mut f = self.faults();
                f.drop_in = p;
                self.set_faults(f);
                tracing::warn!("drop-in {p}");
                format!("drop-in {p}")
            }
            AllegroCommand::StopStream(stop) => {
                self.with_firmware(|fw| fw.stop_stream(stop));
                let word = if stop { "stop-stream" } else { "resume-stream" };
                tracing::warn!("{word}");
                word.into()
            }
            AllegroCommand::BusOff(d) => {
                self.bus_off(d);
                tracing::warn!("bus off for {} ms", d.as_millis());
                format!("bus-off {} ms", d.as_millis())
            }
            AllegroCommand::Generation(g) => {
                self.with_firmware(|fw| fw.set_generation(g));
                tracing::warn!("protocol generation now {g}");
                format!("generation {g}")
            }
            AllegroCommand::Overheat(true) => {
                self.with_firmware(|fw| fw.heat(OVERHEAT_TO_C));
                format!("overheat {OVERHEAT_TO_C} C")
            }
            AllegroCommand::Overheat(false) => {
                let ambient = HandParams::default().ambient_c;
                self.with_firmware(|fw| fw.heat(ambient));
                format!("overheat off {ambient} C")
            }
            AllegroCommand::Inject(frame) => {
                self.inject(frame);
                format!("inject {frame}")
            }
            AllegroCommand::Garbage => {
                if !self.garbage() {
                    return Err("garbage: no slcan adapter (start with --slcan PATH)".into());
                }
                "garbage".into()
            }
            AllegroCommand::Gravity(on) => {
                self.with_firmware(|fw| fw.hand_mut().set_gravity(on));
                format!("gravity {}", if on { "on" } else { "off" })
            }
        })
    }
}
