//! The palm's PIC32 firmware, one EtherCAT cycle at a time (docs/devices/shadow.md, "One 1 kHz
//! cycle": E11 `this_node.c`), over the 20 motor boards on its two CAN buses.
//!
//! - Booting: until [`Palm::BOOT_MS`] the status is what the firmware writes on entering INIT
//!   (E11 `this_node.c`, `Platform_Init_Callback`): EDC_command 0xCC, then every 16-bit word
//!   from the struct's second on 0xDEAD, so EDC_command's upper half too: it reads 0xDEAD00CC.
//! - SENSOR_DATA: the motors of the command's parity (`which_motors`, 0 even, 1 odd) answer the
//!   requested type; each reply sets its packet (slot = motor / 2) and its arrival bit; a reply of
//!   another type sets both its arrival and error bits and is dropped; the error mask is
//!   cleared as the firmware does (`&= 0xFFFFFFFE << n`, which clears bits 0..n). The demands of
//!   `to_motor_data_type` go to every motor; `idle_time_us` is the time from the last status (or
//!   bridge status) write to this command (E11 `calculate_idle_time`), modulo 2^16 as the
//!   firmware's `int16u` result; the status is written [`SENSOR_DATA_ROUND`] after the command.
//! - CAN_DIRECT_MODE: a bridge message that was written goes on its bus; a reply that comes within
//!   [`CAN_DIRECT_ROUND`] is written to the bridge status only; the status is not refilled.
//! - Any other command: nothing is written (the firmware lights its error LED).
//!
//! A motor board here is its bootloader ([`crate::bootloader::Board`]) and, while that runs its
//! application, a first-order torque loop with strain gauges, current, temperature and flags. The
//! motor boards' own CAN payloads are not public, so the palm reads the motors directly.

use teleop_shadow_protocol::can::{bus_of_motor, BootMessage, APP_START};
use teleop_shadow_protocol::data::{
    flags, tactile, EdcCommand, EdcNumbering, FromMotor, SlowData, ToMotor, EDC_BOOTING,
};
use teleop_shadow_protocol::layout::{CanBridge, Command, MotorPacket, Status, MOTORS, TACTILE};
use teleop_shadow_protocol::mapping::Mapping;

use crate::bootloader::{Board, Mode};
use crate::hand::{Hand, VirtualObject};

/// One motor's application state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Motor {
    /// Torque demand in effect (raw units).
    pub demand: i16,
    /// Whether the demand is PWM (else torque).
    pub pwm_mode: bool,
    /// Measured torque (raw units), following the demand with a 5 ms time constant.
    pub torque: f64,
    /// Temperature, deg C.
    pub temperature: f64,
    /// Time of the last demand, ms (the 20 ms no-demand stop).
    pub last_demand_ms: Option<u64>,
    /// Replies sent.
    pub replies: u64,
    /// The slow data type the next SLOW_MISC reply carries (the motor picks: 1..0x10 in turn).
    pub slow_next: u16,
}

/// The SVN revision (slow data 1) a motor's application reports: in this emulator, the
/// little-endian word at the start of the application area (0x04C0) of its flash, so a
/// flashed image says which revision it is.
pub fn motor_revision(board: &Board) -> u16 {
    let at = APP_START as usize;
    match board.flash().get(at..at + 2) {
        Some(b) => u16::from_le_bytes([b[0], b[1]]),
        None => 0,
    }
}

/// The emulator's ADC wiring (the real one is not public): sensor word `sensor` comes from
/// ADC `1 + sensor / 4`, channel `(2 * (sensor % 4) + 6) % 8`, which puts LFJ5 (sensor 16) on
/// channel 6 of ADC 5 as the document's example has it. As SENSOR_CHANNEL_NUMBERS reports it:
/// channel in the high byte, ADC in the low byte ("LFJ5 : 0x0605").
pub fn wiring(sensor: usize) -> u16 {
    let adc = 1 + sensor / 4;
    let channel = (2 * (sensor % 4) + 6) % 8;
    (channel << 8 | adc) as u16
}

/// From the command to the status write in SENSOR_DATA mode. E11 `this_node.c`
/// (shadow-robot/sr-ros-interface-ethercat at f478de52, `Service_EtherCAT_Packet`): after the
/// start-of-frame message and the ADC reads it waits until frame time 562 us, then 617 us (the
/// BioTac sample), then for the motors' replies until 610 us (already past), sends the demands
/// and writes the status: at least 617 us after it saw the command.
pub const SENSOR_DATA_ROUND: std::time::Duration = std::time::Duration::from_micros(617);
/// From the command to the bridge status write in CAN direct mode (E11: waits until frame time
/// 600 us for a reply).
pub const CAN_DIRECT_ROUND: std::time::Duration = std::time::Duration::from_micros(600);

/// The boot status (E11 `Platform_Init_Callback`): EDC_command = 0xCC, then the 16-bit words
/// 1 .. size/2 of the struct set to 0xDEAD, word 1 being the upper half of EDC_command.
pub fn boot_status() -> Status {
    let mut b = [0u8; Status::SIZE];
    for w in b.chunks_exact_mut(2) {
        w.copy_from_slice(&0xDEADu16.to_le_bytes());
    }
    b[..2].copy_from_slice(&(EDC_BOOTING as u16).to_le_bytes());
    Status::unpack(&b).unwrap_or_default()
}

/// The firmware's cut-out temperature (release notes: 60 deg C).
pub const CUT_OUT_C: f64 = 60.0;

impl Motor {
    fn flags(&self, now_ms: u64) -> u16 {
        let mut f = 0;
        if self
            .last_demand_ms
            .is_none_or(|t| now_ms.saturating_sub(t) > 20)
        {
            f |= flags::NO_DEMAND_SEEN;
        }
        if self.temperature >= CUT_OUT_C {
            f |= flags::OVER_TEMPERATURE;
        }
        f
    }

    /// A slow data value of motor `n`: revisions, serial `0x5A00_0000 + n`, a build date, the
    /// gains, 5 kHz, coupled gauges.
    fn slow(n: usize, kind: SlowData, board: &Board) -> u16 {
        match kind {
            SlowData::SvnRevision | SlowData::ServerRevision => motor_revision(board),
            SlowData::Modified => 0,
            SlowData::SerialLow => n as u16,
            SlowData::SerialHigh => 0x5A00,
            SlowData::GearRatio => 131,
            SlowData::Year => 2011,
            SlowData::MonthDay => 0x0A1F,
            SlowData::Frequency => 5000,
            SlowData::GaugeType => 0x0C,
            _ => 0,
        }
    }

    fn value(&self, kind: FromMotor, now_ms: u64) -> u16 {
        match kind {
            FromMotor::StrainGaugeLeft => (2048.0 + self.torque / 16.0) as u16,
            FromMotor::StrainGaugeRight => (2048.0 - self.torque / 16.0) as u16,
            FromMotor::Pwm => (self.torque / 32.0) as i16 as u16,
            FromMotor::Flags => self.flags(now_ms),
            FromMotor::Current => (self.torque.abs() / 20.0) as u16,
            FromMotor::Voltage => 24 * 256,
            FromMotor::Temperature => (self.temperature * 256.0) as i16 as u16,
            FromMotor::CanRx | FromMotor::CanTx => self.replies as u16,
            _ => 0,
        }
    }

    fn step(&mut self, dt_ms: f64, now_ms: u64) {
        let serious = flags::serious(self.flags(now_ms));
        // A PWM demand (+-0x3FF) drives the motor as a torque demand 32 times as large would.
        let scale = if self.pwm_mode { 32.0 } else { 1.0 };
        let target = if serious {
            0.0
        } else {
            f64::from(self.demand) * scale
        };
        self.torque += (target - self.torque) * (dt_ms / 5.0).min(1.0);
        // Heating with torque, cooling toward 30 deg C (a 20 s time constant).
        let rise = (self.torque / 8000.0).powi(2) * 40.0;
        self.temperature += (30.0 + rise - self.temperature) * (dt_ms / 20_000.0).min(1.0);
    }
}

/// The palm and its motor boards.
#[derive(Debug, Clone)]
pub struct Palm {
    /// The motor boards (motor n: bus n / 10 + 1, id n % 10).
    pub boards: Vec<Board>,
    /// Their applications.
    pub motors: [Motor; MOTORS],
    /// EDC command numbering of this firmware.
    pub numbering: EdcNumbering,
    /// When the firmware last wrote a status or a bridge status, us since power-up (its idle
    /// timer's start).
    idle_since_us: Option<u64>,
    last_cycle_ms: Option<u64>,
    /// The joints the motors move, whose sensors the palm reads.
    pub hand: Hand,
}

impl Palm {
    /// Milliseconds the palm reports boot status after power-up.
    pub const BOOT_MS: u64 = 50;

    /// A palm whose 20 boards run an application (revision 2035), in a hand of the E v3 mapping with the
    /// ball under its middle finger.
    pub fn new() -> Self {
        Self::with_hand(Hand::new(Mapping::EV3, Some(VirtualObject::ball())))
    }

    /// A palm whose 20 boards run an application, in `hand`.
    pub fn with_hand(hand: Hand) -> Self {
        Self {
            boards: (0..MOTORS as u8)
                .map(|n| Board::new(n % 10, &2035u16.to_le_bytes()))
                .collect(),
            motors: [Motor {
                temperature: 30.0,
                ..Motor::default()
            }; MOTORS],
            numbering: EdcNumbering::Shipped,
            idle_since_us: None,
            last_cycle_ms: None,
            hand,
        }
    }

    /// One cycle at `now_ms`: the command and bridge message the host wrote, and the status and
    /// bridge message the palm writes back (`None`: not written this cycle).
    pub fn cycle(
        &mut self,
        command: &Command,
        bridge: Option<&CanBridge>,
        now_ms: u64,
    ) -> (Option<Status>, Option<CanBridge>) {
        self.cycle_us(command, bridge, now_ms * 1000)
    }

    /// One cycle whose command the firmware saw at `start_us` (us since power-up); what it
    /// writes is written [`SENSOR_DATA_ROUND`] (a status) or [`CAN_DIRECT_ROUND`] (a bridge
    /// status) later.
    pub fn cycle_us(
        &mut self,
        command: &Command,
        bridge: Option<&CanBridge>,
        start_us: u64,
    ) -> (Option<Status>, Option<CanBridge>) {
        let now_ms = start_us / 1000;
        let dt = self
            .last_cycle_ms
            .map_or(1.0, |t| now_ms.saturating_sub(t) as f64);
        self.last_cycle_ms = Some(now_ms);
        let mut torques = [0.0; MOTORS];
        for (n, m) in self.motors.iter_mut().enumerate() {
            if self.boards[n].mode() == Mode::Application {
                m.step(dt, now_ms);
                torques[n] = m.torque;
            }
        }
        self.hand.step(&torques, dt / 1000.0);
        if now_ms < Self::BOOT_MS {
            return (Some(boot_status()), None);
        }
        match EdcCommand::from_value(command.edc_command, self.numbering) {
            Some(EdcCommand::SensorData) => (Some(self.sensor_data(command, start_us)), None),
            Some(EdcCommand::SensorChannelNumbers) => {
                // As SENSOR_DATA, with each sensor word's ADC and channel instead of its value.
                let mut s = self.sensor_data(command, start_us);
                s.edc_command = command.edc_command;
                for (i, w) in s.sensors.iter_mut().enumerate() {
                    *w = wiring(i);
                }
                (Some(s), None)
            }
            Some(EdcCommand::CanDirectMode) => {
                let reply = self.bridge(bridge, now_ms);
                if reply.is_some() {
                    self.idle_since_us = Some(start_us + CAN_DIRECT_ROUND.as_micros() as u64);
                }
                (None, reply)
            }
            _ => (None, None),
        }
    }

    /// A reply forwarded later (see [`Palm::pending_reply`]) was written to the bridge status at
    /// `at_us`: the idle timer starts there, as after any bridge status write.
    pub fn bridge_status_written(&mut self, at_us: u64) {
        self.idle_since_us = Some(at_us);
    }

    fn sensor_data(&mut self, c: &Command, start_us: u64) -> Status {
        let now_ms = start_us / 1000;
        let parity = usize::from(c.which_motors & 1 != 0);
        let kind = FromMotor::from_value(c.from_motor_data_type);
        let mut s = Status {
            edc_command: 1,
            sensors: self.hand.sensors(),
            motor_data_type: c.from_motor_data_type,
            which_motors: c.which_motors & 1,
            ..Status::default()
        };
        for n in (parity..MOTORS).step_by(2) {
            if self.boards[n].mode() != Mode::Application || self.boards[n].silent {
                continue;
            }
            let m = &mut self.motors[n];
            m.replies += 1;
            match kind {
                Some(FromMotor::SlowMisc) => {
                    // The torque word says which slow type this is.
                    m.slow_next = m.slow_next % 0x10 + 1;
                    let slow = SlowData::from_value(m.slow_next).unwrap_or(SlowData::SvnRevision);
                    s.packets[n / 2] = MotorPacket {
                        torque: m.slow_next as i16,
                        misc: Motor::slow(n, slow, &self.boards[n]),
                    };
                    s.which_motor_data_arrived |= 1 << n;
                    s.which_motor_data_had_errors &= 0xFFFF_FFFEu32.wrapping_shl(n as u32);
                }
                Some(kind) => {
                    s.packets[n / 2] = MotorPacket {
                        torque: m.torque as i16,
                        misc: m.value(kind, now_ms),
                    };
                    s.which_motor_data_arrived |= 1 << n;
                    s.which_motor_data_had_errors &= 0xFFFF_FFFEu32.wrapping_shl(n as u32);
                }
                None => {
                    s.which_motor_data_arrived |= 1 << n;
                    s.which_motor_data_had_errors |= 1 << n;
                }
            }
        }
        if let Some(to) = ToMotor::from_value(c.to_motor_data_type) {
            for (n, m) in self.motors.iter_mut().enumerate() {
                match to {
                    ToMotor::TorqueDemand | ToMotor::PwmDemand => {
                        m.demand = c.motor_data[n];
                        m.pwm_mode = to == ToMotor::PwmDemand;
                        m.last_demand_ms = Some(now_ms);
                    }
                    _ => {}
                }
            }
        }
        if c.tactile_data_type == tactile::PST3 {
            // PST3: word 0 pressure, word 1 temperature (not emulated: 0).
            s.tactile_data_type = tactile::PST3;
            s.tactile_data_valid = (1 << TACTILE) - 1;
            for (words, pressure) in s.tactile.iter_mut().zip(self.hand.pst()) {
                words[0] = pressure;
            }
        }
        // E11 `calculate_idle_time`: core timer ticks from the last status write to this
        // command, in us, returned as `int16u` (so modulo 2^16). Before any write the timer's
        // start is 0: the time since power-up (assuming the core timer starts at 0 at reset).
        let since = self.idle_since_us.unwrap_or(0);
        s.idle_time_us = start_us.saturating_sub(since) as u16;
        self.idle_since_us = Some(start_us + SENSOR_DATA_ROUND.as_micros() as u64);
        s
    }

    fn bridge(&mut self, bridge: Option<&CanBridge>, now_ms: u64) -> Option<CanBridge> {
        let msg = bridge.filter(|b| !b.is_idle())?;
        let boot = BootMessage {
            id: msg.id,
            len: msg.length.min(8),
            data: msg.data,
        };
        let bus = msg.can_bus;
        let mut reply = None;
        for (n, board) in self.boards.iter_mut().enumerate() {
            if bus_of_motor(n as u8).map(|(b, _)| b) != Some(bus) {
                continue;
            }
            board.receive(&boot, now_ms);
            // The firmware waits up to 600 us: replies due by then come back this cycle.
            if let Some(r) = board.take_sent(now_ms).into_iter().next() {
                reply.get_or_insert(CanBridge {
                    can_bus: bus,
                    length: r.len,
                    id: r.id,
                    data: r.data,
                });
            }
        }
        reply
    }

    /// Replies that became due since (an ERASE's echo), as the palm forwards them in CAN direct
    /// mode on a later cycle with an idle bridge.
    pub fn pending_reply(&mut self, now_ms: u64) -> Option<CanBridge> {
        for (n, board) in self.boards.iter_mut().enumerate() {
            if let Some(r) = board.take_sent(now_ms).into_iter().next() {
                let (bus, _) = bus_of_motor(n as u8)?;
                return Some(CanBridge {
                    can_bus: bus,
                    length: r.len,
                    id: r.id,
                    data: r.data,
                });
            }
        }
        None
    }
}

impl Default for Palm {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn sensor_command(which: i16, from: FromMotor) -> Command {
        Command {
            edc_command: 1,
            from_motor_data_type: from as u32,
            which_motors: which,
            to_motor_data_type: ToMotor::TorqueDemand as u32,
            ..Command::default()
        }
    }

    #[test]
    fn boot_status_then_even_and_odd_motors_answer() {
        let mut palm = Palm::new();
        let (s, _) = palm.cycle(&sensor_command(0, FromMotor::Flags), None, 0);
        let s = s.unwrap();
        assert_eq!(s.edc_command, 0xDEAD_0000 | EDC_BOOTING);
        assert_eq!(s.sensors[0], 0xDEAD);
        let (s, _) = palm.cycle(&sensor_command(1, FromMotor::Temperature), None, 60);
        let s = s.unwrap();
        assert_eq!(s.which_motors, 1);
        assert_eq!(s.which_motor_data_arrived, 0xAAAAA, "the ten odd motors");
        assert_eq!(s.which_motor_data_had_errors, 0);
        assert_eq!(s.reply(3).unwrap().misc, 30 * 256, "30 deg C in 8.8");
        assert!(s.reply(2).is_none());
        let (s, _) = palm.cycle(&sensor_command(0, FromMotor::Flags), None, 61);
        let s = s.unwrap();
        assert_eq!(s.which_motor_data_arrived, 0x55555);
        assert_eq!(
            s.idle_time_us,
            1000 - SENSOR_DATA_ROUND.as_micros() as u16,
            "from the status write to the next command"
        );
    }

    #[test]
    fn torque_follows_the_demand_and_over_temperature_stops_the_motor() {
        let mut palm = Palm::new();
        let mut c = sensor_command(0, FromMotor::Flags);
        c.motor_data[4] = 4000;
        for t in 60..120 {
            palm.cycle(&c, None, t);
        }
        assert!((palm.motors[4].torque - 4000.0).abs() < 10.0);
        palm.motors[4].temperature = 61.0;
        let (s, _) = palm.cycle(&c, None, 120);
        let f = s.unwrap().reply(4).unwrap().misc;
        assert!(flags::serious(f), "{f:#x}");
        assert_eq!(flags::names(f), vec!["over temperature"]);
        for t in 121..200 {
            palm.cycle(&c, None, t);
        }
        assert!(palm.motors[4].torque.abs() < 10.0, "the motor stopped");
    }

    #[test]
    fn can_direct_mode_bridges_to_the_bootloader_and_writes_only_the_bridge_status() {
        let mut palm = Palm::new();
        let direct = Command::can_direct_mode(EdcNumbering::Shipped);
        // MAGIC to motor 13 (bus 2, id 3): its application restarts into the bootloader, which
        // announces itself.
        let magic = BootMessage::magic(3);
        let msg = CanBridge {
            can_bus: 2,
            length: magic.len,
            id: magic.id,
            data: magic.data,
        };
        let (status, reply) = palm.cycle(&direct, Some(&msg), 100);
        assert!(
            status.is_none(),
            "the status is not refilled in CAN direct mode"
        );
        let reply = reply.unwrap();
        assert_eq!((reply.can_bus, reply.id), (2, 0x600 | 3 << 5 | 0x1A));
        assert_eq!(palm.boards[13].mode(), Mode::Bootloader);
        assert_eq!(
            palm.boards[3].mode(),
            Mode::Application,
            "bus 1's id 3 untouched"
        );
        // The document's numbering (CAN_TEST_MODE = 5) is not this firmware's: nothing written.
        let doc = Command {
            edc_command: 5,
            ..Command::default()
        };
        assert_eq!(palm.cycle(&doc, Some(&msg), 101), (None, None));
    }
}
