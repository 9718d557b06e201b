//! The glove's firmware as seen from the wire: which frames it answers, its register file with
//! permissions and side effects, and the pending ID/baud changes that take effect after the
//! acknowledge. Pure: the serial timing and fault injection live in `serve`.

use teleop_glove_protocol::{
    reg, register_containing, BaudRate, Frame, Register, Request, Response, Width, WRITE_ACCEPTED,
    WRITE_REFUSED,
};

use crate::hand::{Drive, Hand, FINGERS};

/// How long the device's own calibration runs: the five steps of the manual, 1 + 4 x 2 s.
pub const CALIBRATION_S: f32 = 9.0;

/// Parameters kept in flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Flash {
    id: u8,
    baud: BaudRate,
}

/// The simulated device.
#[derive(Debug, Clone)]
pub struct Device {
    id: u8,
    baud: BaudRate,
    flash: Flash,
    hand: Hand,
    position_set: [i16; FINGERS],
    force_set: [i16; FINGERS],
    calibrating_until: Option<f32>,
    pending_id: Option<u8>,
    pending_baud: Option<BaudRate>,
    now: f32,
}

impl Device {
    /// A device with this id and baud rate, as if they had been saved to flash.
    pub fn new(id: u8, baud: BaudRate, hand: Hand) -> Self {
        Self {
            id,
            baud,
            flash: Flash { id, baud },
            hand,
            position_set: [-1; FINGERS],
            force_set: [0; FINGERS],
            calibrating_until: None,
            pending_id: None,
            pending_baud: None,
            now: 0.0,
        }
    }

    /// The id it answers to.
    pub fn id(&self) -> u8 {
        self.id
    }

    /// The current line speed.
    pub fn baud(&self) -> BaudRate {
        self.baud
    }

    /// The operator's hand.
    pub fn hand(&self) -> &Hand {
        &self.hand
    }

    /// The last force set-points received (glove order).
    pub fn force_set(&self) -> [i16; FINGERS] {
        self.force_set
    }

    /// True while the device's own calibration runs.
    pub fn calibrating(&self) -> bool {
        self.calibrating_until.is_some_and(|t| self.now < t)
    }

    /// Advances the hand to `t` seconds.
    pub fn advance_to(&mut self, t: f32) {
        self.now = t;
        self.hand.advance_to(t);
        if self.calibrating_until.is_some_and(|end| t >= end) {
            self.calibrating_until = None;
        }
    }

    /// Handles one request. `None` when the device stays silent: another id, or a read of
    /// addresses outside the register map (the manual defines no error answer; silence is what
    /// the host then sees as a timeout).
    pub fn handle(&mut self, frame: &Frame<Request>) -> Option<Frame<Response>> {
        if frame.id != self.id {
            return None;
        }
        let body = match frame.body {
            Request::ForceControl { forces } => {
                for (f, &force) in forces.iter().enumerate() {
                    self.set_force(f, force);
                }
                Response::ForceControl {
                    positions: self.hand.positions(),
                }
            }
            Request::PositionControl { positions } => {
                for (f, &p) in positions.iter().enumerate() {
                    self.set_position(f, p.min(1000) as i16);
                }
                Response::PositionControl {
                    forces: self.hand.forces(),
                }
            }
            Request::ReadRegister { address, len } => {
                let mut bytes = [0u8; teleop_glove_protocol::MAX_DATA];
                let n = usize::from(len).min(bytes.len());
                for (i, b) in bytes.iter_mut().take(n).enumerate() {
                    *b = self.read_byte(address.checked_add(i as u16)?)?;
                }
                Response::ReadRegister {
                    address,
                    data: teleop_glove_protocol::Data::new(&bytes[..n]).ok()?,
                }
            }
            Request::WriteRegister { address, data } => Response::WriteRegister {
                address,
                status: if self.write(address, data.as_slice()) {
                    WRITE_ACCEPTED
                } else {
                    WRITE_REFUSED
                },
            },
        };
        Some(Frame { id: frame.id, body })
    }

    /// Applies an ID or baud change requested by the last write, once its acknowledge is out.
    /// Returns the new baud rate if it changed.
    pub fn after_answer(&mut self) -> Option<BaudRate> {
        if let Some(id) = self.pending_id.take() {
            self.id = id;
        }
        let baud = self.pending_baud.take()?;
        self.baud = baud;
        Some(baud)
    }

    fn set_force(&mut self, finger: usize, force: i16) {
        let force = force.clamp(-1000, 1000);
        self.force_set[finger] = force;
        self.hand.set_drive(finger, Drive::Force(f32::from(force)));
    }

    fn set_position(&mut self, finger: usize, position: i16) {
        self.position_set[finger] = position;
        if position >= 0 {
            self.hand
                .set_drive(finger, Drive::Position(f32::from(position)));
        }
    }

    /// The values a register holds now.
    fn values(&self, register: &Register) -> [i32; 6] {
        let five = |v: [i32; FINGERS]| [v[0], v[1], v[2], v[3], v[4], 0];
        match register.address {
            a if a == reg::ID.address => [i32::from(self.id), 0, 0, 0, 0, 0],
            a if a == reg::BAUD_RATE.address => [self.baud as i32, 0, 0, 0, 0, 0],
            a if a == reg::CALIBRATION.address => [i32::from(self.calibrating()), 0, 0, 0, 0, 0],
            // Nominal 8.4 V supply in tens of millivolts (the manual gives no unit).
            a if a == reg::VOLTAGE.address => [840, 0, 0, 0, 0, 0],
            a if a == reg::POSITION_SET.address => five(self.position_set.map(i32::from)),
            a if a == reg::FORCE_SET.address => five(self.force_set.map(i32::from)),
            a if a == reg::POSITION_ACTUAL.address => self.hand.positions().map(i32::from),
            a if a == reg::FORCE_ACTUAL.address => five(self.hand.forces().map(i32::from)),
            a if a == reg::CURRENT.address => five(self.hand.currents().map(i32::from)),
            a if a == reg::ERROR_CODE.address => five(self.hand.errors().map(i32::from)),
            a if a == reg::TEMPERATURE.address => five(self.hand.temperatures().map(i32::from)),
            // Command registers (error clearance, save, factory reset) read back 0.
            _ => [0; 6],
        }
    }

    fn read_byte(&self, address: u16) -> Option<u8> {
        let (register, offset) = register_containing(address)?;
        let values = self.values(register);
        Some(match register.width {
            Width::U8 => values[offset] as u8,
            Width::I16 | Width::U16 => {
                let v = (values[offset / 2] as u16).to_le_bytes();
                v[offset % 2]
            }
        })
    }

    /// Writes `data` at `address`: every byte must fall in a writable register, whole elements
    /// only, every value in range. All or nothing.
    fn write(&mut self, address: u16, data: &[u8]) -> bool {
        let mut writes: Vec<(&'static Register, usize, i32)> = Vec::new();
        let mut i = 0;
        while i < data.len() {
            let Some(addr) = address.checked_add(i as u16) else {
                return false;
            };
            let Some((register, offset)) = register_containing(addr) else {
                return false;
            };
            if register.access != teleop_glove_protocol::Access::ReadWrite {
                return false;
            }
            let (value, width) = match register.width {
                Width::U8 => (i32::from(data[i]), 1),
                Width::I16 | Width::U16 => {
                    if offset % 2 != 0 || i + 1 >= data.len() {
                        return false;
                    }
                    let raw = [data[i], data[i + 1]];
                    let v = if register.width == Width::I16 {
                        i32::from(i16::from_le_bytes(raw))
                    } else {
                        i32::from(u16::from_le_bytes(raw))
                    };
                    (v, 2)
                }
            };
            let in_range =
                (register.min..=register.max).contains(&value) || register.special == Some(value);
            if !in_range {
                return false;
            }
            writes.push((register, offset / width, value));
            i += width;
        }
        for (register, element, value) in writes {
            self.apply(register, element, value);
        }
        true
    }

    fn apply(&mut self, register: &Register, element: usize, value: i32) {
        match register.address {
            a if a == reg::ID.address => self.pending_id = Some(value as u8),
            a if a == reg::BAUD_RATE.address => {
                self.pending_baud = BaudRate::from_code(value as u8);
            }
            a if a == reg::ERROR_CLEAR.address && value == 1 => self.hand.clear_errors(),
            a if a == reg::SAVE.address && value == 1 => {
                // What is saved is what is in effect once pending changes apply.
                self.flash = Flash {
                    id: self.pending_id.unwrap_or(self.id),
                    baud: self.pending_baud.unwrap_or(self.baud),
                };
            }
            a if a == reg::FACTORY_RESET.address && value == 1 => {
                self.flash = Flash {
                    id: 1,
                    baud: BaudRate::B115200,
                };
                self.pending_id = Some(1);
                self.pending_baud = Some(BaudRate::B115200);
                for f in 0..FINGERS {
                    self.set_force(f, 0);
                    self.position_set[f] = -1;
                }
            }
            a if a == reg::CALIBRATION.address && value == 1 => {
                self.calibrating_until = Some(self.now + CALIBRATION_S);
            }
            a if a == reg::POSITION_SET.address => self.set_position(element, value as i16),
            a if a == reg::FORCE_SET.address => self.set_force(element, value as i16),
            _ => {}
        }
    }

    /// What a power cycle would restore: the saved id and baud rate.
    pub fn saved(&self) -> (u8, BaudRate) {
        (self.flash.id, self.flash.baud)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hand::{HandModel, Script};
    use teleop_glove_protocol::{read_request, write_request, Data};

    fn device() -> Device {
        Device::new(
            1,
            BaudRate::B115200,
            Hand::new(Script::Hold([500.0; 6]), HandModel::default()),
        )
    }

    fn ask(d: &mut Device, body: Request) -> Option<Response> {
        d.handle(&Frame { id: d.id(), body }).map(|f| f.body)
    }

    #[test]
    fn answers_only_its_own_id() {
        let mut d = device();
        let req = Frame {
            id: 2,
            body: Request::ForceControl { forces: [0; 5] },
        };
        assert!(d.handle(&req).is_none());
        assert!(ask(&mut d, Request::ForceControl { forces: [0; 5] }).is_some());
    }

    #[test]
    fn force_control_drives_the_actuators_and_answers_positions() {
        let mut d = device();
        let r = ask(
            &mut d,
            Request::ForceControl {
                forces: [0, 0, 0, 300, 0],
            },
        );
        assert_eq!(
            r,
            Some(Response::ForceControl {
                positions: [500; 6]
            })
        );
        d.advance_to(1.0);
        // 0.9 N against the operator's finger, stiffened to 290 N/m: 3.1 mm, 18 raw units.
        let p = d.hand().positions();
        assert!((515..=521).contains(&p[3]), "index pushed open: {p:?}");
        assert_eq!(d.hand().forces()[3], 300, "and the force felt");
        assert_eq!(d.force_set()[3], 300);
    }

    #[test]
    fn reads_follow_the_register_map() {
        let mut d = device();
        let Some(Response::ReadRegister { data, .. }) = ask(&mut d, read_request(&reg::ID)) else {
            panic!("no answer");
        };
        assert_eq!(data.as_slice(), &[1]);
        let Some(Response::ReadRegister { data, .. }) =
            ask(&mut d, read_request(&reg::POSITION_ACTUAL))
        else {
            panic!("no answer");
        };
        assert_eq!(data.len(), 12);
        assert_eq!(
            u16::from_le_bytes([data.as_slice()[0], data.as_slice()[1]]),
            500
        );
        // Outside the map: silence.
        assert!(ask(
            &mut d,
            Request::ReadRegister {
                address: 1100,
                len: 1
            }
        )
        .is_none());
        assert!(ask(
            &mut d,
            Request::ReadRegister {
                address: 1622,
                len: 2
            }
        )
        .is_none());
    }

    #[test]
    fn writes_to_read_only_or_out_of_range_are_refused() {
        let mut d = device();
        let refused = |r| {
            matches!(
                r,
                Some(Response::WriteRegister {
                    status: WRITE_REFUSED,
                    ..
                })
            )
        };
        let data = Data::new(&[1, 0]).unwrap();
        assert!(refused(ask(
            &mut d,
            Request::WriteRegister {
                address: reg::VOLTAGE.address,
                data
            }
        )));
        let data = Data::new(&[0]).unwrap();
        assert!(refused(ask(
            &mut d,
            Request::WriteRegister {
                address: reg::ID.address,
                data
            }
        )));
        let data = Data::new(&[9]).unwrap();
        assert!(refused(ask(
            &mut d,
            Request::WriteRegister {
                address: reg::BAUD_RATE.address,
                data
            }
        )));
    }

    #[test]
    fn id_and_baud_change_after_the_acknowledge_and_save_persists() {
        let mut d = device();
        let r = ask(&mut d, write_request(&reg::ID, &[7]).unwrap());
        assert!(matches!(
            r,
            Some(Response::WriteRegister {
                status: WRITE_ACCEPTED,
                ..
            })
        ));
        assert_eq!(d.id(), 1, "the acknowledge still comes from the old id");
        assert_eq!(d.after_answer(), None);
        assert_eq!(d.id(), 7);
        ask(&mut d, write_request(&reg::BAUD_RATE, &[2]).unwrap()).unwrap();
        assert_eq!(d.after_answer(), Some(BaudRate::B19200));
        assert_eq!(d.saved(), (1, BaudRate::B115200));
        ask(&mut d, write_request(&reg::SAVE, &[1]).unwrap()).unwrap();
        assert_eq!(d.saved(), (7, BaudRate::B19200));
        ask(&mut d, write_request(&reg::FACTORY_RESET, &[1]).unwrap()).unwrap();
        d.after_answer();
        assert_eq!((d.id(), d.baud()), (1, BaudRate::B115200));
    }

    #[test]
    fn position_set_points_with_leave_alone() {
        let mut d = device();
        ask(
            &mut d,
            write_request(&reg::POSITION_SET, &[100, -1, 100, 100, 100]).unwrap(),
        )
        .unwrap();
        d.advance_to(1.0);
        let p = d.hand().positions();
        assert!(p[0] < 110 && p[1] == 500, "{p:?}");
    }

    #[test]
    fn calibration_runs_for_the_manuals_duration() {
        let mut d = device();
        ask(&mut d, write_request(&reg::CALIBRATION, &[1]).unwrap()).unwrap();
        assert!(d.calibrating());
        d.advance_to(CALIBRATION_S - 0.1);
        assert!(d.calibrating());
        d.advance_to(CALIBRATION_S + 0.1);
        assert!(!d.calibrating());
    }
}
