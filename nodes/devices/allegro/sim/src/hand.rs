//! The simulated Allegro Hand's mechanics: 16 joints driven by motor torque, with inertia,
//! viscous damping, hard joint limits, optional gravity, a virtual ball the fingers close on and
//! a motor temperature that rises with effort.
//!
//! Geometry comes from the hand profile (`config/hands/allegro.toml`, compiled into
//! `teleop-hand-profile`): each finger's chain is posed by forward kinematics; the ball pushes
//! back on points along the phalanges (a spring-damper on the penetration, finger pads of
//! [`HandParams::pad_radius`]), and that force reaches the joints through the chain's Jacobian
//! (`tau_i = (axis_i x (p - origin_i)) . F`). Gravity pulls on point masses at the phalanx
//! midpoints the same way. Joints are decoupled otherwise (a diagonal inertia, which is what a
//! geared joint looks like from its motor).
//!
//! Pure: time comes in as seconds; the model advances in fixed sub-steps of
//! [`HandParams::step_s`].

use teleop_hand_profile::HandProfile;
use teleop_sim_kit::plant::{lag, Clock, Joint};
use teleop_sim_kit::Object;

/// Joints: index 0-3, middle 4-7, ring 8-11, thumb 12-15 (the CAN order).
pub const JOINTS: usize = 16;
/// Fingers in CAN order: index, middle, ring, thumb.
pub const FINGERS: usize = 4;
/// Joints per finger.
pub const JOINTS_PER_FINGER: usize = 4;

type Vec3 = [f64; 3];
type Mat3 = [[f64; 3]; 3];

fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}
fn mat_vec(m: &Mat3, v: Vec3) -> Vec3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}
fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, cell) in row.iter_mut().enumerate() {
            *cell = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}
/// Rotation by `angle` about the unit `axis` (Rodrigues).
fn rotation(axis: Vec3, angle: f64) -> Mat3 {
    let [x, y, z] = axis;
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}
/// URDF roll-pitch-yaw: about fixed x, then y, then z (R = Rz Ry Rx).
fn rpy(r: [f64; 3]) -> Mat3 {
    let rx = rotation([1.0, 0.0, 0.0], r[0]);
    let ry = rotation([0.0, 1.0, 0.0], r[1]);
    let rz = rotation([0.0, 0.0, 1.0], r[2]);
    mat_mul(&rz, &mat_mul(&ry, &rx))
}
fn v3(a: [f32; 3]) -> Vec3 {
    [f64::from(a[0]), f64::from(a[1]), f64::from(a[2])]
}

/// One finger's kinematic chain (four joints, then the tip).
#[derive(Debug, Clone, PartialEq)]
struct Chain {
    base: Vec3,
    base_rotation: Mat3,
    /// Per joint: its axis in its link frame and its origin in the previous frame.
    links: [(Vec3, Vec3); JOINTS_PER_FINGER],
    tip: Vec3,
}

/// A posed finger: each joint's position and world axis, then the tip.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pose {
    origin: [Vec3; JOINTS_PER_FINGER],
    axis: [Vec3; JOINTS_PER_FINGER],
    tip: Vec3,
}

impl Chain {
    fn pose(&self, q: &[f64]) -> Pose {
        let mut p = self.base;
        let mut r = self.base_rotation;
        let mut origin = [[0.0; 3]; JOINTS_PER_FINGER];
        let mut axis = [[0.0; 3]; JOINTS_PER_FINGER];
        for (k, (a, o)) in self.links.iter().enumerate() {
            p = add(p, mat_vec(&r, *o));
            origin[k] = p;
            axis[k] = mat_vec(&r, *a);
            r = mat_mul(&r, &rotation(*a, q[k]));
        }
        Pose {
            origin,
            axis,
            tip: add(p, mat_vec(&r, self.tip)),
        }
    }
}

impl Pose {
    /// The end of segment `s` (0: joint 0 to joint 1, ..., 3: joint 3 to the tip).
    fn segment_end(&self, s: usize) -> Vec3 {
        if s + 1 < JOINTS_PER_FINGER {
            self.origin[s + 1]
        } else {
            self.tip
        }
    }

    /// The point at fraction `f` along segment `s` (moved by joints 0..=s).
    fn segment_point(&self, s: usize, f: f64) -> Vec3 {
        let a = self.origin[s];
        add(a, scale(sub(self.segment_end(s), a), f))
    }

    /// Adds the joint torques of a force `f` acting at `p` on segment `s` to `tau`.
    fn apply(&self, s: usize, p: Vec3, f: Vec3, tau: &mut [f64]) {
        for (k, t) in tau.iter_mut().enumerate().take(s + 1) {
            *t += dot(cross(self.axis[k], sub(p, self.origin[k])), f);
        }
    }
}

/// The shape of the virtual object.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// A sphere.
    Sphere,
    /// A cylinder lying across the palm (its axis along x, the hand's width), infinitely long:
    /// the long fingers wrap it in their own planes, the thumb opposes it.
    Cylinder,
}

/// The virtual object: a ball (or a bar) in the hand frame (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VirtualObject {
    /// Its shape.
    pub shape: Shape,
    /// Centre, hand frame (for a cylinder, a point on its axis).
    pub centre: [f64; 3],
    /// Radius.
    pub radius: f64,
    /// Contact stiffness, N/m of penetration.
    pub stiffness: f64,
    /// Contact damping, N s/m of penetration speed (only while pressing in).
    pub damping: f64,
}

impl VirtualObject {
    /// A ball of 8 cm under the palm, in front of the middle finger: the middle finger closing
    /// meets it about half closed and the opposed thumb presses on it from its side; the index
    /// and ring fingers only brush its sides (pushing their first joints outwards) and close
    /// beside it.
    pub fn ball() -> Self {
        Self {
            shape: Shape::Sphere,
            centre: [0.0, 0.11, -0.07],
            radius: 0.04,
            stiffness: 2000.0,
            damping: 4.0,
        }
    }

    /// A bar of 8 cm across the palm where the ball is: the index, middle and ring fingers
    /// closing wrap it about half closed.
    pub fn bar() -> Self {
        Self {
            shape: Shape::Cylinder,
            ..Self::ball()
        }
    }

    /// The geometry of the simulator kit's `object`.
    pub fn of(object: Object) -> Self {
        match object {
            Object::Ball => Self::ball(),
            Object::Bar => Self::bar(),
        }
    }
}

/// Physical constants. Allegro figures from the v4 URDF where it has them (masses); the rest
/// are plausible values for a small geared joint (no published numbers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandParams {
    /// Joint inertia as the motor sees it, kg m^2.
    pub inertia: f64,
    /// Viscous joint damping, N m s/rad.
    pub damping: f64,
    /// Pull gravity on the phalanges (the hand palm down: gravity along -z of the hand frame).
    pub gravity: bool,
    /// Phalanx masses (segments 1, 2, 3 of a finger), kg (URDF links 1-3 of a finger).
    pub segment_mass: [f64; 3],
    /// Radius of the finger pads around the chain's points, m.
    pub pad_radius: f64,
    /// Motor temperature with no effort, deg C.
    pub ambient_c: f64,
    /// Steady-state temperature rise per (N m)^2 of sustained torque, deg C.
    pub heat_c_per_nm2: f64,
    /// Thermal time constant, s.
    pub thermal_tau_s: f64,
    /// Integration sub-step, s.
    pub step_s: f64,
}

impl Default for HandParams {
    fn default() -> Self {
        Self {
            inertia: 1.0e-4,
            damping: 0.05,
            gravity: false,
            segment_mass: [0.065, 0.036, 0.027],
            pad_radius: 0.012,
            ambient_c: 30.0,
            heat_c_per_nm2: 120.0,
            thermal_tau_s: 30.0,
            step_s: 0.0005,
        }
    }
}

/// Fractions along a segment where the ball can touch it.
const CONTACT_POINTS: [f64; 3] = [0.33, 0.66, 1.0];

/// The hand.
#[derive(Debug, Clone)]
pub struct Hand {
    params: HandParams,
    chains: [Chain; FINGERS],
    limits: [(f64, f64); JOINTS],
    object: Option<VirtualObject>,
    q: [f64; JOINTS],
    qd: [f64; JOINTS],
    motor: [f64; JOINTS],
    external: [f64; JOINTS],
    contact_n: [f64; FINGERS],
    temperature: [f64; JOINTS],
    clock: Clock,
}

impl Hand {
    /// The Allegro of `profile` (16 joints in CAN order, four fingers of four joints), at rest
    /// at 0 rad clamped into the limits.
    pub fn new(
        profile: &HandProfile,
        params: HandParams,
        object: Option<VirtualObject>,
    ) -> Result<Self, String> {
        if profile.joints.len() != JOINTS || profile.fingers.len() != FINGERS {
            return Err(format!(
                "hand profile `{}`: {} joints and {} fingers; the Allegro has {JOINTS} and {FINGERS}",
                profile.name,
                profile.joints.len(),
                profile.fingers.len()
            ));
        }
        let mut chains = Vec::with_capacity(FINGERS);
        for (f, finger) in profile.fingers.iter().enumerate() {
            if finger.links.len() != JOINTS_PER_FINGER {
                return Err(format!(
                    "hand profile `{}`: finger {} has {} links, expected {JOINTS_PER_FINGER}",
                    profile.name,
                    finger.name,
                    finger.links.len()
                ));
            }
            let mut links = [([0.0; 3], [0.0; 3]); JOINTS_PER_FINGER];
            for (k, link) in finger.links.iter().enumerate() {
                if link.joint != Some(f * JOINTS_PER_FINGER + k) {
                    return Err(format!(
                        "hand profile `{}`: finger {} link {k} is not joint {}",
                        profile.name,
                        finger.name,
                        f * JOINTS_PER_FINGER + k
                    ));
                }
                links[k] = (v3(link.axis), v3(link.origin));
            }
            chains.push(Chain {
                base: v3(finger.base),
                base_rotation: rpy(v3(finger.base_rpy)),
                links,
                tip: v3(finger.tip),
            });
        }
        let chains: [Chain; FINGERS] = chains
            .try_into()
            .map_err(|_| "four fingers were checked above".to_string())?;
        let limits: [(f64, f64); JOINTS] = core::array::from_fn(|j| {
            (
                f64::from(profile.joints[j].lower),
                f64::from(profile.joints[j].upper),
            )
        });
        let q = core::array::from_fn(|j| 0.0f64.clamp(limits[j].0, limits[j].1));
        Ok(Self {
            params,
            chains,
            limits,
            object,
            q,
            qd: [0.0; JOINTS],
            motor: [0.0; JOINTS],
            external: [0.0; JOINTS],
            contact_n: [0.0; FINGERS],
            temperature: [params.ambient_c; JOINTS],
            clock: Clock::new(params.step_s),
        })
    }

    /// The builtin Allegro profile's hand.
    pub fn allegro(params: HandParams, object: Option<VirtualObject>) -> Result<Self, String> {
        let profile = HandProfile::builtin("allegro")
            .ok_or_else(|| "the builtin hand profile `allegro` is missing".to_string())?;
        Self::new(&profile, params, object)
    }

    /// Places or removes the object.
    pub fn set_object(&mut self, object: Option<VirtualObject>) {
        self.object = object;
    }

    /// The object.
    pub fn object(&self) -> Option<VirtualObject> {
        self.object
    }

    /// Turns gravity on or off.
    pub fn set_gravity(&mut self, on: bool) {
        self.params.gravity = on;
    }

    /// Sets the motor torques, N m (joint order).
    pub fn set_torques(&mut self, torque: &[f64; JOINTS]) {
        for (m, &t) in self.motor.iter_mut().zip(torque) {
            *m = if t.is_finite() { t } else { 0.0 };
        }
    }

    /// Puts joint `joint` at `rad` (clamped into its limits) at rest (tests, start pose).
    pub fn set_position(&mut self, joint: usize, rad: f64) {
        if let Some(q) = self.q.get_mut(joint) {
            let (lo, hi) = self.limits[joint];
            *q = rad.clamp(lo, hi);
            self.qd[joint] = 0.0;
        }
    }

    /// Sets every motor temperature, deg C (a fault: an overheated hand).
    pub fn set_temperatures(&mut self, celsius: f64) {
        self.temperature = [celsius; JOINTS];
    }

    /// Advances the model to time `t` seconds (earlier times are ignored).
    pub fn advance_to(&mut self, t: f64) {
        let mut clock = self.clock;
        clock.advance_to(t, |_, h| self.step(h));
        self.clock = clock;
    }

    /// The model's time, s.
    pub fn time(&self) -> f64 {
        self.clock.time()
    }

    fn external_torques(&mut self) {
        self.external = [0.0; JOINTS];
        self.contact_n = [0.0; FINGERS];
        let p = self.params;
        for f in 0..FINGERS {
            let q = &self.q[f * JOINTS_PER_FINGER..(f + 1) * JOINTS_PER_FINGER];
            let qd = &self.qd[f * JOINTS_PER_FINGER..(f + 1) * JOINTS_PER_FINGER];
            let pose = self.chains[f].pose(q);
            let tau = &mut self.external[f * JOINTS_PER_FINGER..(f + 1) * JOINTS_PER_FINGER];
            if p.gravity {
                for s in 1..JOINTS_PER_FINGER {
                    let mid = pose.segment_point(s, 0.5);
                    pose.apply(s, mid, [0.0, 0.0, -9.81 * p.segment_mass[s - 1]], tau);
                }
            }
            let Some(ball) = self.object else { continue };
            for s in 1..JOINTS_PER_FINGER {
                for point in CONTACT_POINTS.map(|f| pose.segment_point(s, f)) {
                    let mut d = sub(point, ball.centre);
                    if ball.shape == Shape::Cylinder {
                        d[0] = 0.0;
                    }
                    let dist = norm(d);
                    let depth = ball.radius + p.pad_radius - dist;
                    if depth <= 0.0 || dist < 1e-9 {
                        continue;
                    }
                    let n = scale(d, 1.0 / dist);
                    // The point's velocity along the normal: sum over the joints moving it.
                    let speed: f64 = (0..=s)
                        .map(|k| qd[k] * dot(cross(pose.axis[k], sub(point, pose.origin[k])), n))
                        .sum();
                    let push = (ball.stiffness * depth - ball.damping * speed).max(0.0);
                    self.contact_n[f] += push;
                    pose.apply(s, point, scale(n, push), tau);
                }
            }
        }
    }

    fn step(&mut self, h: f64) {
        let p = self.params;
        self.external_torques();
        let joint = Joint {
            inertia: p.inertia,
            damping: p.damping,
        };
        for j in 0..JOINTS {
            joint.step(
                &mut self.q[j],
                &mut self.qd[j],
                self.motor[j] + self.external[j],
                h,
                self.limits[j],
            );
            let rise = p.heat_c_per_nm2 * self.motor[j] * self.motor[j];
            let target = p.ambient_c + rise;
            self.temperature[j] = lag(self.temperature[j], target, h, p.thermal_tau_s);
        }
    }

    /// Joint positions, rad.
    pub fn positions(&self) -> [f64; JOINTS] {
        self.q
    }

    /// Joint velocities, rad/s.
    pub fn velocities(&self) -> [f64; JOINTS] {
        self.qd
    }

    /// Motor torques applied, N m.
    pub fn torques(&self) -> [f64; JOINTS] {
        self.motor
    }

    /// Torques of the ball (and gravity) on the joints at the last step, N m.
    pub fn external_torque(&self) -> [f64; JOINTS] {
        self.external
    }

    /// The ball's push on each finger at the last step, N (0 = no contact).
    pub fn contact_forces(&self) -> [f64; FINGERS] {
        self.contact_n
    }

    /// Motor temperatures, deg C.
    pub fn temperatures(&self) -> [f64; JOINTS] {
        self.temperature
    }

    /// Joint limits, rad.
    pub fn limits(&self) -> [(f64, f64); JOINTS] {
        self.limits
    }

    /// Each finger's fingertip in the hand frame, m.
    pub fn tips(&self) -> [[f64; 3]; FINGERS] {
        core::array::from_fn(|f| {
            self.chains[f]
                .pose(&self.q[f * JOINTS_PER_FINGER..(f + 1) * JOINTS_PER_FINGER])
                .tip
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hand(object: Option<VirtualObject>) -> Hand {
        Hand::allegro(HandParams::default(), object).expect("builtin profile")
    }

    fn run(hand: &mut Hand, seconds: f64) {
        let end = hand.time() + seconds;
        hand.advance_to(end);
    }

    /// Constant flexing torque on one finger's flexion joints for `seconds`, its first joint
    /// held at `hold` by a PD (as the node's controller does).
    fn flex(hand: &mut Hand, finger: usize, nm: f64, hold: f64, seconds: f64) {
        let end = hand.time() + seconds;
        while hand.time() < end {
            let mut t = [0.0; JOINTS];
            let j0 = finger * 4;
            t[j0] = 0.5 * (hold - hand.positions()[j0]) - 0.01 * hand.velocities()[j0];
            for k in 1..4 {
                t[j0 + k] = nm;
            }
            hand.set_torques(&t);
            let next = hand.time() + 0.001;
            hand.advance_to(next);
        }
    }

    #[test]
    fn open_fingers_point_along_y() {
        let h = hand(None);
        for f in 0..3 {
            let tip = h.tips()[f];
            assert!(tip[1] > 0.2 && tip[2].abs() < 1e-6, "finger {f}: {tip:?}");
        }
    }

    #[test]
    fn flexing_curls_towards_the_palm_side() {
        let mut h = hand(None);
        for j in [1, 2, 3] {
            h.set_position(j, 1.0);
        }
        assert!(h.tips()[0][2] < -0.05, "{:?}", h.tips()[0]);
    }

    fn stops_at(object: VirtualObject, f: usize) {
        let mut free = hand(None);
        let mut held = hand(Some(object));
        flex(&mut free, f, 0.3, 0.0, 1.0);
        flex(&mut held, f, 0.3, 0.0, 1.0);
        for j in f * 4 + 1..f * 4 + 4 {
            let (_, hi) = free.limits()[j];
            assert!(
                free.positions()[j] > hi - 1e-6,
                "finger {f} free reaches its limit: {:?}",
                free.positions()
            );
        }
        let j = f * 4 + 1;
        assert!(
            held.positions()[j] < 0.8,
            "finger {f} stops at the object: {:?}",
            held.positions()
        );
        assert!(
            held.contact_forces()[f] > 0.5,
            "{:?}",
            held.contact_forces()
        );
        assert!(
            held.velocities()[j].abs() < 0.05,
            "at rest: {:?}",
            held.velocities()
        );
    }

    #[test]
    fn a_finger_flexing_with_constant_torque_stops_at_the_object_and_not_without() {
        stops_at(VirtualObject::ball(), 1);
        for f in 0..3 {
            stops_at(VirtualObject::bar(), f);
        }
    }

    /// Closes every finger with a PD towards a fist (as the node does); returns the hand.
    fn close_with_pd(object: Option<VirtualObject>) -> Hand {
        let target = [
            0.0, 1.2, 1.2, 1.2, 0.0, 1.2, 1.2, 1.2, 0.0, 1.2, 1.2, 1.2, 1.3, 0.6, 1.2, 1.2,
        ];
        let mut h = hand(object);
        h.set_position(12, 1.3);
        while h.time() < 1.5 {
            let q = h.positions();
            let qd = h.velocities();
            let t: [f64; JOINTS] =
                core::array::from_fn(|j| 0.6 * (target[j] - q[j]) - 0.012 * qd[j]);
            h.set_torques(&t);
            let next = h.time() + 0.003;
            h.advance_to(next);
        }
        h
    }

    #[test]
    fn a_pd_closing_the_hand_stops_at_the_ball_with_the_effort_rising() {
        let free = close_with_pd(None);
        assert!(free.positions()[5] > 1.15, "{:?}", free.positions());
        assert!(free.torques()[5].abs() < 0.05, "{:?}", free.torques());
        let ball = close_with_pd(Some(VirtualObject::ball()));
        let (q, t, c) = (ball.positions(), ball.torques(), ball.contact_forces());
        assert!(
            q[5] < 0.8 && t[5] > 0.2,
            "middle stops, effort rises: {q:?} {t:?}"
        );
        assert!(
            c[1] > 2.0 && c[3] > 2.0,
            "middle and thumb press on it: {c:?}"
        );
        let bar = close_with_pd(Some(VirtualObject::bar()));
        let (q, t) = (bar.positions(), bar.torques());
        for f in 0..3 {
            let j = f * 4 + 1;
            assert!(q[j] < 0.8 && t[j] > 0.2, "finger {f}: {q:?} {t:?}");
        }
    }

    #[test]
    fn pushing_harder_on_the_ball_takes_more_torque_and_presses_further() {
        let mut h = hand(Some(VirtualObject::bar()));
        flex(&mut h, 1, 0.2, 0.0, 1.0);
        let (q1, n1) = (h.positions()[5], h.contact_forces()[1]);
        flex(&mut h, 1, 0.5, 0.0, 1.0);
        let (q2, n2) = (h.positions()[5], h.contact_forces()[1]);
        assert!(n2 > 1.5 * n1, "force rises with the torque: {n1} -> {n2}");
        assert!(q2 - q1 < 0.15, "presses in a little: {q1} -> {q2}");
    }

    #[test]
    fn joint_limits_hold_against_large_torques() {
        let mut h = hand(None);
        h.set_torques(&[5.0; JOINTS]);
        run(&mut h, 0.5);
        for (j, (&q, &(lo, hi))) in h.positions().iter().zip(&h.limits()).enumerate() {
            assert!(q >= lo && q <= hi, "joint {j}: {q}");
            assert!((q - hi).abs() < 1e-9, "joint {j} at its upper limit: {q}");
        }
        h.set_torques(&[-5.0; JOINTS]);
        run(&mut h, 0.5);
        for (j, (&q, &(lo, _))) in h.positions().iter().zip(&h.limits()).enumerate() {
            assert!((q - lo).abs() < 1e-9, "joint {j} at its lower limit: {q}");
        }
    }

    #[test]
    fn gravity_pulls_a_free_finger_towards_the_palm_side_only_when_on() {
        let mut h = hand(None);
        run(&mut h, 0.5);
        assert_eq!(h.positions()[1], 0.0);
        h.set_gravity(true);
        run(&mut h, 0.5);
        assert!(h.positions()[1] > 0.1, "{:?}", h.positions());
    }

    #[test]
    fn temperature_rises_with_effort_and_not_at_rest() {
        let mut h = hand(None);
        flex(&mut h, 0, 0.5, 0.0, 5.0);
        let t = h.temperatures();
        assert!(t[2] > 33.0, "{t:?}");
        assert!((t[4] - 30.0).abs() < 1e-9, "{t:?}");
    }
}
