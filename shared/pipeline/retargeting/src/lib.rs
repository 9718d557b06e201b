//! Pure retargeting from the EH55BF1 exoskeleton glove to any robot hand a
//! [`HandProfile`] describes (the Revo2, the Allegro Hand, the Shadow Hand).
//!
//! # What this crate owns
//!
//! Everything between a raw glove sample and normalised joint targets in the
//! hand's joint order: the operator [`Calibration`] profile, the profile's
//! glove → joint map (channels, gains, offset), per-joint response
//! [`Curve`]s, One Euro filtering, deadband, position limits, slew limiting
//! and coupled joints ([`RetargetConfig`], [`Retargeter`]). Joint sets are
//! sized at run time up to [`MAX_JOINTS`]; a step allocates nothing.
//!
//! It does **no I/O and no IPC**: no files, no clocks, no threads. It takes
//! strings (TOML text plus an origin label for messages) and timestamps
//! supplied by the caller. It must not depend on iceoryx2, on the message
//! crate (`teleop-msgs`) or on any runtime/transport crate; the nodes convert
//! between their messages and [`GloveInput`] / [`JointTargets`]. The hand
//! comes from `teleop-hand-profile`; no hand is named in this crate.
//!
//! # Conventions
//!
//! Glove order (raw input, `u16`, nominally `0..=1000`, any value accepted and
//! clamped): `[little, ring, middle, index, thumb, thumb_rotation]`
//! ([`GLOVE_CHANNEL_NAMES`]). For the five fingers 0 = fully bent and 1000 =
//! fully open; for `thumb_rotation` 0 = innermost (toward the palm) and 1000 =
//! outermost.
//!
//! Output: the profile's joint order, normalised to `[0, 1]` with 0 = the
//! joint's `open` angle and 1 = its `closed` angle (the node turns these into
//! radians when the profile's `command_units` asks for it).
//!
//! # Pipeline (per driven joint, in [`Retargeter::step`])
//!
//! 1. each glove channel's closure from the [`Calibration`]:
//!    `(open - raw) / (open - closed)` (thumb rotation:
//!    `(outer - raw) / (outer - inner)`), clamped to `[0, 1]`;
//! 2. the profile's map: `offset + Σ gain × closure`, then the joint's
//!    [`Curve`] (which clamps to `[0, 1]`);
//! 3. One Euro filter (`dt` from consecutive stamps, capped at
//!    [`MAX_STEP_DT_S`]; non-increasing stamps count as no time elapsed);
//! 4. deadband: changes smaller than `deadband` are ignored;
//! 5. clamp to the joint's `[min, max]` (counted in [`JointTargets::clamped`]);
//! 6. slew limit to `max_speed * dt` from the previous output (counted in
//!    [`JointTargets::slew_limited`]).
//!
//! A coupled joint (the Shadow Hand's J1) is then set to `ratio ×` its
//! leader's angle, clamped to its own limits. The first step (and the first
//! after [`Retargeter::reset`]) jumps straight to the value. Outputs are
//! finite and within limits for any input.
//!
//! # Calibration profile (TOML)
//!
//! One table per glove finger plus `[thumb_rotation]`, all required, and an
//! optional `[operator]` table: the operator's thumb as `teleop calibrate`'s
//! pinch step fitted it ([`Calibration::with_pinches`]), in millimetres and
//! degrees in the hand frame of `teleop_kinematics` (the scales multiply the
//! default hand's thumb joint range and lengths). Without it the operator is
//! the default hand ([`Calibration::operator_hand`]). Every key of a table is
//! required, unknown keys are rejected and the operator's values must lie in
//! the human range ([`teleop_kinematics::ThumbParams::check`]):
//!
//! ```
//! let text = r#"
//! [little]
//! open = 980
//! closed = 40
//!
//! [ring]
//! open = 970
//! closed = 60
//!
//! [middle]
//! open = 990
//! closed = 20
//!
//! [index]
//! open = 960
//! closed = 30
//!
//! [thumb]
//! open = 900
//! closed = 200
//!
//! [thumb_rotation]
//! inner = 30
//! outer = 970
//!
//! [operator]
//! thumb_base_mm = [-24.1, 27.3, -10.6]  # the thumb's CMC joint, hand frame
//! thumb_direction_deg = 38.2            # the relaxed thumb, from the fingers towards the thumb side
//! opposition_deg = 84.5                 # its turn under the palm at full opposition
//! thumb_flexion_scale = 1.04
//! thumb_length_scale = 1.02
//! "#;
//! let cal = teleop_retargeting::Calibration::from_toml_str(text, "calibration.toml")?;
//! assert_eq!(cal.fingers[1].closed, 60);
//! assert_eq!(teleop_retargeting::Calibration::from_toml_str(&cal.to_toml_string(), "x")?, cal);
//! assert!((cal.operator_hand().opposition_rad - 84.5f32.to_radians()).abs() < 1e-6);
//! # Ok::<(), teleop_retargeting::ConfigError>(())
//! ```
//!
//! # Retargeting configuration (TOML)
//!
//! Every key is optional (the defaults are shown below); unknown keys are
//! rejected. `joints` is a table keyed by the profile's joint names; joints
//! left out use the defaults (linear curve, limits `[0, 1]`):
//!
//! ```
//! let text = r#"
//! mode = "joint"       # joint | vector | pinch; default: the hand profile's [retarget] mode
//! deadband = 0.005     # normalised
//! max_speed = 3.0      # normalised units per second, per joint
//!
//! [filter]             # One Euro filter, normalised units
//! min_cutoff_hz = 1.5
//! beta = 0.5
//! d_cutoff_hz = 1.0
//!
//! [joints.index]
//! curve = { kind = "gamma", gamma = 0.8 }
//!
//! [joints.thumb_abduct]
//! min = 0.1
//! max = 0.9
//! curve = { kind = "piecewise", points = [[0, 0], [0.5, 0.3], [1, 1]] }
//! "#;
//! let cfg = teleop_retargeting::RetargetConfig::from_toml_str(text, "retarget.toml")?;
//! assert_eq!(cfg.joint("index").curve, teleop_retargeting::Curve::Gamma { gamma: 0.8 });
//!
//! let revo2 = teleop_retargeting::HandProfile::builtin("revo2").expect("shipped profile");
//! let calibration = teleop_retargeting::Calibration::default();
//! let mut rt = teleop_retargeting::Retargeter::new(cfg, calibration, &revo2)?;
//! assert!(rt.hold().is_none());
//! let out = rt.step(&teleop_retargeting::GloveInput { t_ns: 0, raw: [1000; 6] });
//! assert_eq!(out.position[2], 0.0); // index open
//! assert_eq!(out.position[1], 0.1); // thumb_abduct clamped to its min
//! assert!(rt.hold().is_some_and(|h| h.held));
//! # Ok::<(), teleop_retargeting::ConfigError>(())
//! ```
//!
//! Errors ([`ConfigError`]) display as `origin: field: reason`, e.g.
//! `calibration.toml: [ring]: open (500) and closed (480) are only 20 apart; need at least 50`;
//! TOML syntax and shape errors keep toml's line and column.

mod calibration;
mod config;
mod error;
pub mod eval;
mod filter;
mod retargeter;
mod solver;

pub use calibration::{
    Calibration, FingerCalibration, RotationCalibration, GLOVE_CHANNEL_NAMES, GLOVE_RAW_MAX,
    MIN_CALIBRATION_SPAN,
};
pub use config::{
    Curve, FingertipConfig, JointConfig, OneEuroParams, RetargetConfig, MAX_DEADBAND,
};
pub use error::{ConfigError, CALIBRATION_ORIGIN, POSES_ORIGIN, RETARGET_ORIGIN};
pub use retargeter::{GloveInput, JointTargets, Retargeter, MAX_STEP_DT_S};
pub use solver::{SolveReport, Solver, MAX_VECTORS};
pub use teleop_hand_profile::{HandProfile, RetargetMode, MAX_JOINTS};

/// Number of glove channels (little, ring, middle, index, thumb, thumb_rotation).
pub const GLOVE_CHANNELS: usize = 6;
