//! The simulated Revo2 hand: six joints with speed limits and first-order dynamics, the five
//! control modes, motor current that follows the load, and an optional object that the closing
//! fingers meet: the finger stops against it, current rises, the fingertip's normal and
//! tangential force grow with penetration, proximity rises on approach, and the tactile sensor's
//! update counter ticks at the sensor's own rate.
//!
//! Two models of the object ([`ObjectModel`]): a shape placed in the hand that the fingertip
//! pads touch where the hand profile's kinematics put them ([`ShapeObject`], see
//! [`crate::contact`]), and the older joint-space model that stops each finger at a fixed
//! position whatever the pose ([`VirtualObject`]), kept so that tests can pin its numbers.
//!
//! Units inside the model are the device's percentage units: position 0 (open) .. 1000 (closed),
//! speed in position units per second, current in mA. Pure: time comes in as seconds.

use teleop_sim_kit::plant::{lag, Clock};

use crate::contact::{ContactState, Pads};
pub use crate::contact::{Shape, ShapeObject};

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

/// Something in the hand that closing fingers touch, in joint space: each finger stops at a
/// fixed position whatever the pose of the others.
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

    /// Where joint `j` comes to rest when the surface stops it: the motor (pushing with `push_n`
    /// newtons, positive closing) would take it from `pos` to `next`; the finger presses into
    /// the surface until the surface pushes back as hard as the motor pushes. `None` when the
    /// surface does not hold it back.
    fn settle(&self, j: usize, pos: f32, next: f32, push_n: f32) -> Option<f32> {
        let c = self.contact_at[j].filter(|&c| next > c)?;
        let equilibrium = c + push_n.max(0.0) / self.n_per_unit;
        (next > equilibrium).then(|| equilibrium.max(c).min(next.max(pos)))
    }

    /// The surface's force on joint `j`'s finger at `position`, newtons.
    fn force(&self, j: usize, position: f32) -> f32 {
        self.contact_at[j].map_or(0.0, |c| (self.n_per_unit * (position - c)).max(0.0))
    }

    /// How close joint `j`'s finger at `position` is to the surface: 0 (far, or a finger that
    /// misses it) .. 1 (touching).
    fn nearness(&self, j: usize, position: f32) -> f32 {
        self.contact_at[j].map_or(0.0, |c| nearness(c - position, self.approach))
    }
}

/// The object in the hand and how it touches the fingers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ObjectModel {
    /// Each finger stops at a fixed position (the older model, for tests that pin its numbers).
    Joint(VirtualObject),
    /// A shape that the fingertip pads touch where the kinematics put them.
    Shape(ShapeObject),
}

impl ObjectModel {
    /// The tangential force's share of the normal force, and its direction in degrees.
    fn tangential(&self) -> (f32, u16) {
        match self {
            Self::Joint(o) => (o.tangential_share, o.tangential_direction_deg),
            Self::Shape(o) => (o.tangential_share, o.tangential_direction_deg),
        }
    }
}

/// 0 (at least `approach` away) .. 1 (touching) for a `gap` to the surface.
pub(crate) fn nearness(gap: f32, approach: f32) -> f32 {
    if gap <= 0.0 {
        1.0
    } else if gap < approach {
        1.0 - gap / approach
    } else {
        0.0
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
    object: Option<ObjectModel>,
    /// The fingertip pads where the hand profile puts them (`None` only if the builtin profile
    /// does not fit the simulator, logged once: shape objects are then out of reach).
    pads: Option<Pads>,
    position: [f32; JOINTS],
    speed: [f32; JOINTS],
    drive: [Drive; JOINTS],
    /// Per joint, how hard the object resists it, newtons at the fingertip.
    load: [f32; JOINTS],
    /// Per fingertip, the object's normal force on it, newtons.
    normal: [f32; FINGERTIPS],
    /// Per fingertip, how close it is to the object (0 far .. 1 touching).
    nearness: [f32; FINGERTIPS],
    sensor: [Touch; FINGERTIPS],
    sensor_counter: u8,
    next_sensor_update: f32,
    clock: Clock,
}

impl Hand {
    /// An open hand holding still, with an optional object in it.
    pub fn new(params: HandParams, object: Option<ObjectModel>) -> Self {
        let pads = Pads::revo2()
            .map_err(|e| tracing::error!("{e}: shape objects will not touch the fingers"))
            .ok();
        Self {
            params,
            object,
            pads,
            position: [0.0; JOINTS],
            speed: [0.0; JOINTS],
            drive: [Drive::Hold(0.0); JOINTS],
            load: [0.0; JOINTS],
            normal: [0.0; FINGERTIPS],
            nearness: [0.0; FINGERTIPS],
            sensor: [Touch::default(); FINGERTIPS],
            sensor_counter: 0,
            next_sensor_update: 0.0,
            clock: Clock::new(STEP_S),
        }
    }

    /// Places or removes the object.
    pub fn set_object(&mut self, object: Option<ObjectModel>) {
        self.object = object;
        if let Some(pads) = &mut self.pads {
            pads.clear();
        }
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
            let stop = match (&self.object, &self.pads) {
                (Some(ObjectModel::Joint(o)), _) => o.settle(j, pos, next, push_n),
                (Some(ObjectModel::Shape(o)), Some(pads)) => {
                    pads.settle(o, &self.position, j, next, push_n, h)
                }
                _ => None,
            };
            if let Some(stop) = stop {
                next = stop;
                self.speed[j] = 0.0;
            }
            if next <= 0.0 || next >= 1000.0 {
                self.speed[j] = 0.0;
            }
            self.position[j] = next;
        }
        self.update_contacts(h);
    }

    /// The object's forces and nearness at the joints' positions.
    fn update_contacts(&mut self, h: f32) {
        let pos = self.position;
        let contacts = match (&self.object, &mut self.pads) {
            (Some(ObjectModel::Joint(o)), _) => {
                let load_n = core::array::from_fn(|j| o.force(j, pos[j]));
                ContactState {
                    load_n,
                    normal_n: FINGERTIP_JOINT.map(|j| load_n[j]),
                    nearness: FINGERTIP_JOINT.map(|j| o.nearness(j, pos[j])),
                }
            }
            (Some(ObjectModel::Shape(o)), Some(pads)) => pads.update(o, &pos, h),
            _ => ContactState::default(),
        };
        self.load = contacts.load_n;
        self.normal = contacts.normal_n;
        self.nearness = contacts.nearness;
    }

    fn update_sensor(&mut self) {
        self.sensor_counter = self.sensor_counter.wrapping_add(1);
        let (share, direction) = self.object.map_or((0.0, 0), |o| o.tangential());
        for tip in 0..FINGERTIPS {
            let normal_n = self.normal[tip];
            let tangential_n = normal_n * share;
            self.sensor[tip] = Touch {
                normal_n,
                tangential_n,
                direction_deg: (tangential_n > 0.05).then_some(direction),
                proximity: (self.nearness[tip] * PROXIMITY_MAX as f32) as u32,
            };
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
            let load = self.load[j] * self.params.ma_per_n;
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

    /// Advances `hand` by `seconds` in 1 ms steps.
    pub(super) fn run(hand: &mut Hand, seconds: f32) {
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
        let mut h = Hand::new(
            HandParams::default(),
            Some(ObjectModel::Joint(VirtualObject::ball())),
        );
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
        let mut h = Hand::new(
            HandParams::default(),
            Some(ObjectModel::Joint(VirtualObject::ball())),
        );
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
        let mut h = Hand::new(
            HandParams::default(),
            Some(ObjectModel::Joint(VirtualObject::ball())),
        );
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

#[cfg(test)]
mod shape_tests {
    use glam::DVec3;
    use teleop_hand_profile::HandProfile;
    use teleop_kinematics::Chains;

    use super::tests::run;
    use super::*;

    /// Fingertip `f`'s pad centre and radius with the joints at `positions`, by the profile's
    /// kinematics and the Revo2 node's map (per mille of travel = normalised position).
    fn pad(positions: [f32; JOINTS], f: usize) -> (DVec3, f64) {
        let profile = HandProfile::builtin("revo2").unwrap();
        let q: Vec<f64> = profile
            .joints
            .iter()
            .zip(positions)
            .map(|(j, p)| f64::from(j.radians(p / 1000.0)))
            .collect();
        let chains = Chains::new(&profile);
        (chains.pad(f, &q), chains.chains()[f].pad_radius)
    }

    fn centre(shape: Shape) -> DVec3 {
        match shape {
            Shape::Sphere { centre, .. } | Shape::Box { centre, .. } => {
                DVec3::from(centre.map(f64::from))
            }
        }
    }

    /// The radius of [`sphere_on_index_path`]'s sphere, m.
    const SPHERE_RADIUS: f64 = 0.030;

    /// Where the index pad's centre stops against [`sphere_on_index_path`]'s sphere: the
    /// sphere's radius plus the pad's (from the profile), m from the sphere's centre.
    fn index_surface() -> f64 {
        SPHERE_RADIUS + pad([0.0; JOINTS], 1).1
    }

    /// A sphere of radius 30 mm placed by its centre so that the index pad's surface meets it
    /// at 40 % of the index's travel, pressing straight into it (the centre on the pad's path).
    fn sphere_on_index_path(stiffness_n_per_m: f32) -> ShapeObject {
        let radius = SPHERE_RADIUS;
        let mut at = [0.0; JOINTS];
        at[2] = 400.0;
        let (touch, pad_radius) = pad(at, 1);
        at[2] = 401.0;
        let (further, _) = pad(at, 1);
        let centre = touch + (further - touch).normalize() * (radius + pad_radius);
        ShapeObject::new(
            Shape::Sphere {
                centre: centre.as_vec3().to_array(),
                radius: radius as f32,
            },
            stiffness_n_per_m,
        )
    }

    /// Closes the index with `current` (per mille of the maximum) against `object`; the pad's
    /// distance to the object's centre and the index's normal force once settled.
    fn press_index(object: ShapeObject, current: f32) -> (f64, f32) {
        let mut h = Hand::new(HandParams::default(), Some(ObjectModel::Shape(object)));
        h.command(2, mode::CURRENT, current, 0.0);
        run(&mut h, 1.0);
        let (p, _) = pad(h.positions(), 1);
        (p.distance(centre(object.shape)), h.touches()[1].normal_n)
    }

    #[test]
    fn a_closing_finger_stops_at_the_spheres_surface() {
        let object = sphere_on_index_path(1e5);
        let mut h = Hand::new(HandParams::default(), Some(ObjectModel::Shape(object)));
        h.command(2, mode::POSITION_SPEED, 700.0, 1000.0);
        run(&mut h, 1.0);
        let (p, _) = pad(h.positions(), 1);
        let surface = index_surface();
        let distance = p.distance(centre(object.shape));
        assert!(
            (surface - 0.001..=surface).contains(&distance),
            "pad centre {distance} m from the centre, surface at {surface} m ({:?})",
            h.positions()
        );
        let index = h.positions()[2];
        assert!((399.0..402.0).contains(&index), "index at {index}");
        let touch = h.touches()[1];
        assert!(touch.normal_n > 5.0, "{touch:?}");
        assert_eq!(touch.proximity, PROXIMITY_MAX);
        assert!(
            h.currents()[2] > h.currents()[3] + 300.0,
            "{:?}",
            h.currents()
        );
        assert_eq!(
            h.touches()[2],
            Touch::default(),
            "the middle finger is free"
        );
    }

    #[test]
    fn a_sponge_lets_the_finger_in_further_than_a_rigid_object_for_the_same_push() {
        // 300 mA: 5 N at the fingertip.
        let push_n = 300.0 / HandParams::default().ma_per_n;
        let (rigid, rigid_n) = press_index(sphere_on_index_path(1e5), 300.0);
        let (sponge, sponge_n) = press_index(sphere_on_index_path(300.0), 300.0);
        let surface = index_surface();
        assert!(surface - rigid < 0.001, "rigid: {} m deep", surface - rigid);
        assert!(
            surface - sponge > 0.008,
            "sponge: {} m deep",
            surface - sponge
        );
        // Pressing straight in, the surface's force balances the push in both.
        for n in [rigid_n, sponge_n] {
            assert!(
                (n - push_n).abs() < 0.1 * push_n,
                "{n} N against {push_n} N"
            );
        }
    }

    #[test]
    fn a_rigid_contact_holds_still_at_the_half_millisecond_step() {
        let object = sphere_on_index_path(1e5);
        let mut h = Hand::new(HandParams::default(), Some(ObjectModel::Shape(object)));
        h.command(2, mode::CURRENT, 1000.0, 0.0);
        run(&mut h, 0.5);
        let (mut low, mut high) = (f32::MAX, f32::MIN);
        let (mut least, mut most) = (f32::MAX, f32::MIN);
        let mut t = h.time();
        for _ in 0..1000 {
            t += 0.0005;
            h.advance_to(t);
            let (p, n) = (h.positions()[2], h.normal[1]);
            (low, high) = (low.min(p), high.max(p));
            (least, most) = (least.min(n), most.max(n));
        }
        assert!(high - low < 0.01, "index between {low} and {high}");
        assert!(most - least < 0.01, "force between {least} and {most} N");
        assert!(least > 10.0, "{least} N");
    }

    #[test]
    fn damping_slows_the_pressing_in_but_not_where_it_ends() {
        let springy = sphere_on_index_path(1000.0);
        let damped = ShapeObject {
            damping_n_s_per_m: 50.0,
            ..springy
        };
        let depth_after = |object: ShapeObject, seconds: f32| {
            let mut h = Hand::new(HandParams::default(), Some(ObjectModel::Shape(object)));
            h.command(2, mode::POSITION_SPEED, 395.0, 1000.0);
            run(&mut h, 0.5);
            h.command(2, mode::CURRENT, 600.0, 0.0);
            run(&mut h, seconds);
            let (p, _) = pad(h.positions(), 1);
            index_surface() - p.distance(centre(object.shape))
        };
        let (quick, slow) = (depth_after(springy, 0.02), depth_after(damped, 0.02));
        assert!(
            slow < 0.8 * quick,
            "after 20 ms: {slow} m damped, {quick} m not"
        );
        let (quick, slow) = (depth_after(springy, 1.0), depth_after(damped, 1.0));
        assert!(
            (slow - quick).abs() < 1e-4,
            "settled: {slow} m damped, {quick} m not"
        );
    }

    #[test]
    fn a_grasp_meets_the_ball_near_the_joint_space_balls_travel() {
        let mut h = Hand::new(
            HandParams::default(),
            Some(ObjectModel::Shape(ShapeObject::ball(1e5))),
        );
        // The thumb turned in first, then every finger closes.
        h.command(1, mode::POSITION_SPEED, 700.0, 1000.0);
        run(&mut h, 0.5);
        for j in [0, 2, 3, 4, 5] {
            h.command(j, mode::POSITION_SPEED, 700.0, 1000.0);
        }
        run(&mut h, 1.0);
        let p = h.positions();
        assert!((300.0..400.0).contains(&p[2]), "index {p:?}");
        for j in 3..JOINTS {
            assert!((250.0..450.0).contains(&p[j]), "joint {j}: {p:?}");
        }
        assert!(
            p[0] < 200.0,
            "the turned-in thumb meets the ball early: {p:?}"
        );
        let touch = h.touches();
        for (f, t) in touch.iter().enumerate() {
            assert!(t.normal_n > 5.0, "fingertip {f}: {touch:?}");
            assert!(t.tangential_n > 0.0 && t.direction_deg == Some(180));
        }
    }

    #[test]
    fn the_thumb_meets_the_ball_only_when_turned_in() {
        let thumb = |abduction: f32| {
            let mut h = Hand::new(
                HandParams::default(),
                Some(ObjectModel::Shape(ShapeObject::ball(3000.0))),
            );
            h.command(1, mode::POSITION_SPEED, abduction, 1000.0);
            run(&mut h, 0.5);
            h.command(0, mode::POSITION_SPEED, 600.0, 1000.0);
            run(&mut h, 1.0);
            (h.positions()[0], h.touches()[0].normal_n)
        };
        let (flex, force) = thumb(700.0);
        assert!(flex < 200.0 && force > 5.0, "turned in: {flex}, {force} N");
        let (flex, force) = thumb(300.0);
        assert!(
            flex > 590.0 && force == 0.0,
            "beside the hand: {flex}, {force} N"
        );
    }

    /// The case: a pinch with the fingertips apart and nothing between them, which the
    /// joint-space ball feels as a firm contact.
    #[test]
    fn a_pinch_away_from_the_ball_feels_nothing() {
        // The thumb 45 % flexed beside the hand, the index at 35.5 %.
        let pinch = [450.0, 300.0, 355.0, 0.0, 0.0, 0.0];
        let hold = |object: Option<ObjectModel>| {
            let mut h = Hand::new(HandParams::default(), object);
            for (j, target) in pinch.into_iter().enumerate() {
                h.command(j, mode::POSITION_SPEED, target, 1000.0);
            }
            run(&mut h, 1.0);
            h
        };
        let joint = hold(Some(ObjectModel::Joint(VirtualObject::ball())));
        let felt = joint.touches().map(|t| t.normal_n);
        assert!(felt[0] > 3.0 && felt[1] > 0.5, "joint-space ball: {felt:?}");
        let (thumb, _) = pad(joint.positions(), 0);
        let (index, _) = pad(joint.positions(), 1);
        assert!(thumb.distance(index) > 0.05, "{}", thumb.distance(index));

        let far = ShapeObject::new(
            Shape::Sphere {
                centre: [0.0, -0.2, 0.0],
                radius: 0.035,
            },
            3000.0,
        );
        for object in [
            None,
            Some(ObjectModel::Shape(ShapeObject::ball(3000.0))),
            Some(ObjectModel::Shape(far)),
        ] {
            let h = hold(object);
            assert!(
                (h.positions()[0] - 450.0).abs() < 1.0 && (h.positions()[2] - 355.0).abs() < 1.0,
                "{object:?}: {:?}",
                h.positions()
            );
            for t in h.touches() {
                assert_eq!(t.normal_n, 0.0, "{object:?}: {:?}", h.touches());
            }
            assert!(h.currents()[0] < 100.0, "{:?}", h.currents());
        }
        let far = hold(Some(ObjectModel::Shape(far)));
        assert!(far.touches().iter().all(|t| t.proximity == 0));
    }

    #[test]
    fn proximity_rises_as_a_pad_nears_the_surface() {
        let object = sphere_on_index_path(3000.0);
        let proximity = |index: f32| {
            let mut h = Hand::new(HandParams::default(), Some(ObjectModel::Shape(object)));
            h.command(2, mode::POSITION_SPEED, index, 1000.0);
            run(&mut h, 1.0);
            h.touches()[1].proximity
        };
        let (far, near, closer) = (proximity(0.0), proximity(300.0), proximity(380.0));
        assert_eq!(far, 0);
        assert!(
            0 < near && near < closer && closer < PROXIMITY_MAX,
            "{near} {closer}"
        );
    }

    #[test]
    fn a_block_stops_the_fingers_on_its_face() {
        let mut h = Hand::new(
            HandParams::default(),
            Some(ObjectModel::Shape(ShapeObject::block(1e5))),
        );
        for j in 2..JOINTS {
            h.command(j, mode::POSITION_SPEED, 700.0, 1000.0);
        }
        run(&mut h, 1.0);
        let p = h.positions();
        for j in 2..JOINTS {
            assert!((280.0..400.0).contains(&p[j]), "joint {j}: {p:?}");
        }
        assert!(h.touches()[1..].iter().all(|t| t.normal_n > 5.0));
        // Removing it lets them close.
        h.set_object(None);
        run(&mut h, 1.0);
        assert!((h.positions()[2] - 700.0).abs() < 1.0);
        assert_eq!(h.touches()[1], Touch::default());
    }

    #[test]
    fn friction_holds_a_finger_that_presses_the_ball_off_its_centre_line() {
        // The index's plane passes 27 mm beside the ball's centre: pressing it with its full
        // push, the pad slides round the side of a frictionless soft ball and through it.
        let index = |friction: f32| {
            let ball = ShapeObject {
                friction,
                ..ShapeObject::ball(1000.0)
            };
            let mut h = Hand::new(HandParams::default(), Some(ObjectModel::Shape(ball)));
            h.command(2, mode::CURRENT, 1000.0, 0.0);
            run(&mut h, 1.0);
            (h.positions()[2], h.touches()[1].normal_n)
        };
        let (held, force) = index(0.5);
        assert!(
            held < 500.0 && force > 10.0,
            "with friction: {held}, {force} N"
        );
        let (slid, _) = index(0.0);
        assert!(slid > 690.0, "without: {slid}");
    }
}
