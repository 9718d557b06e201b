//! The emulated Revo2's control socket: the simulator kit's common words (`unplug MS` takes the
//! EtherCAT link down, `object NAME` places an object with the process's contact model) and the
//! Revo2's own (`wrong-wkc P`, `watchdog`, `refuse CODE`, `foe-stall N|off`,
//! `flash-time ERASE_MS PER_KIB_MS`, `power-cycle MS`, `versions`).

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use teleop_ecat_sim::SubDevice;
use teleop_sim_kit::command::{Args, DeviceCommand, ParseError, MAX_MS};
use teleop_sim_kit::outage::Outage;
use teleop_sim_kit::{lock, Object, Simulator, Stats};

use crate::hand::{ObjectModel, ShapeObject, VirtualObject};
use crate::Revo2;

/// The Revo2's own control commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Revo2Command {
    /// `wrong-wkc P`: a process data datagram's working counter falsified with this probability.
    WrongWkc(f64),
    /// `watchdog`: the SM watchdog trips now.
    Watchdog,
    /// `refuse CODE`: the next upward transition refused with this AL status code (hex).
    Refuse(u16),
    /// `foe-stall N|off`: the boot loader stops answering after N data packets of the next
    /// firmware transfer.
    FoeStall(Option<u32>),
    /// `flash-time ERASE_MS PER_KIB_MS`: the simulated flash's timing.
    FlashTime(Duration, Duration),
    /// `power-cycle MS`: the device restarts, off the bus for this long.
    PowerCycle(Duration),
    /// `versions`: the firmware versions.
    Versions,
}

impl DeviceCommand for Revo2Command {
    const WORDS: &'static str = "wrong-wkc P, watchdog, refuse CODE, foe-stall N|off, \
         flash-time ERASE_MS PER_KIB_MS, power-cycle MS, versions";

    fn parse(word: &str, args: &mut Args<'_>) -> Option<Result<Self, ParseError>> {
        Some(match word {
            "wrong-wkc" => args.probability().map(Self::WrongWkc),
            "watchdog" => Ok(Self::Watchdog),
            "refuse" => args.text("CODE (hex, e.g. 0x0011)").and_then(|code| {
                u16::from_str_radix(code.trim_start_matches("0x"), 16)
                    .map(Self::Refuse)
                    .map_err(|_| args.error("CODE (hex, e.g. 0x0011)", code))
            }),
            "foe-stall" => args.text("PACKETS|off").and_then(|n| match n {
                "off" => Ok(Self::FoeStall(None)),
                n => n
                    .parse()
                    .map(|n| Self::FoeStall(Some(n)))
                    .map_err(|_| args.error("PACKETS|off", n)),
            }),
            "flash-time" => args.millis(MAX_MS).and_then(|erase| {
                args.millis(MAX_MS)
                    .map(|per_kib| Self::FlashTime(erase, per_kib))
            }),
            "power-cycle" => args.millis(MAX_MS).map(Self::PowerCycle),
            "versions" => Ok(Self::Versions),
            _ => return None,
        })
    }
}

/// How the objects touch the fingers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Contact {
    /// By geometry ([`ShapeObject`]), with this surface stiffness, newtons per metre.
    Geometric {
        /// The objects' surface stiffness.
        stiffness_n_per_m: f32,
    },
    /// In joint space ([`VirtualObject`]): each finger stops at a fixed position.
    Joint,
}

/// The emulated Revo2 as its control socket drives it.
pub struct Revo2Sim {
    device: Arc<Mutex<SubDevice<Revo2>>>,
    start: Instant,
    link: Outage,
    contact: Contact,
}

impl Revo2Sim {
    /// `device`, whose time zero is `start`, placing objects with `contact`.
    pub fn new(device: Arc<Mutex<SubDevice<Revo2>>>, start: Instant, contact: Contact) -> Self {
        Self {
            device,
            start,
            link: Outage::new(),
            contact,
        }
    }
}

/// The Revo2's model of `object` under `contact`: geometrically a ball or a bar (a block across
/// the fingers); in joint space only a ball.
pub fn object_model(
    object: Option<Object>,
    contact: Contact,
) -> Result<Option<ObjectModel>, String> {
    let Some(object) = object else {
        return Ok(None);
    };
    Ok(Some(match (contact, object) {
        (Contact::Geometric { stiffness_n_per_m }, Object::Ball) => {
            ObjectModel::Shape(ShapeObject::ball(stiffness_n_per_m))
        }
        (Contact::Geometric { stiffness_n_per_m }, Object::Bar) => {
            ObjectModel::Shape(ShapeObject::block(stiffness_n_per_m))
        }
        (Contact::Joint, Object::Ball) => ObjectModel::Joint(VirtualObject::ball()),
        (Contact::Joint, other) => {
            return Err(format!(
                "object: the Revo2 simulator's joint-space contact has no {}: use ball or none \
                 (or --contact geometric)",
                other.name()
            ))
        }
    }))
}

impl Simulator for Revo2Sim {
    type Command = Revo2Command;

    fn unplug(&self, pause: Duration) -> Result<String, String> {
        let device = Arc::clone(&self.device);
        self.link.start(
            "link-up",
            pause,
            || lock(&self.device).faults().link_down = true,
            move || {
                lock(&device).faults().link_down = false;
                tracing::info!("link up again");
            },
        );
        tracing::warn!("link down for {} ms", pause.as_millis());
        Ok(format!("unplug {} ms", pause.as_millis()))
    }

    fn set_drop(&self, p: f64) -> Result<String, String> {
        lock(&self.device).faults().drop_probability = p as f32;
        Ok(format!("drop {p}"))
    }

    fn clear(&self) -> Result<String, String> {
        let mut device = lock(&self.device);
        device.faults().drop_probability = 0.0;
        device.faults().wrong_wkc_probability = 0.0;
        Ok(String::new())
    }

    fn stats(&self) -> Stats {
        let device = lock(&self.device);
        let (state, error, code) = device.al_state();
        Stats::new()
            .field("state", state)
            .field("error", error)
            .field("code", format!("{code:#06x}"))
            .field("up_s", format!("{:.1}", self.start.elapsed().as_secs_f32()))
            .counters("", &device.stats())
    }

    fn set_object(&self, object: Option<Object>) -> Result<String, String> {
        let o = object_model(object, self.contact)?;
        lock(&self.device).app_mut().hand_mut().set_object(o);
        Ok(format!("object {}", object.map_or("none", Object::name)))
    }

    fn command(&self, command: Revo2Command) -> Result<String, String> {
        let mut dev = lock(&self.device);
        Ok(match command {
            Revo2Command::WrongWkc(p) => {
                dev.faults().wrong_wkc_probability = p as f32;
                format!("wrong-wkc {p}")
            }
            Revo2Command::Watchdog => {
                dev.trip_watchdog();
                "watchdog tripped".into()
            }
            Revo2Command::Refuse(code) => {
                dev.faults().refuse_next_transition = Some(code);
                format!("refusing the next transition with {code:#06x}")
            }
            Revo2Command::FoeStall(None) => {
                dev.app_mut().upgrade_mut().stall_after = None;
                "foe-stall off".into()
            }
            Revo2Command::FoeStall(Some(n)) => {
                dev.app_mut().upgrade_mut().stall_after = Some(n);
                format!("the boot loader stops answering after {n} data packets")
            }
            Revo2Command::FlashTime(erase, per_kib) => {
                let timing = &mut dev.app_mut().upgrade_mut().timing;
                timing.erase = erase;
                timing.per_kib = per_kib;
                format!(
                    "flash erase {} ms, {} ms per KiB",
                    erase.as_millis(),
                    per_kib.as_millis()
                )
            }
            Revo2Command::PowerCycle(off) => {
                dev.restart(self.start.elapsed(), off);
                format!("restarting, off the bus for {} ms", off.as_millis())
            }
            Revo2Command::Versions => {
                let (control, wrist) = dev.app().firmware_versions();
                format!("control {control} wrist {wrist}")
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn objects_take_the_contact_model_and_only_geometry_has_a_bar() {
        let firm = Contact::Geometric {
            stiffness_n_per_m: 3000.0,
        };
        assert_eq!(object_model(None, firm), Ok(None));
        assert_eq!(
            object_model(Some(Object::Ball), firm),
            Ok(Some(ObjectModel::Shape(ShapeObject::ball(3000.0))))
        );
        assert_eq!(
            object_model(Some(Object::Bar), firm),
            Ok(Some(ObjectModel::Shape(ShapeObject::block(3000.0))))
        );
        assert_eq!(
            object_model(Some(Object::Ball), Contact::Joint),
            Ok(Some(ObjectModel::Joint(VirtualObject::ball())))
        );
        let err = object_model(Some(Object::Bar), Contact::Joint).unwrap_err();
        assert!(
            err.contains("bar") && err.contains("--contact geometric"),
            "{err}"
        );
    }
}
