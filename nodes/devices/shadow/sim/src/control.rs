//! The emulated Shadow Hand's control socket: the simulator kit's common words (`unplug MS`
//! takes the EtherCAT link down, `drop P` loses frames at the bridge) and the hand's own
//! (`silent MOTOR|none`, `overheat MOTOR`, `flash-stall MOTOR N|off`, `joints`).

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use teleop_shadow_protocol::layout::MOTORS;
use teleop_sim_kit::command::{Args, DeviceCommand, ParseError};
use teleop_sim_kit::outage::Outage;
use teleop_sim_kit::{lock, Object, Simulator, Stats};

use crate::ethercat::ShadowBus;
use crate::hand::{self, JOINTS};
use crate::palm::CUT_OUT_C;

/// The hand's own control commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShadowCommand {
    /// `silent MOTOR|none`: a motor board stops answering (none: every board answers).
    Silent(Option<usize>),
    /// `overheat MOTOR`: a motor above its cut-out temperature.
    Overheat(usize),
    /// `flash-stall MOTOR N|off`: a board stops acking after N more messages.
    FlashStall(usize, Option<u64>),
    /// `joints`: every joint's angle.
    Joints,
}

const MOTOR: &str = "MOTOR (0..19)";

fn motor(args: &mut Args<'_>) -> Result<usize, ParseError> {
    args.value(MOTOR, |m: &usize| *m < MOTORS)
}

impl DeviceCommand for ShadowCommand {
    const WORDS: &'static str =
        "silent MOTOR|none, overheat MOTOR, flash-stall MOTOR N|off, joints";

    fn parse(word: &str, args: &mut Args<'_>) -> Option<Result<Self, ParseError>> {
        Some(match word {
            "silent" => match args.text("MOTOR (0..19)|none") {
                Ok("none") => Ok(Self::Silent(None)),
                Ok(m) => m
                    .parse::<usize>()
                    .ok()
                    .filter(|m| *m < MOTORS)
                    .map(|m| Self::Silent(Some(m)))
                    .ok_or_else(|| args.error("MOTOR (0..19)|none", m)),
                Err(e) => Err(e),
            },
            "overheat" => motor(args).map(Self::Overheat),
            "flash-stall" => motor(args).and_then(|m| match args.text("MESSAGES|off")? {
                "off" => Ok(Self::FlashStall(m, None)),
                n => n
                    .parse()
                    .map(|n| Self::FlashStall(m, Some(n)))
                    .map_err(|_| args.error("MESSAGES|off", n)),
            }),
            "joints" => Ok(Self::Joints),
            _ => return None,
        })
    }
}

/// The emulated hand as its control socket drives it.
pub struct ShadowSim {
    bus: Arc<Mutex<ShadowBus>>,
    start: Instant,
    link: Outage,
}

impl ShadowSim {
    /// `bus`, whose time zero is `start`.
    pub fn new(bus: Arc<Mutex<ShadowBus>>, start: Instant) -> Self {
        Self {
            bus,
            start,
            link: Outage::new(),
        }
    }
}

/// The hand's geometry of `object` (it has no bar).
pub fn hand_object(object: Option<Object>) -> Result<Option<hand::VirtualObject>, String> {
    match object {
        None => Ok(None),
        Some(Object::Ball) => Ok(Some(hand::VirtualObject::ball())),
        Some(other) => Err(format!(
            "object: the Shadow simulator has no {}: use ball or none",
            other.name()
        )),
    }
}

impl Simulator for ShadowSim {
    type Command = ShadowCommand;

    fn unplug(&self, pause: Duration) -> Result<String, String> {
        let bus = Arc::clone(&self.bus);
        self.link.start(
            "link-up",
            pause,
            || lock(&self.bus).bridge.faults().link_down = true,
            move || {
                lock(&bus).bridge.faults().link_down = false;
                tracing::info!("link up again");
            },
        );
        tracing::warn!("link down for {} ms", pause.as_millis());
        Ok(format!("unplug {} ms", pause.as_millis()))
    }

    fn set_drop(&self, p: f64) -> Result<String, String> {
        lock(&self.bus).bridge.faults().drop_probability = p as f32;
        Ok(format!("drop {p}"))
    }

    fn clear(&self) -> Result<String, String> {
        lock(&self.bus).bridge.faults().drop_probability = 0.0;
        Ok(String::new())
    }

    fn stats(&self) -> Stats {
        let bus = lock(&self.bus);
        let (state, error, code) = bus.palm.al_state();
        Stats::new()
            .field("palm", state)
            .field("error", error)
            .field("code", format!("{code:#06x}"))
            .field("up_s", format!("{:.1}", self.start.elapsed().as_secs_f32()))
            .counters("", &bus.palm.app().stats)
            .counters("esc_", &bus.palm.stats())
    }

    fn set_object(&self, object: Option<Object>) -> Result<String, String> {
        let o = hand_object(object)?;
        lock(&self.bus).palm_mut().hand.object = o;
        Ok(format!("object {}", object.map_or("none", Object::name)))
    }

    fn command(&self, command: ShadowCommand) -> Result<String, String> {
        let mut bus = lock(&self.bus);
        let palm = bus.palm_mut();
        Ok(match command {
            ShadowCommand::Silent(None) => {
                for b in &mut palm.boards {
                    b.silent = false;
                }
                "every motor answers".into()
            }
            ShadowCommand::Silent(Some(m)) => {
                palm.boards[m].silent = true;
                format!("motor {m} stops answering")
            }
            ShadowCommand::Overheat(m) => {
                palm.motors[m].temperature = CUT_OUT_C + 5.0;
                format!("motor {m} at {} C", CUT_OUT_C + 5.0)
            }
            ShadowCommand::FlashStall(m, None) => {
                palm.boards[m].stop_after = None;
                format!("motor {m} acks again")
            }
            ShadowCommand::FlashStall(m, Some(n)) => {
                palm.boards[m].stop_after = Some(n);
                format!("motor {m} stops acking after {n} messages")
            }
            ShadowCommand::Joints => JOINTS
                .iter()
                .zip(palm.hand.angles)
                .map(|(j, a)| format!("{j} {a:.3}"))
                .collect::<Vec<_>>()
                .join(" "),
        })
    }
}
