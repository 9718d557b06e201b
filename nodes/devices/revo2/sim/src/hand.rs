//! The simulated Revo2 hand: six joints with speed limits and first-order dynamics, the five
//! control modes, motor current that follows the load, and an optional virtual object that the
//! closing fingers meet: the finger stops against it, current rises, the fingertip's normal and
//! tangential force grow with penetration, proximity rises on approach, and the tactile sensor's
//! update counter ticks at the sensor's own rate.
//!
//! Units inside the model are the device's percentage units: position 0 (open) .. 1000 (closed),
//! speed in position units per second, current in mA. Pure: time comes in as seconds.

use teleop_sim_kit::plant::{lag, Clock};

/// Longest integration step, s.
const STEP_S: f64 = 0.0005;

/// Joints in Revo2 order: thumb flex, thumb abduct, index, middle, ring, pinky.
pub const JOINTS: usize = 6;
/// Fingertips in tactile order: thumb, index, middle, ring, pinky.
pub const FINGERTIPS: usize = 5;
/// The joint that moves each fingertip.
pub const FINGERTIP_JOINT: [usize; FINGERTIPS] = [0, 2, 3, 4, 5];

/// Control modes (the device's `CTRL_MODE_*`).
pub mod mode {
    /// Position + time.
    pub const POSITION_TIME: u8 = 1;
    /// Position + speed.
    pub const POSITION_SPEED: u8 = 2;
    /// Speed.
    pub const SPEED: u8 = 3;
    /// Current.
    pub const CURRENT: u8 = 4;
    /// PWM duty cycle.
    pub const PWM: u8 = 5;
}

/// What a joint is told to do, in percentage units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drive {
    /// Hold the current position (power-on and safe state).
    Hold(f32),
    /// Go to a position at this speed (position units per second).
    Position {
        /// Target position.
        target: f32,
        /// Speed limit, position units per second.
        speed: f32,
    },
    /// Move at this signed speed.
    Speed(f32),
    /// Push with this signed current (mA): the finger moves until the load balances it.
    Current(f32),
    /// Drive the motor with this duty cycle (-1..1).
    Pwm(f32),
}

/// Physical constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandParams {
    /// Fastest joint motion, position units per second (full travel in 0.5 s).
    pub max_speed: f32,
    /// Time constant of the speed following its command, seconds.
    pub tau_s: f32,
    /// Idle motor current, mA.
    pub idle_ma: f32,
    /// Current per newton of fingertip force, mA.
    pub ma_per_n: f32,
    /// Largest motor current (the protection current), mA.
    pub max_ma: f32,
    /// Position controller stiffness, newtons per position unit of error.
    pub controller_n_per_unit: f32,
    /// Tactile sensor update period, seconds.
    pub sensor_period_s: f32,
}

impl Default for HandParams {
    fn default() -> Self {
        Self {
            max_speed: 2000.0,
            tau_s: 0.02,
            idle_ma: 60.0,
            ma_per_n: 60.0,
            max_ma: 1000.0,
            controller_n_per_unit: 0.03,
            sensor_period_s: 0.01,
        }
    }
}

/// Something in the hand that closing fingers touch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VirtualObject {
    /// Per joint, the position where the finger meets the surface (None: that finger misses it).
    pub contact_at: [Option<f32>; JOINTS],
    /// Surface stiffness, newtons per position unit of penetration.
    pub n_per_unit: f32,
    /// Tangential force as a share of the normal force (the object's weight pulling sideways).
    pub tangential_share: f32,
    /// Direction of the tangential force, degrees (0 = towards the fingertip, clockwise).
    pub tangential_direction_deg: u16,
    /// Proximity starts rising this many position units before contact.
    pub approach: f32,
}

impl VirtualObject {
    /// A ball of about a third of a fist, touched by every finger; the thumb's abduction is
    /// free.
    pub fn ball() -> Self {
        Self {
            contact_at: [
                Some(300.0),
                None,
                Some(330.0),
                Some(350.0),
                Some(370.0),
                Some(390.0),
            ],
            n_per_unit: 0.3,
            tangential_share: 0.25,
            tangential_direction_deg: 180,
            approach: 150.0,
        }
    }
}

/// Largest proximity value reported (raw sensor units).
pub const PROXIMITY_MAX: u32 = 100_000;

/// One fingertip's tactile reading.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Touch {
    /// Normal force, newtons.
    pub normal_n: f32,
    /// Tangential force, newtons.
    pub tangential_n: f32,
    /// Direction of the tangential force, degrees; None when there is none.
    pub direction_deg: Option<u16>,
    /// Proximity, raw units (larger = closer).
    pub proximity: u32,
}

/// The hand.
#[derive(Debug, Clone)]
pub struct Hand {
    params: HandParams,
    object: Option<VirtualObject>,
    position: [f32; JOINTS],
    speed: [f32; JOINTS],
    drive: [Drive; JOINTS],
    force: [f32; JOINTS],
    sensor: [Touch; FINGERTIPS],
    sensor_counter: u8,
    next_sensor_update: f32,
    clock: Clock,
}

impl Hand {
    /// An open hand holding still, with an optional object in it.
    pub fn new(params: HandParams, object: Option<VirtualObject>) -> Self {
        Self {
            params,
            object,
            position: [0.0; JOINTS],
            speed: [0.0; JOINTS],
            drive: [Drive::Hold(0.0); JOINTS],
            force: [0.0; JOINTS],
            sensor: [Touch::default(); FINGERTIPS],
            sensor_counter: 0,
            next_sensor_update: 0.0,
            clock: Clock::new(STEP_S),
        }
    }

    /// Places or removes the object.
    pub fn set_object(&mut self, object: Option<VirtualObject>) {
        self.object = object;
    }

    /// Applies a command to one joint: `mode` with its two parameters, already converted to
    /// percentage units (position 0..1000; speed and current as percentages of their maxima;
    /// PWM -1000..1000; time in ms). Unknown modes and out-of-range joints are ignored.
    pub fn command(&mut self, joint: usize, mode: u8, param1: f32, param2: f32) {
        let Some(drive) = self.drive.get_mut(joint) else {
            return;
        };
        let pos = self.position[joint];
        let max = self.params.max_speed;
        *drive = match mode {
            mode::POSITION_TIME => {
                let target = param1.clamp(0.0, 1000.0);
                let t = (param2 / 1000.0).max(0.001);
                Drive::Position {
                    target,
                    speed: ((target - pos).abs() / t).min(max),
                }
            }
            mode::POSITION_SPEED => Drive::Position {
                target: param1.clamp(0.0, 1000.0),
                speed: (param2.abs() / 1000.0 * max).min(max),
            },
            mode::SPEED => Drive::Speed(param1.clamp(-1000.0, 1000.0) / 1000.0 * max),
            mode::CURRENT => {
                Drive::Current(param1.clamp(-1000.0, 1000.0) / 1000.0 * self.params.max_ma)
            }
            mode::PWM => Drive::Pwm(param1.clamp(-1000.0, 1000.0) / 1000.0),
            _ => return,
        };
    }

    /// Every joint holds where it is (the safe state for a lost or stale command).
    pub fn hold(&mut self) {
        for (d, &p) in self.drive.iter_mut().zip(&self.position) {
            *d = Drive::Hold(p);
        }
    }

    /// The joints' drives.
    pub fn drives(&self) -> [Drive; JOINTS] {
        self.drive
    }

    /// Advances the model to time `t` seconds.
    pub fn advance_to(&mut self, t: f32) {
        let mut clock = self.clock;
        clock.advance_to(f64::from(t), |_, h| self.step(h as f32));
        self.clock = clock;
        let now = self.time();
        if now >= self.next_sensor_update {
            self.update_sensor();
            self.next_sensor_update = now + self.params.sensor_period_s;
        }
    }

    /// The model's time, s.
    fn time(&self) -> f32 {
        self.clock.time() as f32
    }

    fn step(&mut self, h: f32) {
        let p = self.params;
        for j in 0..JOINTS {
            let pos = self.position[j];
            let contact = self
                .object
                .and_then(|o| o.contact_at[j].map(|c| (c, o.n_per_unit)));
            // Wanted speed for this drive, and the push the motor can make.
            let (wanted, push_n) = match self.drive[j] {
                Drive::Hold(target) => (
                    ((target - pos) / p.tau_s).clamp(-p.max_speed, p.max_speed),
                    (target - pos) * p.controller_n_per_unit,
                ),
                Drive::Position { target, speed } => {
                    let v = ((target - pos) / p.tau_s).clamp(-speed, speed);
                    (v, (target - pos) * p.controller_n_per_unit)
                }
                Drive::Speed(v) => (v, v.signum() * p.max_ma / p.ma_per_n),
                Drive::Current(ma) => (ma.signum() * p.max_speed, ma / p.ma_per_n),
                Drive::Pwm(d) => (d * p.max_speed, d * p.max_ma / p.ma_per_n),
            };
            let max_push = (p.max_ma - p.idle_ma) / p.ma_per_n;
            let push_n = push_n.clamp(-max_push, max_push);
            self.speed[j] = lag(self.speed[j], wanted, h, p.tau_s);
            let mut next = (pos + self.speed[j] * h).clamp(0.0, 1000.0);
            self.force[j] = 0.0;
            if let Some((c, k)) = contact {
                if next > c {
                    // The finger presses into the surface until the surface pushes back as hard as
                    // the motor pushes.
                    let equilibrium = c + push_n.max(0.0) / k;
                    if next > equilibrium {
                        next = equilibrium.max(c).min(next.max(pos));
                        self.speed[j] = 0.0;
                    }
                    self.force[j] = (k * (next - c)).max(0.0);
                }
            }
            if next <= 0.0 || next >= 1000.0 {
                self.speed[j] = 0.0;
            }
            self.position[j] = next;
        }
    }

    fn update_sensor(&mut self) {
        self.sensor_counter = self.sensor_counter.wrapping_add(1);
        for (tip, &j) in FINGERTIP_JOINT.iter().enumerate() {
            let mut touch = Touch::default();
            if let Some((c, o)) = self.object.and_then(|o| o.contact_at[j].map(|c| (c, o))) {
                let gap = c - self.position[j];
                touch.proximity = if gap <= 0.0 {
                    PROXIMITY_MAX
                } else if gap < o.approach {
                    ((1.0 - gap / o.approach) * PROXIMITY_MAX as f32) as u32
                } else {
                    0
                };
                touch.normal_n = self.force[j];
                touch.tangential_n = self.force[j] * o.tangential_share;
                touch.direction_deg =
                    (touch.tangential_n > 0.05).then_some(o.tangential_direction_deg);
            }
            self.sensor[tip] = touch;
        }
    }

    /// Joint positions, 0 (open) .. 1000 (closed).
    pub fn positions(&self) -> [f32; JOINTS] {
        self.position
    }

    /// Joint speeds, position units per second.
    pub fn speeds(&self) -> [f32; JOINTS] {
        self.speed
    }

    /// Motor currents, mA (signed with the push).
    pub fn currents(&self) -> [f32; JOINTS] {
        core::array::from_fn(|j| {
            let load = self.force[j] * self.params.ma_per_n;
            let moving = self.speed[j].abs() / self.params.max_speed * 200.0;
            (self.params.idle_ma + load + moving).min(self.params.max_ma)
        })
    }

    /// The tactile sensor's last readings (updated every `sensor_period_s`).
    pub fn touches(&self) -> [Touch; FINGERTIPS] {
        self.sensor
    }

    /// The tactile sensor's update counter.
    pub fn sensor_counter(&self) -> u8 {
        self.sensor_counter
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(hand: &mut Hand, seconds: f32) {
        let start = hand.time();
        let mut t = start;
        while t < start + seconds {
            t += 0.001;
            hand.advance_to(t);
        }
    }

    #[test]
    fn position_speed_mode_moves_at_the_commanded_speed() {
        let mut h = Hand::new(HandParams::default(), None);
        h.command(2, mode::POSITION_SPEED, 1000.0, 500.0); // 50 % of max speed: 1000 units/s
        run(&mut h, 0.5);
        let p = h.positions()[2];
        assert!((400.0..600.0).contains(&p), "{p}");
        run(&mut h, 1.0);
        assert!((h.positions()[2] - 1000.0).abs() < 1.0);
        assert_eq!(h.positions()[3], 0.0, "other joints hold");
    }

    #[test]
    fn position_time_mode_arrives_in_the_given_time() {
        let mut h = Hand::new(HandParams::default(), None);
        h.command(0, mode::POSITION_TIME, 600.0, 300.0);
        run(&mut h, 0.15);
        assert!(
            (250.0..350.0).contains(&h.positions()[0]),
            "{}",
            h.positions()[0]
        );
        run(&mut h, 0.3);
        assert!((h.positions()[0] - 600.0).abs() < 2.0);
    }

    #[test]
    fn speed_current_and_pwm_modes_move_the_finger() {
        for (m, p1) in [
            (mode::SPEED, 300.0),
            (mode::CURRENT, 500.0),
            (mode::PWM, 400.0),
        ] {
            let mut h = Hand::new(HandParams::default(), None);
            h.command(4, m, p1, 0.0);
            run(&mut h, 0.2);
            assert!(h.positions()[4] > 50.0, "mode {m}: {}", h.positions()[4]);
            h.command(4, m, -p1, 0.0);
            run(&mut h, 1.0);
            assert_eq!(h.positions()[4], 0.0, "mode {m} opens again");
        }
    }

    #[test]
    fn closing_on_the_object_stops_the_finger_and_produces_force() {
        let mut h = Hand::new(HandParams::default(), Some(VirtualObject::ball()));
        for j in 0..JOINTS {
            h.command(j, mode::POSITION_SPEED, 700.0, 1000.0);
        }
        run(&mut h, 1.0);
        let p = h.positions();
        assert!(
            p[2] > 330.0 && p[2] < 600.0,
            "index stopped at the object: {p:?}"
        );
        assert!(p[1] > 690.0, "thumb abduction is free: {p:?}");
        let touch = h.touches();
        assert!(touch[1].normal_n > 2.0, "index fingertip force {touch:?}");
        assert!(touch[1].tangential_n > 0.0 && touch[1].direction_deg == Some(180));
        assert_eq!(touch[1].proximity, PROXIMITY_MAX);
        let cur = h.currents();
        assert!(
            cur[2] > cur[1] + 100.0,
            "loaded joint draws more current: {cur:?}"
        );
        // Squeezing harder presses further in.
        let before = h.touches()[1].normal_n;
        h.command(2, mode::CURRENT, 1000.0, 0.0);
        run(&mut h, 0.5);
        assert!(h.touches()[1].normal_n > before);
        assert!(h.currents()[2] <= 1000.0);
    }

    #[test]
    fn proximity_rises_on_approach_and_the_sensor_counter_ticks() {
        let mut h = Hand::new(HandParams::default(), Some(VirtualObject::ball()));
        let c0 = h.sensor_counter();
        h.command(2, mode::POSITION_SPEED, 250.0, 1000.0); // 80 short of contact
        run(&mut h, 1.0);
        let t = h.touches()[1];
        assert!(t.proximity > 0 && t.proximity < PROXIMITY_MAX, "{t:?}");
        assert_eq!(t.normal_n, 0.0);
        let ticks = h.sensor_counter().wrapping_sub(c0);
        assert!(
            (90..=110).contains(&ticks),
            "100 Hz sensor over 1 s: {ticks}"
        );
    }

    #[test]
    fn hold_keeps_the_position() {
        let mut h = Hand::new(HandParams::default(), None);
        h.command(3, mode::SPEED, 500.0, 0.0);
        run(&mut h, 0.2);
        h.hold();
        let p = h.positions()[3];
        run(&mut h, 1.0);
        assert!((h.positions()[3] - p).abs() < 25.0, "settles where it was");
    }
}

#[cfg(test)]
mod ramp_tests {
    use super::*;

    #[test]
    fn a_slow_close_also_stops_at_the_object() {
        let mut h = Hand::new(HandParams::default(), Some(VirtualObject::ball()));
        let mut t = 0.0;
        for i in 0..2000 {
            t += 0.001;
            let target = (i as f32 / 2000.0 * 490.0).min(490.0);
            h.command(0, mode::POSITION_SPEED, target, 1000.0);
            h.advance_to(t);
        }
        let p = h.positions()[0];
        assert!(p < 360.0, "thumb went through the object: {p}");
        assert!(h.touches()[0].normal_n > 1.0, "{:?}", h.touches()[0]);
    }
}
