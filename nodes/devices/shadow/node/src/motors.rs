//! What the statuses say about each motor: the latest value of every data type, its flags by
//! name, whether a serious flag stops its demand, whether it still answers, and whether it has
//! answered every slow type (the end of the start requests).
//!
//! A status answers the previous cycle's command and carries the replies of one parity of motors
//! (`which_motors`), each with its arrival and error bit. The error bit is read at bit `motor`,
//! where the firmware sets it; the shipped host reads bit `motor / 2`, a bug
//! (docs/devices/shadow.md, "One 1 kHz cycle") that this node does not copy. Replies are decoded by
//! the status's own type, as the shipped host does. Nothing here allocates per cycle.

use teleop_shadow_protocol::data::{flags, FromMotor, SlowData};
use teleop_shadow_protocol::layout::{Status, MOTORS};

/// One motor's latest values (raw units unless said).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Motor {
    /// Measured torque (raw).
    pub torque: i16,
    /// Left and right strain gauges.
    pub strain_gauges: [u16; 2],
    /// PWM.
    pub pwm: i16,
    /// Flags.
    pub flags: u16,
    /// Current, mA.
    pub current_ma: f64,
    /// Supply, V.
    pub voltage_v: f64,
    /// Temperature, deg C.
    pub temperature_c: f64,
    /// Slow data by type (index = slow type, 1..0x10).
    pub slow: [Option<u16>; 17],
    /// Time of the last reply, ms.
    pub last_reply_ms: Option<u64>,
    /// Replies received.
    pub replies: u64,
    /// Replies with the error bit (or of another type than asked).
    pub errors: u64,
}

impl Motor {
    /// Whether a serious flag stops this motor's demand.
    pub fn stopped(&self) -> bool {
        flags::serious(self.flags)
    }

    /// The motor firmware's serial number (slow data 4 and 5), once both halves came.
    pub fn serial(&self) -> Option<u32> {
        let lo = self.slow[SlowData::SerialLow as usize]?;
        let hi = self.slow[SlowData::SerialHigh as usize]?;
        Some(u32::from(hi) << 16 | u32::from(lo))
    }

    /// The motor firmware's SVN revision (slow data 1).
    pub fn revision(&self) -> Option<u16> {
        self.slow[SlowData::SvnRevision as usize]
    }
}

/// What one status changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Update {
    /// Bit n: motor n replied.
    pub replied: u32,
    /// Bit n: motor n's demand became stopped by a serious flag.
    pub newly_stopped: u32,
    /// Bit n: motor n's serious flags cleared.
    pub released: u32,
}

/// The 20 motors.
#[derive(Debug, Clone, Default)]
pub struct Motors {
    /// By motor number.
    pub motors: [Motor; MOTORS],
}

impl Motors {
    /// Takes one status received at `now_ms`. A status with EDC command 0 (nothing valid) or the
    /// boot status changes nothing.
    pub fn update(&mut self, status: &Status, now_ms: u64) -> Update {
        let mut update = Update::default();
        if status.edc_command != 1 {
            return update;
        }
        let kind = FromMotor::from_value(status.motor_data_type);
        let parity = usize::from(status.which_motors & 1 != 0);
        for n in (parity..MOTORS).step_by(2) {
            let bit = 1u32 << n;
            if status.which_motor_data_arrived & bit == 0 {
                continue;
            }
            let m = &mut self.motors[n];
            let Some(packet) = status.reply(n) else {
                m.errors += 1;
                continue;
            };
            let was_stopped = m.stopped();
            m.replies += 1;
            m.last_reply_ms = Some(now_ms);
            update.replied |= bit;
            let misc = packet.misc;
            match kind {
                Some(FromMotor::SlowMisc) => {
                    if let Some(slot) = m.slow.get_mut(packet.torque as u16 as usize) {
                        *slot = Some(misc);
                    }
                    continue;
                }
                Some(FromMotor::ReadbackLastConfig) => continue,
                _ => m.torque = packet.torque,
            }
            match kind {
                Some(FromMotor::StrainGaugeLeft) => m.strain_gauges[0] = misc,
                Some(FromMotor::StrainGaugeRight) => m.strain_gauges[1] = misc,
                Some(FromMotor::Pwm) => m.pwm = misc as i16,
                Some(FromMotor::Flags) => m.flags = misc,
                Some(k @ FromMotor::Current) => m.current_ma = k.scaled(misc),
                Some(k @ FromMotor::Voltage) => m.voltage_v = k.scaled(misc),
                Some(k @ FromMotor::Temperature) => m.temperature_c = k.scaled(misc),
                _ => {}
            }
            match (was_stopped, m.stopped()) {
                (false, true) => update.newly_stopped |= bit,
                (true, false) => update.released |= bit,
                _ => {}
            }
        }
        update
    }

    /// Bit n: motor n has not replied for `timeout_ms` (or never, once `timeout_ms` has passed
    /// since `since_ms`).
    pub fn silent(&self, now_ms: u64, since_ms: u64, timeout_ms: u64) -> u32 {
        let mut bits = 0;
        for (n, m) in self.motors.iter().enumerate() {
            let last = m.last_reply_ms.unwrap_or(since_ms);
            if now_ms.saturating_sub(last) > timeout_ms {
                bits |= 1 << n;
            }
        }
        bits
    }

    /// Whether every motor has answered every slow type (the start requests are done).
    pub fn started(&self) -> bool {
        self.motors
            .iter()
            .all(|m| SlowData::ALL.iter().all(|t| m.slow[*t as usize].is_some()))
    }

    /// The demand words to send: `demands`, with 0 for a motor whose demand is stopped.
    pub fn gate(&self, demands: &[i16; MOTORS]) -> [i16; MOTORS] {
        std::array::from_fn(|n| {
            if self.motors[n].stopped() {
                0
            } else {
                demands[n]
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use teleop_shadow_protocol::layout::MotorPacket;

    fn status(kind: FromMotor, which: i16, value: impl Fn(usize) -> (i16, u16)) -> Status {
        let mut s = Status {
            edc_command: 1,
            motor_data_type: kind as u32,
            which_motors: which,
            ..Status::default()
        };
        for n in (usize::from(which != 0)..MOTORS).step_by(2) {
            let (torque, misc) = value(n);
            s.packets[n / 2] = MotorPacket { torque, misc };
            s.which_motor_data_arrived |= 1 << n;
        }
        s
    }

    #[test]
    fn values_by_type_and_parity() {
        let mut m = Motors::default();
        let u = m.update(
            &status(FromMotor::Temperature, 1, |n| (n as i16, 0x2480)),
            5,
        );
        assert_eq!(u.replied, 0xAAAAA);
        assert_eq!(m.motors[3].temperature_c, 36.5);
        assert_eq!(m.motors[3].torque, 3);
        assert_eq!(
            m.motors[2].temperature_c, 0.0,
            "an even motor: not in this status"
        );
        // A reply with its error bit is counted, not used.
        let mut s = status(FromMotor::Current, 0, |_| (0, 500));
        s.which_motor_data_had_errors = 1 << 4;
        m.update(&s, 6);
        assert_eq!(m.motors[4].current_ma, 0.0);
        assert_eq!(m.motors[4].errors, 1);
        assert_eq!(m.motors[6].current_ma, 500.0);
        // Nothing valid, or the boot status: no change.
        let mut s = status(FromMotor::Current, 0, |_| (0, 900));
        s.edc_command = 0;
        assert_eq!(m.update(&s, 7), Update::default());
    }

    #[test]
    fn a_serious_flag_stops_that_motors_demand_and_is_reported_once() {
        let mut m = Motors::default();
        let over = |n: usize| (0, if n == 8 { flags::OVER_TEMPERATURE } else { 0 });
        let u = m.update(&status(FromMotor::Flags, 0, over), 1);
        assert_eq!(u.newly_stopped, 1 << 8);
        assert_eq!(flags::names(m.motors[8].flags), vec!["over temperature"]);
        let gated = m.gate(&[100; MOTORS]);
        assert_eq!(gated[8], 0);
        assert_eq!(gated[6], 100, "the others keep working");
        assert_eq!(
            m.update(&status(FromMotor::Flags, 0, over), 2)
                .newly_stopped,
            0
        );
        let u = m.update(&status(FromMotor::Flags, 0, |_| (0, 0)), 3);
        assert_eq!(u.released, 1 << 8);
    }

    #[test]
    fn slow_data_ends_the_start_and_gives_serials_and_a_silent_motor_is_found() {
        let mut m = Motors::default();
        assert!(!m.started());
        for t in SlowData::ALL {
            for which in [0, 1] {
                m.update(
                    &status(FromMotor::SlowMisc, which, |n| (t as i16, 0x100 + n as u16)),
                    10,
                );
            }
        }
        assert!(m.started());
        assert_eq!(m.motors[5].revision(), Some(0x105));
        assert_eq!(m.motors[5].serial(), Some(0x0105_0105));
        // Motor 7 stops answering.
        for t in 11..200 {
            let mut s = status(FromMotor::Flags, (t % 2) as i16, |_| (0, 0));
            s.which_motor_data_arrived &= !(1 << 7);
            m.update(&s, t);
        }
        assert_eq!(m.silent(200, 0, 50), 1 << 7);
    }
}
