//! A robot hand posed from its profile, for drawing.

use glam::Vec3;
use teleop_hand_profile::HandProfile;

use crate::{Chains, Skeleton};

/// A robot hand drawn from its profile's kinematics (`teleop_hand_profile`): each finger is a
/// chain from its base pose (`base`, `base_rpy`); each link translates by its `origin` from the
/// previous frame, then turns by `ratio ×` its joint's angle about its `axis`; the fingertip is
/// the `tip` offset in the last link's frame. Posed from joint angles in radians, in the
/// profile's joint order.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotHand {
    profile: HandProfile,
    /// Where the profile came from (a file, a recording, or compiled in), for display.
    source: String,
    /// The fingers' chains.
    chains: Chains,
    /// The finger of each fingertip sensor, in `hand/tactile` order.
    tip_fingers: Vec<usize>,
    /// The fingers whose base outlines the palm, ordered around the wrist (thumb side first).
    palm: Vec<usize>,
}

impl RobotHand {
    /// The hand of `profile`; `source` says where it came from.
    pub fn new(profile: HandProfile, source: impl Into<String>) -> Self {
        let chains = Chains::new(&profile);
        // Finger names are unique (the loader checks), so a fingertip's name finds its finger.
        let tip_fingers = profile
            .fingertips()
            .filter_map(|tip| profile.fingers.iter().position(|f| f.name == tip.name))
            .collect();
        // The palm: the bases in front of the wrist, by their angle around it from the thumb
        // side (-X) to the little finger side (+X). A chain behind the wrist (the Shadow Hand's
        // wrist joints) is drawn on its own.
        let mut palm: Vec<(f32, usize)> = profile
            .fingers
            .iter()
            .enumerate()
            .filter(|(_, f)| f.base[1] > 0.0)
            .map(|(i, f)| (f.base[0].atan2(f.base[1]), i))
            .collect();
        palm.sort_by(|a, b| a.0.total_cmp(&b.0));
        Self {
            profile,
            source: source.into(),
            chains,
            tip_fingers,
            palm: palm.into_iter().map(|(_, i)| i).collect(),
        }
    }

    /// The builtin profile of a contract hand model id (`hand_model` fields), if one is
    /// compiled in.
    pub fn builtin_for_model(model_id: u8) -> Option<Self> {
        HandProfile::builtin_for_model(model_id).map(|p| {
            let source = format!("builtin `{}`", p.name);
            Self::new(p, source)
        })
    }

    /// The profile.
    pub fn profile(&self) -> &HandProfile {
        &self.profile
    }

    /// Where the profile came from.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The fingers' chains (fingertips, pads and their Jacobians).
    pub fn chains(&self) -> &Chains {
        &self.chains
    }

    /// The finger index of each fingertip sensor, in `hand/tactile` order.
    pub fn tip_fingers(&self) -> &[usize] {
        &self.tip_fingers
    }

    /// Every joint at its `open` angle, radians.
    pub fn open_angles(&self) -> Vec<f32> {
        self.profile.joints.iter().map(|j| j.open).collect()
    }

    /// The hand at joint angles in radians (profile joint order; missing joints rest at their
    /// `open` angle, angles are clamped to the limits and NaN counts as open).
    pub fn pose(&self, radians: &[f32]) -> Skeleton {
        let angles: Vec<f32> = self
            .profile
            .joints
            .iter()
            .enumerate()
            .map(|(i, j)| j.clamp(radians.get(i).copied().unwrap_or(j.open)))
            .collect();
        let q: Vec<f64> = angles.iter().map(|&a| f64::from(a)).collect();
        let fingers: Vec<Vec<Vec3>> = (0..self.profile.fingers.len())
            .map(|f| {
                let mut points = Vec::new();
                self.chains
                    .points(f, &q, |p| push_distinct(&mut points, p.as_vec3()));
                points
            })
            .collect();
        let mut outline = vec![Vec3::ZERO];
        outline.extend(self.palm.iter().map(|&i| fingers[i][0]));
        outline.push(Vec3::ZERO);
        Skeleton {
            wrist: Vec3::ZERO,
            palm: if self.palm.is_empty() {
                vec![]
            } else {
                vec![outline]
            },
            fingers,
        }
    }
}

/// Appends `p` unless it is where the chain already is (a link that only turns).
fn push_distinct(points: &mut Vec<Vec3>, p: Vec3) {
    if points.last().is_none_or(|last| last.distance(p) > 1e-7) {
        points.push(p);
    }
}
