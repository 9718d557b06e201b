//! Objects that touch the simulated Revo2's fingers by geometry: a shape placed in the hand's
//! frame, pressed by the fingertip pads where the hand profile's kinematics put them
//! (`teleop_kinematics::Chains` over the shipped `revo2` profile), with a surface force that
//! grows with the pads' penetration (a stiffness from a sponge to a rigid block, and optional
//! damping).
//!
//! A finger is massless here as in [`crate::hand`]'s joint-space model: where the contact
//! resists more than the motor pushes, the joint is put at the position where the two balance
//! (found by bisection along the joint), instead of integrating a stiff spring, so that a rigid
//! object (1e5 N/m) is as stable at the hand's 0.5 ms step as a sponge. The balance is taken
//! along the pad's motion: the surface force projected on the direction the joint moves the pad
//! (the pad's Jacobian column) against the motor's push at the fingertip, with friction resisting
//! the part of the motion that slides over the surface. Without it a pad pressing a ball off its
//! centre line, or deep into a soft one, slides round its side and through it.
//!
//! Only the pads touch (a sphere of the profile's `pad_radius` around each finger's `pad`); the
//! links pass through the object. Only the joints that close a fingertip give way to the
//! contact: the thumb's abduction holds its position (its motor's load still rises), an
//! assumption of this model, not a measurement: with the simulated position controller's
//! stiffness (0.03 N per position unit) a thumb pressing the ball would swing its abduction
//! away by hundreds of units and slide off.

use glam::DVec3;
use teleop_hand_profile::{HandProfile, MAX_JOINTS};
use teleop_kinematics::Chains;

use crate::hand::{nearness, FINGERTIPS, FINGERTIP_JOINT, JOINTS};

/// Travel of the position units (0 = open .. 1000 = closed).
const TRAVEL: f32 = 1000.0;

/// The equilibrium search stops when its bracket is this narrow, position units (0.16 µrad:
/// about 10 nm at the pad, 1 mN at 1e5 N/m).
const TOLERANCE: f32 = 1e-4;

/// Bisections at most: enough to narrow the widest bracket (the whole travel) to [`TOLERANCE`]
/// (1000 / 2^24 < 1e-4), and a bound where f32 rounding would stall the bracket.
const MAX_BISECTIONS: usize = 24;

/// The share of an object's squash depth that [`normal_force`] counts as left at least, so the
/// force stays finite (a million times the linear spring's) at and past the middle.
const MIN_SQUASH_LEFT: f64 = 1e-6;

/// A shape in the hand's frame (metres; `teleop_hand_profile`'s frame: wrist at the origin,
/// fingers along +Y, the back of the hand towards +Z, the thumb on the -X side).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// A sphere.
    Sphere {
        /// Its centre.
        centre: [f32; 3],
        /// Its radius.
        radius: f32,
    },
    /// A box whose edges lie along the frame's axes.
    Box {
        /// Its centre.
        centre: [f32; 3],
        /// Half its size along X, Y and Z.
        half_extents: [f32; 3],
    },
}

impl Shape {
    /// How deep a pad can press in before the object is squashed flat, metres: to the sphere's
    /// centre, to the box's middle across its thinnest side.
    fn squash_depth(&self) -> f64 {
        match *self {
            Shape::Sphere { radius, .. } => f64::from(radius),
            Shape::Box { half_extents, .. } => {
                f64::from(half_extents[0].min(half_extents[1]).min(half_extents[2]))
            }
        }
    }

    /// The signed distance from `p` to the surface (negative inside) and the outward normal at
    /// the nearest surface point.
    fn distance(&self, p: DVec3) -> (f64, DVec3) {
        match *self {
            Shape::Sphere { centre, radius } => {
                let d = p - vec(centre);
                (d.length() - f64::from(radius), d.normalize_or(DVec3::Z))
            }
            Shape::Box {
                centre,
                half_extents,
            } => {
                // The usual box distance: per axis, how far outside the slab the point is.
                let d = p - vec(centre);
                let q = d.abs() - vec(half_extents);
                let outside = q.max(DVec3::ZERO);
                if outside.length_squared() > 0.0 {
                    let normal = (outside * d.signum()).normalize_or(DVec3::Z);
                    (outside.length(), normal)
                } else {
                    // Inside: the nearest face's.
                    let axis = if q.x >= q.y && q.x >= q.z {
                        DVec3::X
                    } else if q.y >= q.z {
                        DVec3::Y
                    } else {
                        DVec3::Z
                    };
                    (q.max_element(), axis * d.dot(axis).signum())
                }
            }
        }
    }
}

fn vec(a: [f32; 3]) -> DVec3 {
    DVec3::new(f64::from(a[0]), f64::from(a[1]), f64::from(a[2]))
}

/// An object with a shape, touched by the fingertip pads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeObject {
    /// Where it is.
    pub shape: Shape,
    /// Surface stiffness, newtons per metre of a pad's penetration: a sponge a few hundred, a
    /// firm object a few thousand, a rigid block 1e4..1e5. It is the stiffness of a shallow
    /// press: the object stiffens as it is squashed, without bound as a pad nears its middle
    /// (see [`normal_force`]).
    pub stiffness_n_per_m: f32,
    /// Surface damping, newtons per metre per second of penetration speed (0: none); the
    /// surface's force never pulls a pad in.
    pub damping_n_s_per_m: f32,
    /// Friction coefficient between a pad and the surface: a pad sliding over it is resisted by
    /// up to this many newtons per newton of normal force. Taken as a function of the pad's
    /// position only (the same pressing in and backing out, no stick-slip), so the object
    /// stores and returns energy but never makes any.
    pub friction: f32,
    /// Tangential force as a share of the normal force (the object's weight pulling sideways).
    pub tangential_share: f32,
    /// Direction of the tangential force, degrees (0 = towards the fingertip, clockwise).
    pub tangential_direction_deg: u16,
    /// Proximity starts rising when a pad's surface is this close to the object's, metres.
    pub approach_m: f32,
}

impl ShapeObject {
    /// `shape` with a surface of this stiffness, no damping, friction 0.5 (within the range
    /// measured for skin on common materials, about 0.2 to above 1: Derler and Gerhardt,
    /// "Tribology of skin", Tribology Letters 45, 2012), and the tangential force and proximity
    /// range of the joint-space ball (`VirtualObject::ball`).
    pub fn new(shape: Shape, stiffness_n_per_m: f32) -> Self {
        Self {
            shape,
            stiffness_n_per_m,
            damping_n_s_per_m: 0.0,
            friction: 0.5,
            tangential_share: 0.25,
            tangential_direction_deg: 180,
            approach_m: 0.02,
        }
    }

    /// A ball 80 mm across (an orange) under the fingers, clear of the palm, placed by a grid
    /// search over its centre and radius: closing fingers meet it near the joint-space ball's
    /// travel (index at 36 %, middle 34 %, ring and pinky 30 %), and press it rather than graze
    /// it (a smaller ball lets the outer fingers slide round its side). With the default
    /// friction every finger's full push (15.7 N) is held from about 1000 N/m (below, the index
    /// and pinky, off the ball's centre line, slide round it), a 5 N push from about 500 N/m
    /// (the four fingers from 300 N/m, the thumb sliding past). The thumb's contact depends on
    /// its abduction: with the abduction at 70 % it meets the ball at 12 % of its flexion, at
    /// 60 % at 22 %, and below 50 % it passes beside the ball.
    pub fn ball(stiffness_n_per_m: f32) -> Self {
        Self::new(
            Shape::Sphere {
                centre: [0.004, 0.125, -0.075],
                radius: 0.040,
            },
            stiffness_n_per_m,
        )
    }

    /// A bar 20 mm square and 100 mm long across the fingers, under their fingertips, placed
    /// like [`ShapeObject::ball`]: index and ring meet it at 31 %, middle 35 %, pinky 37 %; the
    /// thumb passes it by.
    pub fn block(stiffness_n_per_m: f32) -> Self {
        Self::new(
            Shape::Box {
                centre: [0.0, 0.1475, -0.065],
                half_extents: [0.05, 0.01, 0.01],
            },
            stiffness_n_per_m,
        )
    }
}

/// One pad against an object.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PadContact {
    /// From the pad's surface to the object's, metres (negative: the pad is that deep in).
    gap: f64,
    /// The object's outward normal there.
    normal: DVec3,
}

/// Where the contacts leave the hand after a step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct ContactState {
    /// Per fingertip, the surface's normal force on its pad, N.
    pub normal_n: [f32; FINGERTIPS],
    /// Per fingertip, how close its pad is to the object: 0 (far) .. 1 (touching).
    pub nearness: [f32; FINGERTIPS],
    /// Per joint, how hard the contact resists its motion, newtons at the pad along the pad's
    /// motion.
    pub load_n: [f32; JOINTS],
}

/// The Revo2's fingertip pads as the hand profile places them (from the simulator's position
/// units), and how deep each was in the object after the last step (for the damping).
#[derive(Debug, Clone)]
pub(crate) struct Pads {
    chains: Chains,
    /// Per fingertip, its pad's radius, metres.
    pad_radius: [f64; FINGERTIPS],
    /// Per joint, the fingertip it moves.
    fingertip_of_joint: [usize; JOINTS],
    /// Per joint, its angle at position 0, radians.
    open: [f64; JOINTS],
    /// Per joint, radians per position unit.
    per_unit: [f64; JOINTS],
    /// Per fingertip, its pad's depth in the object after the last step, metres.
    depth: [f64; FINGERTIPS],
}

impl Pads {
    /// The shipped `revo2` profile's kinematics (`config/hands/revo2.toml`). Positions map to
    /// angles as the Revo2 node maps them: per mille of travel is the normalised position
    /// (`teleop_revo2`'s `normalised_position`), which the profile turns into its joint's
    /// angle between `open` and `closed`. `Err` says what does not fit the simulator's hand.
    pub fn revo2() -> Result<Self, String> {
        let profile = HandProfile::builtin("revo2")
            .ok_or("the builtin hand profile `revo2` does not load")?;
        Self::of(&profile)
    }

    /// The kinematics of `profile`, which must have the Revo2's joints and fingers in its order
    /// (six joints, five fingers in tactile order, each fingertip's joint in its finger).
    fn of(profile: &HandProfile) -> Result<Self, String> {
        let name = &profile.name;
        if profile.joints.len() != JOINTS || profile.fingers.len() != FINGERTIPS {
            return Err(format!(
                "hand profile `{name}`: {} joints and {} fingers, the Revo2 simulator has \
                 {JOINTS} and {FINGERTIPS}",
                profile.joints.len(),
                profile.fingers.len()
            ));
        }
        let mut fingertip_of_joint = [0; JOINTS];
        for (j, joint) in profile.joints.iter().enumerate() {
            fingertip_of_joint[j] = joint.finger;
        }
        for (f, &j) in FINGERTIP_JOINT.iter().enumerate() {
            if fingertip_of_joint[j] != f {
                return Err(format!(
                    "hand profile `{name}`: joint {j} ({}) is not in finger {f}, whose \
                     fingertip it closes in the simulator",
                    profile.joints[j].name
                ));
            }
        }
        let chains = Chains::new(profile);
        Ok(Self {
            pad_radius: core::array::from_fn(|f| chains.chains()[f].pad_radius),
            chains,
            fingertip_of_joint,
            open: core::array::from_fn(|j| f64::from(profile.joints[j].radians(0.0))),
            per_unit: core::array::from_fn(|j| {
                let joint = &profile.joints[j];
                f64::from(joint.radians(1.0) - joint.radians(0.0)) / f64::from(TRAVEL)
            }),
            depth: [0.0; FINGERTIPS],
        })
    }

    /// Forgets the pads' depths (the object changed).
    pub fn clear(&mut self) {
        self.depth = [0.0; FINGERTIPS];
    }

    /// The joint angles of `positions`, radians.
    fn angles(&self, positions: &[f32; JOINTS]) -> [f64; JOINTS] {
        core::array::from_fn(|j| self.open[j] + self.per_unit[j] * f64::from(positions[j]))
    }

    /// Fingertip `f`'s pad against `shape` at angles `q`, and in `jacobian` the pad centre's
    /// motion per position unit of each joint.
    fn pad(
        &self,
        shape: &Shape,
        f: usize,
        q: &[f64; JOINTS],
        jacobian: &mut [DVec3; MAX_JOINTS],
    ) -> PadContact {
        let centre = self.chains.pad_jacobian(f, q, jacobian);
        for (column, per_unit) in jacobian.iter_mut().zip(self.per_unit) {
            *column *= per_unit;
        }
        let (distance, normal) = shape.distance(centre);
        PadContact {
            gap: distance - self.pad_radius[f],
            normal,
        }
    }

    /// The contact's force along joint `j`'s motion with the joints at `positions`, newtons at
    /// the pad, positive towards larger positions; `None` when the pad is clear of the object.
    /// `previous_depth` is the pad's depth a step of `h` seconds before, for the damping.
    fn joint_force(
        &self,
        object: &ShapeObject,
        positions: &[f32; JOINTS],
        j: usize,
        previous_depth: f64,
        h: f64,
    ) -> Option<f64> {
        let mut jacobian = [DVec3::ZERO; MAX_JOINTS];
        let f = self.fingertip_of_joint[j];
        let pad = self.pad(&object.shape, f, &self.angles(positions), &mut jacobian);
        (pad.gap < 0.0).then(|| {
            let force = normal_force(object, -pad.gap, previous_depth, h);
            force * along(pad.normal, jacobian[j].normalize_or_zero(), object.friction)
        })
    }

    /// Where joint `j` comes to rest this step when the contact stops it: the motor (pushing
    /// with `push_n`, newtons at the fingertip, positive closing) would take it from its
    /// position in `positions` to `next`. `None` when the contact does not hold it back (a joint
    /// that closes no fingertip, no contact at `next`, or the motor pushes harder than the
    /// surface resists); otherwise the position, between `next` and where the pad leaves the
    /// surface, where the contact's force along the joint balances the push (or the surface,
    /// when the motor pulls out too).
    pub fn settle(
        &self,
        object: &ShapeObject,
        positions: &[f32; JOINTS],
        j: usize,
        next: f32,
        push_n: f32,
        h: f32,
    ) -> Option<f32> {
        if !FINGERTIP_JOINT.contains(&j) {
            return None;
        }
        let depth = self.depth[self.fingertip_of_joint[j]];
        let push = f64::from(push_n);
        let mut at = *positions;
        let mut force_at = |x: f32| {
            at[j] = x;
            self.joint_force(object, &at, j, depth, f64::from(h))
                .filter(|&s| s != 0.0)
        };
        // The way the surface pushes the joint; the contact holds it where, that way, the
        // surface still pushes at least as hard as the motor.
        let out = force_at(next)?.signum() as f32;
        let mut holds = |x: f32| force_at(x).is_some_and(|s| (push + s) * f64::from(out) >= 0.0);
        if !holds(next) {
            return None;
        }
        // Bracket the balance outwards from `next` with doubling steps, then bisect.
        let (mut inner, mut step) = (next, 1.0);
        let mut outer = loop {
            let x = (inner + out * step).clamp(0.0, TRAVEL);
            if !holds(x) {
                break x;
            }
            if x == 0.0 || x == TRAVEL {
                return Some(x);
            }
            inner = x;
            step *= 2.0;
        };
        for _ in 0..MAX_BISECTIONS {
            if (outer - inner).abs() <= TOLERANCE {
                break;
            }
            let mid = 0.5 * (inner + outer);
            if holds(mid) {
                inner = mid;
            } else {
                outer = mid;
            }
        }
        Some(inner)
    }

    /// The contacts with the joints at `positions` at the end of a step of `h` seconds,
    /// remembering the pads' depths for the next.
    pub fn update(
        &mut self,
        object: &ShapeObject,
        positions: &[f32; JOINTS],
        h: f32,
    ) -> ContactState {
        let q = self.angles(positions);
        let mut state = ContactState::default();
        let mut jacobian = [DVec3::ZERO; MAX_JOINTS];
        for f in 0..FINGERTIPS {
            let pad = self.pad(&object.shape, f, &q, &mut jacobian);
            let depth = (-pad.gap).max(0.0);
            let force = if depth > 0.0 {
                normal_force(object, depth, self.depth[f], f64::from(h))
            } else {
                0.0
            };
            self.depth[f] = depth;
            state.nearness[f] = nearness(pad.gap as f32, object.approach_m);
            state.normal_n[f] = force as f32;
            for (j, load) in state.load_n.iter_mut().enumerate() {
                if self.fingertip_of_joint[j] == f {
                    let direction = jacobian[j].normalize_or_zero();
                    *load = (force * along(pad.normal, direction, object.friction)).abs() as f32;
                }
            }
        }
        state
    }
}

/// The surface's push along a pad's motion `direction` (a unit vector, or zero for a joint that
/// does not move the pad) per newton of normal force, signed the way the `normal` pushes: the
/// normal's component, and the friction (`friction` per newton) against the part of the motion
/// that slides over the surface.
fn along(normal: DVec3, direction: DVec3, friction: f32) -> f64 {
    let cos = normal.dot(direction);
    if cos == 0.0 {
        return 0.0;
    }
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    cos + cos.signum() * f64::from(friction.max(0.0)) * sin
}

/// The surface's normal force at `depth` metres that was `previous_depth` a step of `h` seconds
/// ago, newtons: the spring, plus the damping while the pad goes in; never a pull.
///
/// The spring is `k d / (1 - d / s)` for a depth `d` of an object squashed flat at `s`
/// ([`Shape::squash_depth`]): `k d` for a shallow press, unbounded towards `s`. A crude stand-in
/// for a foam's densification (its stress rising steeply once the cells collapse: Gibson and
/// Ashby, "Cellular Solids", 1997, chapter 5); what matters here is that a pad never presses
/// through a soft object's middle, where its surface would push it on and out the other side.
/// A rigid object's depths are far from `s`, so it stays linear.
fn normal_force(object: &ShapeObject, depth: f64, previous_depth: f64, h: f64) -> f64 {
    let left = (1.0 - depth / object.shape.squash_depth()).max(MIN_SQUASH_LEFT);
    let spring = f64::from(object.stiffness_n_per_m) * depth / left;
    let rate = if h > 0.0 {
        (depth - previous_depth) / h
    } else {
        0.0
    };
    (spring + f64::from(object.damping_n_s_per_m) * rate).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_revo2_profile_fits_the_simulator_and_maps_travel_as_the_node_does() {
        let k = Pads::revo2().unwrap();
        assert_eq!(k.fingertip_of_joint, [0, 0, 1, 2, 3, 4]);
        // The node: per mille / 1000 is the normalised position, 0 = open (0 rad) .. 1 = closed
        // (pi/2 rad) in the shipped profile.
        let q = k.angles(&[0.0, 250.0, 500.0, 750.0, 1000.0, 1000.0]);
        let expected = [0.0, 0.25, 0.5, 0.75, 1.0, 1.0].map(|n| n * std::f64::consts::FRAC_PI_2);
        for (a, e) in q.iter().zip(expected) {
            assert!((a - e).abs() < 1e-6, "{q:?}");
        }
        assert!(k.pad_radius.iter().all(|&r| r > 0.0));
    }

    #[test]
    fn a_profile_without_the_revo2s_joints_is_refused_by_name() {
        let allegro = HandProfile::builtin("allegro").unwrap();
        let err = Pads::of(&allegro).unwrap_err();
        assert!(err.contains("allegro") && err.contains("joints"), "{err}");
    }

    #[test]
    fn distances_and_normals_of_a_sphere_and_a_box() {
        let sphere = Shape::Sphere {
            centre: [0.0, 0.1, 0.0],
            radius: 0.02,
        };
        // (The shapes are in f32: micrometre tolerances.)
        let (d, n) = sphere.distance(DVec3::new(0.0, 0.1, 0.05));
        assert!(
            (d - 0.03).abs() < 1e-6 && n.abs_diff_eq(DVec3::Z, 1e-6),
            "{d} {n}"
        );
        let (d, n) = sphere.distance(DVec3::new(0.01, 0.1, 0.0));
        assert!(
            (d + 0.01).abs() < 1e-6 && n.abs_diff_eq(DVec3::X, 1e-6),
            "{d} {n}"
        );

        let bar = Shape::Box {
            centre: [0.0, 0.0, 0.0],
            half_extents: [0.05, 0.01, 0.02],
        };
        // Over a face, past an edge, and inside near the -Y face.
        let (d, n) = bar.distance(DVec3::new(0.0, 0.0, -0.03));
        assert!(
            (d - 0.01).abs() < 1e-7 && n.abs_diff_eq(-DVec3::Z, 1e-7),
            "{d} {n}"
        );
        let (d, n) = bar.distance(DVec3::new(0.0, 0.013, 0.024));
        assert!((d - 0.005).abs() < 1e-7, "{d}");
        assert!(n.abs_diff_eq(DVec3::new(0.0, 0.6, 0.8), 1e-7), "{n}");
        let (d, n) = bar.distance(DVec3::new(0.01, -0.008, 0.0));
        assert!(
            (d + 0.002).abs() < 1e-7 && n.abs_diff_eq(-DVec3::Y, 1e-7),
            "{d} {n}"
        );
    }

    #[test]
    fn a_soft_object_stiffens_towards_its_middle_and_stays_finite_past_it() {
        let sponge = ShapeObject::ball(300.0);
        let at = |depth: f64| normal_force(&sponge, depth, depth, 0.0005);
        assert!((at(0.001) - 0.3 / 0.975).abs() < 1e-6);
        assert!(at(0.03) > 3.0 * 300.0 * 0.03, "{}", at(0.03));
        for depth in [0.0399, 0.04, 0.05] {
            let force = at(depth);
            assert!(force.is_finite() && force > 1e3, "{depth}: {force}");
        }
    }

    #[test]
    fn the_surface_force_never_pulls() {
        let object = ShapeObject {
            damping_n_s_per_m: 100.0,
            ..ShapeObject::ball(1000.0)
        };
        // Going in: spring plus damping; coming out fast: no pull. The ball (40 mm radius)
        // 2 mm deep has 5 % of its squash depth gone: the spring is 1 / 0.95 of k d.
        let h = 0.0005;
        let spring = 2.0 / 0.95;
        assert!((normal_force(&object, 0.002, 0.001, h) - (spring + 200.0)).abs() < 1e-6);
        assert_eq!(normal_force(&object, 0.001, 0.002, h), 0.0);
        assert!((normal_force(&object, 0.002, 0.002, h) - spring).abs() < 1e-6);
    }
}
