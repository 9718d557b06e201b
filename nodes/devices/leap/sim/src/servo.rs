//! One Dynamixel XC330 servo's firmware: its control table ([`crate::table`]), the instructions
//! addressed to it, its control loop per operating mode, hardware errors with their shutdown,
//! and reboot. Pure: time comes in as seconds.
//!
//! Behaviour (ROBOTIS e-manual, Protocol 2.0 and XC330-M288;
//! `docs/devices/leap.md, "XC330 control table"`):
//! - Ping is answered whatever the Status Return Level; Read (and the sync reads) from level 1;
//!   every other instruction only at level 2 (the default); a broadcast instruction is carried
//!   out without a status (Read not at all);
//! - every status carries the Alert bit (0x80) while Hardware Error Status is not 0;
//! - a hardware error that Shutdown (63) masks switches the torque off and keeps it off (a Write
//!   of Torque Enable = 1 is answered, with Alert, and changes nothing) until a Reboot or a
//!   power cycle;
//! - Reboot is answered, then the servo is silent for its boot time ([`ServoOptions::boot`]),
//!   and comes back with its RAM items at their initial values, no hardware error and Present
//!   Position within one turn; a power cycle is the same without the answer;
//! - Operating Mode changes reset every gain to its initial value (the documents give no
//!   per-mode defaults: `docs/devices/leap.md, "Unknown"`), Profile Velocity and
//!   Acceleration to 0 and Goal PWM and Goal Current to PWM Limit and Current Limit;
//! - Torque Enable 0 -> 1 sets Goal Position to Present Position (the servo holds where it is
//!   until told otherwise);
//! - the control loop: in modes 3, 4 and 5 a position PID (`P/128`, `I/65536`, `D/16` as the
//!   e-manual scales the gains) whose output is taken as a desired current in mA, clipped by
//!   Goal Current and Current Limit in mode 5 and by Current Limit in modes 3 and 4; mode 1 a
//!   velocity PI likewise; mode 0 Goal Current; mode 16 Goal PWM as that share of Current
//!   Limit. The current follows its target with a 0.5 ms lag and turns the joint at
//!   [`TORQUE_PER_AMP`];
//! - Present Temperature rises with the square of the current; above Temperature Limit the
//!   Overheating bit is set.

use std::f64::consts::PI;

use teleop_leap_protocol::packet::ErrorNumber;
use teleop_leap_protocol::xc330;
use teleop_sim_kit::plant::lag;

use crate::table::{LimitError, Model, Table, TABLE_LEN};

/// Counts per turn of the output shaft.
pub const COUNTS_PER_TURN: f64 = 4096.0;
/// Present Position at the URDF's 0 rad (the hand flat: 180 degrees).
pub const ZERO_COUNTS: f64 = 2048.0;
/// Output torque per ampere, N m/A: the XC330-M288's stall torque over its stall current
/// (0.93 N m at 1.8 A, 5 V, as quoted in LEAP_Hand_API issue #7;
/// `docs/devices/leap.md, "Open (unverified)"`).
pub const TORQUE_PER_AMP: f64 = 0.93 / 1.8;
/// Present Input Voltage, 0.1 V (the LEAP Hand's 5 V supply).
pub const INPUT_VOLTAGE: i64 = 50;
/// Temperature without current, deg C.
pub const AMBIENT_C: f64 = 30.0;
/// Steady-state temperature rise per A^2 of current, deg C.
pub const HEAT_C_PER_A2: f64 = 15.0;
/// Thermal time constant, s.
pub const THERMAL_TAU_S: f64 = 60.0;
/// Time constant of the current loop, s.
const CURRENT_TAU_S: f64 = 0.000_5;
/// Position error within which Moving Status says "in position", counts.
const IN_POSITION: f64 = 20.0;

/// What the firmware does where the documents leave it open, and its timing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoOptions {
    /// Boot time after a Reboot or a power cycle, s (silent meanwhile).
    pub boot: f64,
    /// Firmware Version (6).
    pub firmware: u8,
    /// Which error a goal beyond its limit item gets.
    pub limit_error: LimitError,
}

impl Default for ServoOptions {
    fn default() -> Self {
        Self {
            boot: 0.3,
            firmware: 52,
            limit_error: LimitError::Limit,
        }
    }
}

/// One servo.
#[derive(Debug, Clone)]
pub struct Servo {
    table: Table,
    options: ServoOptions,
    /// Silent until this time (booting), s.
    boot_until: f64,
    /// The position PID's integral, count ms.
    integral: f64,
    /// The velocity PI's integral, unit ms.
    velocity_integral: f64,
    /// The current flowing, mA.
    current: f64,
    /// Its temperature, deg C.
    temperature: f64,
    /// A registered write (Reg Write) waiting for Action: its address and bytes.
    registered: Option<(u16, usize, [u8; TABLE_LEN])>,
    /// The table stored by Control Table Backup.
    backup: Option<Table>,
    /// The joint's position the control loop saw last, counts (without Homing Offset).
    position: f64,
    /// Its velocity, 0.229 rpm units.
    velocity: f64,
    /// The control loop's last time, s.
    time: f64,
}

/// The error byte's error number.
fn number(e: ErrorNumber) -> u8 {
    e.code()
}

impl Servo {
    /// A servo of `model` as it leaves the LEAP Hand's assembly: ID `id`, Baud Rate code
    /// `baud`, Return Delay Time `return_delay` (2 us units), the rest at the factory's values.
    pub fn new(model: Model, id: u8, baud: u8, return_delay: u8, options: ServoOptions) -> Self {
        let mut table = Table::new(model, options.firmware);
        table.put(xc330::ID, i64::from(id));
        table.put(xc330::BAUD_RATE, i64::from(baud));
        table.put(xc330::RETURN_DELAY_TIME, i64::from(return_delay));
        let mut s = Self {
            table,
            options,
            boot_until: 0.0,
            integral: 0.0,
            velocity_integral: 0.0,
            current: 0.0,
            temperature: AMBIENT_C,
            registered: None,
            backup: None,
            position: ZERO_COUNTS,
            velocity: 0.0,
            time: 0.0,
        };
        s.publish();
        s
    }

    /// Firmware Version: Fast Sync Read needs 46 or later (ROBOTIS e-manual, Protocol 2.0,
    /// "Fast Sync Read").
    pub fn firmware(&self) -> u8 {
        self.options.firmware
    }

    /// The control table.
    pub fn table(&self) -> &Table {
        &self.table
    }

    /// Its ID.
    pub fn id(&self) -> u8 {
        self.table.get(xc330::ID) as u8
    }

    /// Its Baud Rate code.
    pub fn baud_code(&self) -> u8 {
        self.table.get(xc330::BAUD_RATE) as u8
    }

    /// Its Return Delay Time, s.
    pub fn return_delay(&self) -> f64 {
        self.table.get(xc330::RETURN_DELAY_TIME) as f64 * 2e-6
    }

    /// Its Status Return Level.
    pub fn status_return_level(&self) -> i64 {
        self.table.get(xc330::STATUS_RETURN_LEVEL)
    }

    /// Booting at `now` (silent).
    pub fn booting(&self, now: f64) -> bool {
        now < self.boot_until
    }

    /// Torque Enable.
    pub fn torque_on(&self) -> bool {
        self.table.get(xc330::TORQUE_ENABLE) != 0
    }

    /// Hardware Error Status.
    pub fn hardware_error(&self) -> u8 {
        self.table.get(xc330::HARDWARE_ERROR_STATUS) as u8
    }

    /// Present Current, mA.
    pub fn current_ma(&self) -> f64 {
        self.current
    }

    /// Temperature, deg C.
    pub fn temperature(&self) -> f64 {
        self.temperature
    }

    /// Sets its temperature (a fault: `overheat`).
    pub fn heat(&mut self, celsius: f64) {
        self.temperature = celsius;
    }

    /// Sets hardware error bits (a fault: `overload`); a masked one shuts the torque off.
    pub fn raise(&mut self, bits: u8) {
        let e = self.hardware_error() | bits;
        self.table.put(xc330::HARDWARE_ERROR_STATUS, i64::from(e));
        self.shutdown_check();
    }

    fn shutdown_check(&mut self) {
        if i64::from(self.hardware_error()) & self.table.get(xc330::SHUTDOWN) != 0 {
            self.table.put(xc330::TORQUE_ENABLE, 0);
        }
    }

    /// The error byte of a status with error number `n` (0: none): the Alert bit while a
    /// hardware error is set.
    fn error_byte(&self, n: u8) -> u8 {
        let alert = if self.hardware_error() != 0 { 0x80 } else { 0 };
        alert | n
    }

    /// Restarts: silent until `now` + the boot time, then RAM at its initial values, no
    /// hardware error, torque off, Present Position within one turn.
    pub fn reboot(&mut self, now: f64) {
        self.boot_until = now + self.options.boot;
        self.table.reset_ram();
        self.integral = 0.0;
        self.velocity_integral = 0.0;
        self.current = 0.0;
        self.registered = None;
        self.velocity = 0.0;
        self.publish();
    }

    /// Reboot as an instruction: the error byte of its status (sent before the restart), then
    /// the restart.
    pub fn reboot_answer(&mut self, now: f64) -> u8 {
        let error = self.error_byte(0);
        self.reboot(now);
        error
    }

    /// Ping's status: its error byte and parameters (model number, firmware version) in
    /// `out`, and how many.
    pub fn ping(&self, out: &mut [u8]) -> (u8, usize) {
        let model = self.table.get(xc330::MODEL_NUMBER) as u16;
        let [lo, hi] = model.to_le_bytes();
        out[..3].copy_from_slice(&[lo, hi, self.options.firmware]);
        (self.error_byte(0), 3)
    }

    /// A Read (or a sync read's part): the data into `out`, or the error number.
    pub fn read(&self, addr: u16, len: u16, out: &mut [u8]) -> (u8, usize) {
        match self.table.read(addr, len) {
            Ok(data) if data.len() <= out.len() => {
                out[..data.len()].copy_from_slice(data);
                (self.error_byte(0), data.len())
            }
            Ok(_) => (self.error_byte(number(ErrorNumber::DataLength)), 0),
            Err(e) => (self.error_byte(number(e)), 0),
        }
    }

    /// A Write (also a Sync Write's part and Action's registered write): checked whole, then
    /// applied with its side effects. The error byte of its status.
    pub fn write(&mut self, addr: u16, data: &[u8]) -> u8 {
        if let Err(e) = self.table.check_write(addr, data, self.options.limit_error) {
            return self.error_byte(number(e));
        }
        let torque_was = self.torque_on();
        let mode_was = self.table.get(xc330::OPERATING_MODE);
        self.table.write(addr, data);
        let mode = self.table.get(xc330::OPERATING_MODE);
        if mode != mode_was {
            self.mode_changed();
        }
        if self.torque_on() && !torque_was {
            self.shutdown_check();
            if self.torque_on() {
                self.integral = 0.0;
                self.velocity_integral = 0.0;
                let p = self.table.get(xc330::PRESENT_POSITION);
                self.table.put(xc330::GOAL_POSITION, p);
            }
        }
        self.error_byte(0)
    }

    fn mode_changed(&mut self) {
        let items = self.table.items();
        for addr in [
            xc330::VELOCITY_I_GAIN,
            xc330::VELOCITY_P_GAIN,
            xc330::POSITION_D_GAIN,
            xc330::POSITION_I_GAIN,
            xc330::POSITION_P_GAIN,
            xc330::FEEDFORWARD_2ND_GAIN,
            xc330::FEEDFORWARD_1ST_GAIN,
        ] {
            if let Some(v) = items.item_at(addr).and_then(|i| i.init) {
                self.table.put(addr, i64::from(v));
            }
        }
        self.table.put(xc330::PROFILE_VELOCITY, 0);
        self.table.put(xc330::PROFILE_ACCELERATION, 0);
        let pwm = self.table.get(xc330::PWM_LIMIT);
        self.table.put(xc330::GOAL_PWM, pwm);
        let current = self.table.get(xc330::CURRENT_LIMIT);
        self.table.put(xc330::GOAL_CURRENT, current);
    }

    /// Reg Write: checked now, kept for Action; Registered Instruction = 1.
    pub fn reg_write(&mut self, addr: u16, data: &[u8]) -> u8 {
        if let Err(e) = self.table.check_write(addr, data, self.options.limit_error) {
            return self.error_byte(number(e));
        }
        let mut bytes = [0u8; TABLE_LEN];
        let n = data.len().min(TABLE_LEN);
        bytes[..n].copy_from_slice(&data[..n]);
        self.registered = Some((addr, n, bytes));
        self.table.put(xc330::REGISTERED_INSTRUCTION, 1);
        self.error_byte(0)
    }

    /// Action: the registered write, or Instruction Error without one.
    pub fn action(&mut self) -> u8 {
        match self.registered.take() {
            None => self.error_byte(number(ErrorNumber::Instruction)),
            Some((addr, n, bytes)) => {
                self.table.put(xc330::REGISTERED_INSTRUCTION, 0);
                self.write(addr, &bytes[..n])
            }
        }
    }

    /// Factory Reset with its parameter (0xFF all, 0x01 all but ID, 0x02 all but ID and baud
    /// rate): the error byte (Data Range Error for another parameter). The servo reboots
    /// after answering.
    pub fn factory_reset(&mut self, what: u8, now: f64) -> u8 {
        let keep: &[u16] = match what {
            0xFF => &[],
            0x01 => &[xc330::ID],
            0x02 => &[xc330::ID, xc330::BAUD_RATE],
            _ => return self.error_byte(number(ErrorNumber::DataRange)),
        };
        let error = self.error_byte(0);
        self.table.factory_reset(keep);
        self.reboot(now);
        error
    }

    /// Clear (multi-turn position back within one turn; the LEAP's joint limits keep every
    /// servo within one turn, so there is nothing to take off): Result Fail while moving.
    pub fn clear_turns(&self) -> u8 {
        if self.table.get(xc330::MOVING) != 0 {
            return self.error_byte(number(ErrorNumber::ResultFail));
        }
        self.error_byte(0)
    }

    /// Control Table Backup: 0x01 stores the table, 0x02 restores the stored one; Result Fail
    /// while the torque is on, or restoring without a backup; Data Range Error for another
    /// option.
    pub fn backup(&mut self, option: u8) -> u8 {
        if self.torque_on() {
            return self.error_byte(number(ErrorNumber::ResultFail));
        }
        match (option, &self.backup) {
            (0x01, _) => self.backup = Some(self.table.clone()),
            (0x02, Some(stored)) => self.table = stored.clone(),
            (0x02, None) => return self.error_byte(number(ErrorNumber::ResultFail)),
            _ => return self.error_byte(number(ErrorNumber::DataRange)),
        }
        self.error_byte(0)
    }

    /// An instruction's parameters it does not take (a wrong option or key): Data Range Error.
    pub fn unknown_parameter(&self) -> u8 {
        self.error_byte(number(ErrorNumber::DataRange))
    }

    /// An instruction it does not know: Instruction Error.
    pub fn unknown(&self) -> u8 {
        self.error_byte(number(ErrorNumber::Instruction))
    }

    /// One control step of `h` s at `now` with its joint at `q` rad (URDF) moving at `qd`
    /// rad/s: returns the torque on the joint, N m. The present values reach the table at
    /// [`Servo::publish`].
    pub fn drive(&mut self, q: f64, qd: f64, h: f64, now: f64) -> f64 {
        let position = (q + PI) * COUNTS_PER_TURN / (2.0 * PI);
        let velocity_counts_per_ms = qd * COUNTS_PER_TURN / (2.0 * PI) / 1000.0;
        let velocity_units = qd * 60.0 / (2.0 * PI) / xc330::RPM_PER_VELOCITY_UNIT;
        (self.position, self.velocity, self.time) = (position, velocity_units, now);
        if self.temperature > self.table.get(xc330::TEMPERATURE_LIMIT) as f64 {
            self.raise(xc330::HardwareError::OVERHEATING);
        }
        let target = if self.booting(now) || !self.torque_on() {
            0.0
        } else {
            self.desired_current(position, velocity_counts_per_ms, velocity_units, h)
        };
        self.current = lag(self.current, target, h, CURRENT_TAU_S);
        let amps = self.current / 1000.0;
        let rise = HEAT_C_PER_A2 * amps * amps;
        self.temperature = lag(self.temperature, AMBIENT_C + rise, h, THERMAL_TAU_S);
        TORQUE_PER_AMP * amps
    }

    fn homing(&self) -> f64 {
        self.table.get(xc330::HOMING_OFFSET) as f64
    }

    fn desired_current(&mut self, position: f64, vel_ms: f64, vel_units: f64, h: f64) -> f64 {
        let t = &self.table;
        let limit = t.get(xc330::CURRENT_LIMIT) as f64;
        let h_ms = h * 1000.0;
        let u = match t.get(xc330::OPERATING_MODE) {
            0 => t.get(xc330::GOAL_CURRENT) as f64,
            1 => {
                let e = t.get(xc330::GOAL_VELOCITY) as f64 - vel_units;
                self.velocity_integral += e * h_ms;
                t.get(xc330::VELOCITY_P_GAIN) as f64 / 128.0 * e
                    + t.get(xc330::VELOCITY_I_GAIN) as f64 / 65536.0 * self.velocity_integral
            }
            16 => t.get(xc330::GOAL_PWM) as f64 / 885.0 * limit,
            mode => {
                let e = t.get(xc330::GOAL_POSITION) as f64 - (position + self.homing());
                self.integral += e * h_ms;
                let t = &self.table;
                let u = t.get(xc330::POSITION_P_GAIN) as f64 / 128.0 * e
                    + t.get(xc330::POSITION_I_GAIN) as f64 / 65536.0 * self.integral
                    - t.get(xc330::POSITION_D_GAIN) as f64 / 16.0 * vel_ms;
                if mode == 5 {
                    let goal = (t.get(xc330::GOAL_CURRENT) as f64).abs();
                    u.clamp(-goal, goal)
                } else {
                    u
                }
            }
        };
        u.clamp(-limit, limit)
    }

    /// Writes the present values the control loop saw last into the table.
    pub fn publish(&mut self) {
        let position = self.position + self.homing();
        let (velocity_units, now) = (self.velocity, self.time);
        let t = &mut self.table;
        t.put(xc330::PRESENT_POSITION, position.round() as i64);
        t.put(xc330::PRESENT_VELOCITY, velocity_units.round() as i64);
        t.put(xc330::PRESENT_CURRENT, self.current.round() as i64);
        let limit = t.get(xc330::CURRENT_LIMIT).max(1) as f64;
        t.put(
            xc330::PRESENT_PWM,
            (self.current / limit * 885.0).round() as i64,
        );
        t.put(xc330::PRESENT_INPUT_VOLTAGE, INPUT_VOLTAGE);
        t.put(
            xc330::PRESENT_TEMPERATURE,
            self.temperature.round().clamp(0.0, 255.0) as i64,
        );
        t.put(xc330::REALTIME_TICK, ((now * 1000.0) as i64) % 32768);
        let threshold = t.get(xc330::MOVING_THRESHOLD);
        let moving = velocity_units.abs() > threshold as f64;
        t.put(xc330::MOVING, i64::from(moving));
        let error = t.get(xc330::GOAL_POSITION) as f64 - position;
        t.put(xc330::MOVING_STATUS, i64::from(error.abs() <= IN_POSITION));
    }
}
