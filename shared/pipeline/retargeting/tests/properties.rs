//! Property tests of the retargeting pipeline's glove map (mode `joint`; the fingertip modes'
//! properties are in the solver's tests).

#![allow(clippy::unwrap_used)]

use proptest::prelude::*;
use teleop_hand_profile::{HandProfile, RetargetMode};
use teleop_retargeting::{
    Calibration, Curve, FingerCalibration, GloveInput, JointConfig, OneEuroParams, RetargetConfig,
    Retargeter, RotationCalibration,
};

/// One of the shipped profiles.
fn profile() -> impl Strategy<Value = HandProfile> {
    prop::sample::select(HandProfile::builtin_names().collect::<Vec<_>>())
        .prop_map(|name| HandProfile::builtin(name).unwrap())
}

const MS: u64 = 1_000_000;

fn curve() -> impl Strategy<Value = Curve> {
    prop_oneof![
        Just(Curve::Linear),
        (0.05f32..5.0).prop_map(|gamma| Curve::Gamma { gamma }),
        // interior points: sorted distinct x in (0, 1), sorted y in [0, 1]
        (
            prop::collection::btree_set(1u32..999, 0..5),
            prop::collection::vec(0.0f32..=1.0, 7)
        )
            .prop_map(|(xs, mut ys)| {
                let n = xs.len() + 2;
                ys.truncate(n);
                ys.sort_by(f32::total_cmp);
                let mut points = vec![[0.0, ys[0]]];
                for (i, x) in xs.iter().enumerate() {
                    points.push([*x as f32 / 1000.0, ys[i + 1]]);
                }
                points.push([1.0, ys[n - 1]]);
                Curve::Piecewise { points }
            }),
    ]
}

fn joint() -> impl Strategy<Value = JointConfig> {
    (curve(), 0.0f32..0.9, 0.05f32..1.0).prop_map(|(curve, a, w)| {
        let min = a;
        let max = (a + w).min(1.0);
        JointConfig { curve, min, max }
    })
}

/// A profile and a configuration with a random shaping for every one of its joints.
fn config() -> impl Strategy<Value = (HandProfile, RetargetConfig)> {
    (
        profile(),
        (0.01f32..50.0, 0.0f32..10.0, 0.01f32..50.0),
        0.0f32..=0.2,
        0.01f32..100.0,
        prop::collection::vec(joint(), 24),
    )
        .prop_map(
            |(profile, (min_cutoff_hz, beta, d_cutoff_hz), deadband, max_speed, joints)| {
                let joints = profile
                    .joint_names()
                    .map(String::from)
                    .zip(joints)
                    .collect();
                let cfg = RetargetConfig {
                    filter: OneEuroParams {
                        min_cutoff_hz,
                        beta,
                        d_cutoff_hz,
                    },
                    deadband,
                    max_speed,
                    joints,
                    mode: Some(RetargetMode::Joint),
                    ..RetargetConfig::default()
                };
                (profile, cfg)
            },
        )
}

/// A valid calibration; `forward` forces open > closed and outer > inner (the glove's convention).
fn calibration(forward: bool) -> impl Strategy<Value = Calibration> {
    let pair = move || {
        (0u16..=1000, 0u16..=1000)
            .prop_filter("span >= 50", |(a, b)| a.abs_diff(*b) >= 50)
            .prop_map(move |(a, b)| {
                if forward {
                    (a.max(b), a.min(b))
                } else {
                    (a, b)
                }
            })
    };
    (prop::array::uniform5(pair()), pair()).prop_map(|(f, (outer, inner))| Calibration {
        fingers: f.map(|(open, closed)| FingerCalibration { open, closed }),
        thumb_rotation: RotationCalibration { inner, outer },
        operator: None,
    })
}

/// Every target finite, inside its configured range and (in radians) inside the profile's
/// limits; every coupled joint at `ratio × its leader` unless a limit cut it.
fn check(profile: &HandProfile, cfg: &RetargetConfig, pos: &[f32]) -> Result<(), TestCaseError> {
    prop_assert_eq!(pos.len(), profile.joints.len());
    for (j, (p, joint)) in pos.iter().zip(&profile.joints).enumerate() {
        prop_assert!(p.is_finite(), "joint {j} not finite: {pos:?}");
        let jc = cfg.joint(&joint.name);
        prop_assert!(
            *p >= jc.min && *p <= jc.max,
            "joint {j} = {p} outside [{}, {}]",
            jc.min,
            jc.max
        );
        let q = joint.radians(*p);
        prop_assert!(
            q >= joint.lower - 1e-5 && q <= joint.upper + 1e-5,
            "{} = {q} rad outside [{}, {}]",
            joint.name,
            joint.lower,
            joint.upper
        );
        if let Some(c) = joint.coupling {
            let leader = &profile.joints[c.to];
            let want = joint.clamp(c.ratio * leader.radians(pos[c.to]));
            let cut = jc.min > 0.0 || jc.max < 1.0;
            if !cut {
                prop_assert!((q - want).abs() < 1e-4, "{}: {q} vs {want}", joint.name);
            }
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// (1) Any raw values and any timestamps (sorted or not): finite, inside limits.
    #[test]
    fn outputs_finite_and_within_limits(
        (profile, cfg) in config(),
        cal in calibration(false),
        samples in prop::collection::vec((any::<u64>(), any::<[u16; 6]>()), 1..200),
        sort in any::<bool>(),
        dense in any::<bool>(),
    ) {
        let mut samples = samples;
        if dense {
            // small, realistic steps (possibly repeated) from an arbitrary start
            let start = samples[0].0 / 2;
            let mut t = start;
            for s in &mut samples {
                t = t.saturating_add(s.0 % (3 * MS));
                s.0 = t;
            }
        }
        if sort {
            samples.sort_by_key(|s| s.0);
        }
        let mut rt = Retargeter::new(cfg.clone(), cal, &profile).unwrap();
        prop_assert!(rt.hold().is_none());
        let n = profile.joints.len() as u8;
        for (i, (t_ns, raw)) in samples.iter().enumerate() {
            let out = rt.step(&GloveInput { t_ns: *t_ns, raw: *raw });
            check(&profile, &cfg, out.positions())?;
            prop_assert!(!out.held);
            prop_assert!(out.clamped <= n && out.slew_limited <= n);
            prop_assert_eq!(out.max_speed, cfg.max_speed);
            let held = rt.hold().unwrap();
            prop_assert!(held.held);
            prop_assert_eq!(held.position, out.position);
            if i % 50 == 49 {
                rt.reset();
            }
        }
    }

    /// (2) Monotone in finger flexion: more flexed (smaller raw) -> every joint that channel
    /// drives (directly with a positive gain, or through a coupling) is >= at every step.
    #[test]
    fn monotone_in_flexion(
        (profile, cfg) in config(),
        cal in calibration(true),
        raw_b in any::<[u16; 6]>(),
        finger in 0usize..5,
        less in 1u16..=1000,
        steps in 1usize..300,
        t0 in 0u64..1_000_000_000_000,
    ) {
        let mut raw_a = raw_b;
        raw_a[finger] = raw_b[finger].saturating_sub(less);
        let driven = |j: usize| {
            profile.joints[j].glove.channels.iter().any(|&(c, g)| c == finger && g > 0.0)
        };
        let joints: Vec<usize> = (0..profile.joints.len())
            .filter(|&j| match profile.joints[j].coupling {
                Some(c) => driven(c.to) && c.ratio > 0.0,
                None => driven(j),
            })
            .collect();
        let mut a = Retargeter::new(cfg.clone(), cal, &profile).unwrap();
        let mut b = Retargeter::new(cfg, cal, &profile).unwrap();
        for k in 0..steps as u64 {
            let t_ns = t0 + k * MS;
            let oa = a.step(&GloveInput { t_ns, raw: raw_a });
            let ob = b.step(&GloveInput { t_ns, raw: raw_b });
            for &j in &joints {
                prop_assert!(
                    oa.position[j] >= ob.position[j],
                    "step {k} {}: {} < {}", profile.joints[j].name, oa.position[j], ob.position[j]
                );
            }
        }
    }

    /// (3) The filter converges: after an arbitrary history, constant input for
    /// 3 s at 1 kHz lands within deadband + 1e-3 of the curve's (clamped) value.
    #[test]
    fn converges_to_curve_value(
        (profile, cfg) in config(),
        cal in calibration(false),
        history in prop::collection::vec(any::<[u16; 6]>(), 1..100),
        raw in any::<[u16; 6]>(),
        min_cutoff_hz in 0.5f32..20.0,
        max_speed in 1.0f32..20.0,
    ) {
        let mut cfg = cfg;
        cfg.filter.min_cutoff_hz = min_cutoff_hz;
        cfg.max_speed = max_speed;
        let mut rt = Retargeter::new(cfg.clone(), cal, &profile).unwrap();
        let mut t_ns = 0;
        for h in &history {
            t_ns += 10 * MS;
            rt.step(&GloveInput { t_ns, raw: *h });
        }
        let mut out = None;
        for _ in 0..3000 {
            t_ns += MS;
            out = Some(rt.step(&GloveInput { t_ns, raw }));
        }
        let out = out.unwrap();
        let closure = cal.closure(&raw);
        for (j, joint) in profile.joints.iter().enumerate() {
            if joint.coupling.is_some() {
                continue; // checked against its leader by `check`
            }
            let jc = cfg.joint(&joint.name);
            let n = joint.glove.offset
                + joint.glove.channels.iter().map(|&(c, g)| g * closure[c]).sum::<f32>();
            let expect = jc.curve.apply(n).clamp(jc.min, jc.max);
            let err = (out.position[j] - expect).abs();
            prop_assert!(
                err <= cfg.deadband + 1e-3,
                "joint {j}: {} vs {expect} (deadband {})", out.position[j], cfg.deadband
            );
        }
    }
}

/// Fresh retargeters on a constant input: the output equals the clamped curve value at once.
#[test]
fn constant_input_from_start_is_exact() {
    let cfg = RetargetConfig {
        mode: Some(RetargetMode::Joint),
        ..RetargetConfig::default()
    };
    let revo2 = HandProfile::builtin("revo2").unwrap();
    let mut rt = Retargeter::new(cfg, Calibration::default(), &revo2).unwrap();
    for k in 0..3000 {
        let out = rt.step(&GloveInput {
            t_ns: k * MS,
            raw: [250, 500, 750, 1000, 0, 600],
        });
        assert_eq!(out.positions(), [1.0, 0.4, 0.0, 0.25, 0.5, 0.75]);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// The fingertip modes: any raw glove values (the whole u16 range, any calibration-free
    /// input) give finite angles within every joint's limits, couplings kept.
    #[test]
    fn fingertip_modes_stay_finite_and_within_the_limits(
        profile in profile(),
        pinch in any::<bool>(),
        raws in prop::collection::vec(prop::array::uniform6(any::<u16>()), 1..30),
    ) {
        let mode = if pinch { RetargetMode::Pinch } else { RetargetMode::Vector };
        let cfg = RetargetConfig { mode: Some(mode), ..RetargetConfig::default() };
        let mut rt = Retargeter::new(cfg, Calibration::default(), &profile).unwrap();
        for (k, raw) in raws.iter().enumerate() {
            let out = rt.step(&GloveInput { t_ns: k as u64 * 3 * MS, raw: *raw });
            for (j, joint) in profile.joints.iter().enumerate() {
                let q = joint.radians(out.position[j]);
                prop_assert!(q.is_finite(), "{}: {q}", joint.name);
                prop_assert!(
                    q >= joint.lower - 1e-4 && q <= joint.upper + 1e-4,
                    "{}: {q} outside [{}, {}]", joint.name, joint.lower, joint.upper
                );
                if let Some(c) = joint.coupling {
                    let leader = profile.joints[c.to].radians(out.position[c.to]);
                    prop_assert!((q - joint.clamp(c.ratio * leader)).abs() < 1e-4, "{}", joint.name);
                }
            }
        }
    }
}
