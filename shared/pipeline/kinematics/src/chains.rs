//! Forward kinematics of a profile's finger chains in `f64`, with each pad's Jacobian: what the
//! retargeting solver evaluates many times per glove sample, so nothing here allocates after
//! [`Chains::new`].

use glam::{DQuat, DVec3};
use teleop_hand_profile::{HandProfile, MAX_JOINTS};

#[derive(Debug, Clone, Copy, PartialEq)]
struct ChainLink {
    joint: Option<usize>,
    ratio: f64,
    axis: DVec3,
    origin: DVec3,
}

/// One finger's chain, as the profile describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct Chain {
    base: DVec3,
    rotation: DQuat,
    links: Vec<ChainLink>,
    tip: DVec3,
    pad: DVec3,
    /// Radius of the fingertip's pad, metres.
    pub pad_radius: f64,
    /// The operator finger it follows (`GLOVE_FINGERS` index), if any.
    pub operator: Option<usize>,
}

/// Every finger chain of a hand profile: fingertip and pad positions (metres, hand frame) from
/// joint angles (radians, the profile's joint order; a missing angle counts as 0), and the pads'
/// Jacobians. Angles are used as given: clamping to the limits is the caller's business.
#[derive(Debug, Clone, PartialEq)]
pub struct Chains {
    chains: Vec<Chain>,
}

impl Chains {
    /// The chains of `profile`'s fingers, in its finger order.
    pub fn new(profile: &HandProfile) -> Self {
        let v = |a: [f32; 3]| DVec3::new(f64::from(a[0]), f64::from(a[1]), f64::from(a[2]));
        let chains = profile
            .fingers
            .iter()
            .map(|f| {
                let [roll, pitch, yaw] = f.base_rpy.map(f64::from);
                Chain {
                    base: v(f.base),
                    // URDF convention: roll about x, then pitch about y, then yaw about z (fixed
                    // axes).
                    rotation: DQuat::from_rotation_z(yaw)
                        * DQuat::from_rotation_y(pitch)
                        * DQuat::from_rotation_x(roll),
                    links: f
                        .links
                        .iter()
                        .map(|l| ChainLink {
                            joint: l.joint,
                            ratio: f64::from(l.ratio),
                            axis: v(l.axis),
                            origin: v(l.origin),
                        })
                        .collect(),
                    tip: v(f.tip),
                    pad: v(f.pad),
                    pad_radius: f64::from(f.pad_radius),
                    operator: f.operator,
                }
            })
            .collect();
        Self { chains }
    }

    /// The chains, in the profile's finger order.
    pub fn chains(&self) -> &[Chain] {
        &self.chains
    }

    /// Walks finger `f`'s chain: `at_link(position, world axis, joint, ratio)` for every link
    /// (after its origin's translation, before its turn); returns the last link's frame.
    fn walk(
        &self,
        f: usize,
        q: &[f64],
        mut at_link: impl FnMut(DVec3, DVec3, Option<usize>, f64),
    ) -> (DVec3, DQuat) {
        let chain = &self.chains[f];
        let mut position = chain.base;
        let mut rotation = chain.rotation;
        for link in &chain.links {
            position += rotation * link.origin;
            at_link(position, rotation * link.axis, link.joint, link.ratio);
            let angle = link.joint.map_or(0.0, |j| q.get(j).copied().unwrap_or(0.0)) * link.ratio;
            rotation *= DQuat::from_axis_angle(link.axis, angle);
        }
        (position, rotation)
    }

    /// Calls `point` with the chain's base, each link's position and the fingertip, in order.
    pub fn points(&self, f: usize, q: &[f64], mut point: impl FnMut(DVec3)) {
        point(self.chains[f].base);
        let (position, rotation) = self.walk(f, q, |p, _, _, _| point(p));
        point(position + rotation * self.chains[f].tip);
    }

    /// Finger `f`'s fingertip (the profile's `tip`).
    pub fn tip(&self, f: usize, q: &[f64]) -> DVec3 {
        let (position, rotation) = self.walk(f, q, |_, _, _, _| {});
        position + rotation * self.chains[f].tip
    }

    /// The centre of finger `f`'s pad.
    pub fn pad(&self, f: usize, q: &[f64]) -> DVec3 {
        let (position, rotation) = self.walk(f, q, |_, _, _, _| {});
        position + rotation * self.chains[f].pad
    }

    /// The centre of finger `f`'s pad, and in `jacobian[j]` its derivative by joint `j`'s angle
    /// (zero for the joints that do not move it; joints past [`MAX_JOINTS`] are ignored).
    /// Analytic: a link turning about the world axis `a` at `p` by `ratio ×` the joint's angle
    /// moves the pad by `ratio × a × (pad − p)` per radian.
    pub fn pad_jacobian(&self, f: usize, q: &[f64], jacobian: &mut [DVec3; MAX_JOINTS]) -> DVec3 {
        *jacobian = [DVec3::ZERO; MAX_JOINTS];
        let pad = self.pad(f, q);
        self.walk(f, q, |p, axis, joint, ratio| {
            if let Some(slot) = joint.and_then(|j| jacobian.get_mut(j)) {
                *slot += ratio * axis.cross(pad - p);
            }
        });
        pad
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pad_jacobians_match_finite_differences() {
        for name in HandProfile::builtin_names() {
            let profile = HandProfile::builtin(name).unwrap();
            let chains = Chains::new(&profile);
            // A pose inside the limits away from zero.
            let q: Vec<f64> = profile
                .joints
                .iter()
                .map(|j| f64::from(j.lower + 0.37 * (j.upper - j.lower)))
                .collect();
            let mut jac = [DVec3::ZERO; MAX_JOINTS];
            for f in 0..chains.chains().len() {
                let pad = chains.pad_jacobian(f, &q, &mut jac);
                assert!(pad.abs_diff_eq(chains.pad(f, &q), 1e-12));
                for j in 0..q.len() {
                    let h = 1e-6;
                    let mut up = q.clone();
                    up[j] += h;
                    let mut down = q.clone();
                    down[j] -= h;
                    let numeric = (chains.pad(f, &up) - chains.pad(f, &down)) / (2.0 * h);
                    assert!(
                        numeric.abs_diff_eq(jac[j], 1e-7),
                        "{name} finger {f} joint {j}: {numeric} vs {}",
                        jac[j]
                    );
                }
            }
        }
    }
}
