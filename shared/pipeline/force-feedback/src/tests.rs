//! Unit and property tests of the force-feedback law and its configuration.

use proptest::prelude::*;

use super::*;

/// 1 ms in nanoseconds (1 kHz loop).
const MS: u64 = 1_000_000;

fn revo2() -> HandProfile {
    HandProfile::builtin("revo2").expect("shipped profile")
}

/// The law for the Revo2 profile: glove little <- pinky (fingertip 4, joint 5), ring <- ring
/// (3, 4), middle <- middle (2, 3), index <- index (1, 2), thumb <- thumb (0, thumb_flex 0).
fn law(config: FeedbackConfig) -> ForceFeedback {
    ForceFeedback::new(config, &revo2()).expect("valid config")
}

/// Revo2 fingertip of each glove finger (glove order).
const GLOVE_TO_TACTILE: [usize; GLOVE_FINGERS] = [4, 3, 2, 1, 0];

/// Fresh tactile, all fingertips valid, hand order.
fn fresh(normal_n: [f32; MAX_FINGERTIPS]) -> Tactile {
    Tactile::Fresh(TactileInput {
        normal_n,
        valid: [true; MAX_FINGERTIPS],
    })
}

/// A Revo2 joint-state input (six joints; effort unknown).
fn hand6(commanded: [f32; 6], measured: [f32; 6], current_ma: [f32; 6]) -> HandInput {
    let mut hand = HandInput {
        effort_nm: [f32::NAN; MAX_JOINTS],
        ..HandInput::default()
    };
    hand.commanded[..6].copy_from_slice(&commanded);
    hand.measured[..6].copy_from_slice(&measured);
    hand.current_ma[..6].copy_from_slice(&current_ma);
    hand
}

fn inputs(t_ns: u64, tactile: Tactile, hand: Option<HandInput>) -> Inputs {
    Inputs {
        t_ns,
        tactile,
        hand,
        estop: false,
        operator: None,
        remote: false,
    }
}

/// Hand at rest: no position error, no current.
fn quiet_hand() -> HandInput {
    HandInput::default()
}

/// Runs `steps` steps at 1 kHz starting at `*t`, returns the last output.
fn run(
    ff: &mut ForceFeedback,
    t: &mut u64,
    steps: usize,
    make: impl Fn(u64) -> Inputs,
) -> FeedbackOutput {
    let mut last = None;
    for _ in 0..steps {
        last = Some(ff.step(&make(*t)));
        *t += MS;
    }
    last.expect("at least one step")
}

/// Config without smoothing and with a very fast rate limit, so the output
/// equals the saturated demand from the second step on.
fn direct_config() -> FeedbackConfig {
    FeedbackConfig {
        smoothing_tau_s: 0.0,
        rate_limit_per_s: 1e9,
        max_force: 1000,
        ..FeedbackConfig::default()
    }
}

#[test]
fn defaults_validate_and_match_documented_values() {
    let c = FeedbackConfig::default();
    c.validate().expect("defaults validate");
    assert_eq!(c.contact_threshold_n, 0.3);
    assert_eq!(c.gain_per_n, 250.0);
    assert_eq!(c.max_force, 800);
    assert_eq!(c.rate_limit_per_s, 20_000.0);
    assert_eq!(c.smoothing_tau_s, 0.01);
    assert_eq!(c.stale_ramp_s, 0.1);
    assert_eq!(c.hysteresis, 0.0);
    assert_eq!(c.finger_gain, [1.0; 5]);
    assert!(c.estimate.use_position_error && c.estimate.use_current);
    assert_eq!(c.estimate.position_error_threshold, 0.05);
    assert_eq!(c.estimate.position_gain, 4000.0);
    assert_eq!(c.estimate.current_threshold_ma, 300.0);
    assert_eq!(c.estimate.current_gain_per_ma, 1.0);
    // Empty file = defaults; serialised defaults parse back identically.
    assert_eq!(
        FeedbackConfig::from_toml_str("", "empty.toml").expect("empty"),
        c
    );
    let text = toml::to_string(&c).expect("serialise");
    assert_eq!(
        FeedbackConfig::from_toml_str(&text, "roundtrip.toml").expect("roundtrip"),
        c
    );
    // Partial file: the rest keeps defaults.
    let partial = FeedbackConfig::from_toml_str(
        "max_force = 500\n[estimate]\nuse_current = false\n",
        "p.toml",
    )
    .expect("partial");
    assert_eq!(partial.max_force, 500);
    assert!(!partial.estimate.use_current);
    assert_eq!(partial.gain_per_n, 250.0);
    // PST: 10 counts at rest, 100 per newton; a reading below rest is no force.
    assert_eq!(c.pst.force_n(310), 3.0);
    assert_eq!(c.pst.force_n(0), 0.0);
    let err = FeedbackConfig::from_toml_str("[pst]\ncounts_per_n = 0.0\n", "s.toml")
        .expect_err("zero counts per newton");
    assert!(err.to_string().contains("pst.counts_per_n"), "{err}");
}

#[test]
fn toml_syntax_error_names_origin_and_keeps_line_col() {
    let err =
        FeedbackConfig::from_toml_str("max_force = 800\ngain_per_n = \n", "cfg/feedback.toml")
            .expect_err("syntax error");
    let msg = err.to_string();
    assert!(msg.starts_with("cfg/feedback.toml: "), "{msg}");
    assert!(msg.contains("line 2"), "{msg}");
    assert!(msg.contains("gain_per_n"), "{msg}");
    assert_eq!(err.origin(), "cfg/feedback.toml");
    assert!(matches!(err, ConfigError::Parse { .. }));
}

#[test]
fn toml_unknown_field_is_named() {
    let err =
        FeedbackConfig::from_toml_str("gain_per_N = 1.0\n", "a.toml").expect_err("unknown field");
    let msg = err.to_string();
    assert!(msg.starts_with("a.toml: "), "{msg}");
    assert!(msg.contains("gain_per_N"), "{msg}");

    let err = FeedbackConfig::from_toml_str("[estimate]\ncurrent_gain = 2.0\n", "b.toml")
        .expect_err("unknown nested field");
    let msg = err.to_string();
    assert!(msg.starts_with("b.toml: "), "{msg}");
    assert!(msg.contains("current_gain"), "{msg}");
}

#[test]
fn toml_wrong_type_is_named() {
    let err =
        FeedbackConfig::from_toml_str("max_force = \"lots\"\n", "c.toml").expect_err("wrong type");
    let msg = err.to_string();
    assert!(msg.starts_with("c.toml: "), "{msg}");
    assert!(msg.contains("max_force"), "{msg}");
    assert!(msg.contains("line 1"), "{msg}");
}

#[test]
fn toml_out_of_range_values_name_origin_and_field() {
    let cases = [
        ("max_force = 1200", "max_force"),
        ("max_force = -1", "max_force"),
        ("contact_threshold_n = -0.1", "contact_threshold_n"),
        ("gain_per_n = -1.0", "gain_per_n"),
        ("rate_limit_per_s = 0.0", "rate_limit_per_s"),
        ("rate_limit_per_s = nan", "rate_limit_per_s"),
        ("smoothing_tau_s = inf", "smoothing_tau_s"),
        ("stale_ramp_s = 0.0", "stale_ramp_s"),
        ("hysteresis = -1.0", "hysteresis"),
        ("hysteresis = 800.0", "hysteresis"),
        ("max_force = 30\nhysteresis = 35.0", "hysteresis"),
        ("finger_gain = [1.0, 1.0, 2.5, 1.0, 1.0]", "finger_gain[2]"),
        ("finger_gain = [1.0, 1.0, 1.0, 1.0, -0.5]", "finger_gain[4]"),
        ("[estimate]\nposition_gain = -4.0", "estimate.position_gain"),
        (
            "[estimate]\nposition_error_threshold = -0.1",
            "estimate.position_error_threshold",
        ),
        (
            "[estimate]\ncurrent_threshold_ma = -inf",
            "estimate.current_threshold_ma",
        ),
        (
            "[estimate]\ncurrent_gain_per_ma = nan",
            "estimate.current_gain_per_ma",
        ),
    ];
    for (text, field) in cases {
        let err = FeedbackConfig::from_toml_str(text, "/etc/teleop/feedback.toml").expect_err(text);
        let msg = err.to_string();
        assert!(
            msg.starts_with("/etc/teleop/feedback.toml: "),
            "{text}: {msg}"
        );
        assert!(msg.contains(&format!("`{field}`")), "{text}: {msg}");
        match err {
            ConfigError::Invalid { field: f, .. } => assert_eq!(f, field),
            other => panic!("{text}: expected Invalid, got {other:?}"),
        }
    }
    // Wrong array length is a parse error and still names the field.
    let err =
        FeedbackConfig::from_toml_str("finger_gain = [1.0, 1.0]", "d.toml").expect_err("length");
    assert!(err.to_string().starts_with("d.toml: "), "{err}");
    assert!(err.to_string().contains("finger_gain"), "{err}");
}

#[test]
fn new_rejects_invalid_config_with_in_memory_origin() {
    let bad = FeedbackConfig {
        stale_ramp_s: -1.0,
        ..FeedbackConfig::default()
    };
    let err = ForceFeedback::new(bad, &revo2()).expect_err("invalid");
    assert_eq!(err.origin(), IN_MEMORY_ORIGIN);
    assert!(err.to_string().contains("`stale_ramp_s`"), "{err}");
    // Boundary values are accepted.
    let edge = FeedbackConfig {
        max_force: 0,
        finger_gain: [0.0, 2.0, 0.0, 2.0, 1.0],
        smoothing_tau_s: 0.0,
        contact_threshold_n: 0.0,
        gain_per_n: 0.0,
        ..FeedbackConfig::default()
    };
    edge.validate().expect("edge values valid");
    let edge_max = FeedbackConfig {
        max_force: 1000,
        ..FeedbackConfig::default()
    };
    edge_max.validate().expect("max_force 1000 valid");
}

#[test]
fn first_step_outputs_zero() {
    let mut ff = law(direct_config());
    let out = ff.step(&inputs(123, fresh([20.0; 5]), None));
    assert_eq!(out.force, [0; 5]);
    assert_eq!(out.source, [ContactSource::Tactile; 5]);
    let out = ff.step(&inputs(123 + MS, fresh([20.0; 5]), None));
    assert_eq!(out.force, [1000; 5]);
}

#[test]
fn finger_mapping_tactile() {
    let mut config = direct_config();
    config.contact_threshold_n = 0.0;
    config.gain_per_n = 100.0;
    let mut ff = law(config);
    let mut t = 0;
    // Hand order [thumb, index, middle, ring, pinky].
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, fresh([1.0, 2.0, 3.0, 4.0, 5.0]), None)
    });
    // Glove order [little, ring, middle, index, thumb].
    assert_eq!(out.force, [500, 400, 300, 200, 100]);
    assert_eq!(out.source, [ContactSource::Tactile; 5]);
}

#[test]
fn finger_mapping_estimate() {
    let mut config = direct_config();
    config.estimate.use_current = false;
    config.estimate.position_error_threshold = 0.0;
    config.estimate.position_gain = 10_000.0;
    let mut ff = law(config);
    // Revo2 order [thumb_flex, thumb_abduct, index, middle, ring, pinky];
    // the abduction error must not reach any glove finger.
    let hand = hand6(
        [0.51, 0.9, 0.52, 0.53, 0.54, 0.55],
        [0.5, 0.0, 0.5, 0.5, 0.5, 0.5],
        [0.0; 6],
    );
    let mut t = 0;
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(hand))
    });
    assert_eq!(out.force, [500, 400, 300, 200, 100]);
    assert_eq!(out.source, [ContactSource::PositionError; 5]);
}

#[test]
fn below_threshold_gives_zero() {
    let mut ff = law(FeedbackConfig::default());
    let mut t = 0;
    for _ in 0..1000 {
        let out = ff.step(&inputs(
            t,
            fresh([0.29, 0.0, 0.1, 0.299, -5.0]),
            Some(quiet_hand()),
        ));
        assert_eq!(out.force, [0; 5]);
        assert_eq!(out.source, [ContactSource::None; 5]);
        assert_eq!(out.clamped, 0);
        assert!(!out.stale);
        t += MS;
    }
}

#[test]
fn steady_state_matches_gain() {
    let config = FeedbackConfig::default();
    let (thr, gain) = (config.contact_threshold_n, config.gain_per_n);
    let mut ff = law(config);
    let normals = [0.5, 1.0, 2.0, 2.5, 3.0]; // hand order, all below saturation
    let mut t = 0;
    let out = run(&mut ff, &mut t, 1000, |t| inputs(t, fresh(normals), None));
    for (finger, &tip) in GLOVE_TO_TACTILE.iter().enumerate() {
        let expected = gain * (normals[tip] - thr);
        let got = f32::from(out.force[finger]);
        assert!(
            (got - expected).abs() <= 1.0,
            "finger {finger}: {got} vs {expected}"
        );
    }
    assert_eq!(out.clamped, 0);
}

#[test]
fn saturates_at_max_force_and_counts_clamped() {
    let config = FeedbackConfig::default();
    let max = config.max_force;
    let mut ff = law(config);
    let mut t = 0;
    // Thumb (hand idx 0 -> glove idx 4) below saturation, others far above.
    let out = run(&mut ff, &mut t, 1000, |t| {
        inputs(t, fresh([1.0, 10.0, 10.0, 24.0, 1e30]), None)
    });
    assert_eq!(out.force[..4], [max; 4]);
    assert!(out.force[4] < max);
    assert_eq!(out.clamped, 4);
    // Infinite demand from a huge gain saturates as well.
    let mut ff = law(FeedbackConfig {
        gain_per_n: f32::MAX,
        ..FeedbackConfig::default()
    });
    let out = run(&mut ff, &mut t, 1000, |t| inputs(t, fresh([25.0; 5]), None));
    assert_eq!(out.force, [max; 5]);
    assert_eq!(out.clamped, 5);
}

#[test]
fn rate_limit_bounds_rise_time() {
    for tau in [0.0, 0.01] {
        let config = FeedbackConfig {
            smoothing_tau_s: tau,
            ..FeedbackConfig::default()
        };
        let max = config.max_force;
        let min_rise_s = f64::from(max) / f64::from(config.rate_limit_per_s);
        let per_step = f64::from(config.rate_limit_per_s) * 1e-3;
        let mut ff = law(config);
        let mut prev = 0_i16;
        let mut reached_at = None;
        for k in 0..1000_u64 {
            let out = ff.step(&inputs(k * MS, fresh([25.0; 5]), None));
            let change = f64::from(out.force[0] - prev);
            // Rounding may add at most one unit per step.
            assert!(change <= per_step + 1.0, "step {k}: change {change}");
            prev = out.force[0];
            if out.force == [max; 5] && reached_at.is_none() {
                reached_at = Some(k as f64 * 1e-3);
            }
        }
        let reached = reached_at.expect("reaches max_force");
        assert!(
            reached >= min_rise_s - 1e-9,
            "tau {tau}: reached max after {reached} s < {min_rise_s} s"
        );
    }
}

/// Drives all fingers to max_force with tactile, returns the time reached.
fn saturate(ff: &mut ForceFeedback, t: &mut u64) {
    let max = ff.config().max_force;
    let out = run(ff, t, 500, |t| {
        inputs(t, fresh([25.0; 5]), Some(quiet_hand()))
    });
    assert_eq!(out.force, [max; 5]);
}

/// The hysteresis: a contact force flipping between two neighbouring values (one step of a
/// position-controlled hand's quantised force, 34 units apart here) leaves the force still once
/// it has risen; a larger change is followed, trailing by the hysteresis; light contacts and a
/// contact that ends are passed exactly; without it every flip is followed.
#[test]
fn the_hysteresis_holds_the_force_still_while_the_contact_force_flips_by_one_step() {
    // 0.3 N threshold, 250 units per N: 2.0 N is 425 units, 2.136 N 459.
    let newtons = |demand: f32| 0.3 + demand / 250.0;
    let at = |demand: f32| {
        let mut n = [0.0; MAX_FINGERTIPS];
        n[GLOVE_TO_TACTILE[3]] = newtons(demand);
        fresh(n)
    };
    for hysteresis in [0.0, 35.0] {
        let mut ff = law(FeedbackConfig {
            hysteresis,
            ..direct_config()
        });
        let mut t = 0;
        let index = |ff: &mut ForceFeedback, t: &mut u64, demand: f32| {
            f32::from(run(ff, t, 3, |t| inputs(t, at(demand), None)).force[3])
        };
        // Light contact: passed as it is.
        assert!((index(&mut ff, &mut t, 20.0) - 20.0).abs() <= 1.0);
        // A rise: followed, trailing by the hysteresis.
        let risen = index(&mut ff, &mut t, 459.0);
        assert!((risen - (459.0 - hysteresis)).abs() <= 1.0, "{risen}");
        // The contact force flips by one step and back, over and over.
        let mut seen = vec![];
        for _ in 0..5 {
            seen.push(index(&mut ff, &mut t, 425.0));
            seen.push(index(&mut ff, &mut t, 459.0));
        }
        let swing = seen.iter().copied().fold(f32::MIN, f32::max)
            - seen.iter().copied().fold(f32::MAX, f32::min);
        if hysteresis > 0.0 {
            assert!(swing <= 1.0, "held still: {seen:?}");
        } else {
            assert!(swing >= 33.0, "every flip followed: {seen:?}");
        }
        // A fall of more than the hysteresis is followed, above it by the hysteresis.
        let fallen = index(&mut ff, &mut t, 300.0);
        assert!((fallen - (300.0 + hysteresis)).abs() <= 1.0, "{fallen}");
        // A contact that ends gives no force at all.
        assert_eq!(index(&mut ff, &mut t, 0.0), 0.0);
        // A saturated demand is felt at the saturation, not below it.
        assert_eq!(index(&mut ff, &mut t, 2000.0), 1000.0);
        assert_eq!(index(&mut ff, &mut t, 0.0), 0.0);
        if hysteresis > 0.0 {
            // More demand never gives less force than a demand of the hysteresis itself.
            assert_eq!(index(&mut ff, &mut t, hysteresis), hysteresis);
            assert_eq!(index(&mut ff, &mut t, hysteresis + 5.0), hysteresis);
        }
    }
}

/// What the hysteresis held is forgotten with everything else: after the e-stop, a reset or
/// a stale ramp to zero, a demand gives what it gives a law that never held anything.
#[test]
fn the_hysteresis_starts_afresh_after_an_estop_a_reset_and_a_stale_ramp() {
    let config = FeedbackConfig {
        hysteresis: 35.0,
        ..direct_config()
    };
    let mut index_n = [0.0; MAX_FINGERTIPS];
    index_n[GLOVE_TO_TACTILE[3]] = 0.3 + 100.0 / 250.0;
    let mut fresh_law = law(config.clone());
    let mut t = 0;
    let expected = run(&mut fresh_law, &mut t, 3, |t| {
        inputs(t, fresh(index_n), None)
    })
    .force[3];
    assert_eq!(
        expected, 65,
        "a rise from nothing to 100 trails by the hysteresis"
    );
    let mut high = [0.0; MAX_FINGERTIPS];
    high[GLOVE_TO_TACTILE[3]] = 0.3 + 600.0 / 250.0;
    for how in ["estop", "reset", "stale"] {
        let mut ff = law(config.clone());
        let mut t = 0;
        run(&mut ff, &mut t, 3, |t| inputs(t, fresh(high), None));
        match how {
            "estop" => {
                run(&mut ff, &mut t, 3, |t| Inputs {
                    estop: true,
                    ..inputs(t, fresh(high), None)
                });
            }
            "reset" => ff.reset(),
            _ => {
                let out = run(&mut ff, &mut t, 200, |t| inputs(t, Tactile::Stale, None));
                assert_eq!(out.force, [0; GLOVE_FINGERS], "ramped to zero");
            }
        }
        let out = run(&mut ff, &mut t, 3, |t| inputs(t, fresh(index_n), None));
        assert_eq!(out.force[3], expected, "after {how}");
    }
}

/// The passivity controller inside the law: a saturated push that drives the fingers open
/// generates energy, so the controller (on) cuts it; once the fingers stop, the force climbs
/// back at the controller's recovery rate, slower than the law's rate limit; with the
/// controller off the same motion leaves the force alone.
#[test]
fn the_passivity_controller_cuts_a_push_that_opens_the_finger_and_it_climbs_back_slowly() {
    for mode in [PassivityMode::On, PassivityMode::Off] {
        let config = FeedbackConfig {
            passivity: PassivityConfig {
                mode,
                ..PassivityConfig::default()
            },
            ..FeedbackConfig::default()
        };
        let max = config.max_force;
        let step_limit = config.passivity.recovery_per_s * 0.001;
        let mut ff = law(config);
        let mut t = 0;
        saturate(&mut ff, &mut t);
        // Every finger pushed open at 1 travel/s under full force, sampled every millisecond.
        let at = |t: u64, p: f32| Inputs {
            operator: Some(OperatorInput {
                t_ns: t,
                position: [p; GLOVE_FINGERS],
            }),
            ..inputs(t, fresh([25.0; 5]), Some(quiet_hand()))
        };
        let mut lowest = max;
        for k in 0..40 {
            let out = ff.step(&at(t, 0.5 + k as f32 * 0.001));
            lowest = lowest.min(out.force[3]);
            t += MS;
        }
        if mode == PassivityMode::Off {
            assert_eq!(lowest, max, "off: the push is left alone");
            continue;
        }
        assert_eq!(lowest, 0, "on: the push that throws the finger open is cut");
        // The fingers stop: the force climbs back at the recovery rate.
        let mut before = ff.step(&at(t, 0.54)).force[3];
        let back_ms = (f32::from(max) / step_limit).ceil() as usize + 10;
        for _ in 0..back_ms {
            t += MS;
            let now = ff.step(&at(t, 0.54)).force[3];
            assert!(
                f32::from(now - before) <= step_limit + 1.0,
                "{before} -> {now} in 1 ms"
            );
            before = now;
        }
        assert_eq!(before, max, "back to the law's force");
    }
}

/// Feeds `make` until all forces are 0 (at most 10 s); checks the ramp
/// decreases, is not instantaneous, reports Ramping/stale, and returns the
/// number of steps it took.
fn ramp_steps(ff: &mut ForceFeedback, t: &mut u64, make: impl Fn(u64) -> Inputs) -> usize {
    let max = ff.config().max_force;
    let mut prev = [max; 5];
    for k in 1..=10_000 {
        let out = ff.step(&make(*t));
        *t += MS;
        assert!(out.stale);
        assert_eq!(out.source, [ContactSource::Ramping; 5]);
        for (now, before) in out.force.iter().zip(prev) {
            assert!(*now <= before, "ramp must not increase");
        }
        if k == 1 {
            assert!(
                out.force.iter().all(|&f| f > 0),
                "ramp must not be instantaneous: {:?}",
                out.force
            );
        }
        prev = out.force;
        if out.force == [0; 5] {
            return k;
        }
    }
    panic!("never ramped to zero");
}

#[test]
fn stale_tactile_ramps_to_zero_within_stale_ramp_s() {
    let config = FeedbackConfig::default();
    let ramp_ms = (config.stale_ramp_s * 1000.0).round() as usize;
    let mut ff = law(config);
    let mut t = 0;
    saturate(&mut ff, &mut t);
    // Stale tactile ramps even if the hand state is fresh.
    let steps = ramp_steps(&mut ff, &mut t, |t| {
        inputs(t, Tactile::Stale, Some(quiet_hand()))
    });
    assert!(steps <= ramp_ms + 1, "took {steps} ms");
    assert!(steps >= ramp_ms / 2, "too fast: {steps} ms");
    // Stays at zero and keeps reporting stale.
    let out = run(&mut ff, &mut t, 10, |t| inputs(t, Tactile::Stale, None));
    assert_eq!(out.force, [0; 5]);
    assert!(out.stale);
    // Fresh tactile again: rises from zero, rate limited.
    let out = ff.step(&inputs(t, fresh([25.0; 5]), None));
    assert!(out.force.iter().all(|&f| f <= 21));
    assert!(!out.stale);
}

#[test]
fn absent_tactile_without_hand_ramps_to_zero() {
    let config = FeedbackConfig::default();
    let ramp_ms = (config.stale_ramp_s * 1000.0).round() as usize;
    let mut ff = law(config);
    let mut t = 0;
    // Contact from the position estimate: 4000 * (0.5 - 0.05) saturates.
    let pressing = hand6([1.0; 6], [0.5; 6], [0.0; 6]);
    let out = run(&mut ff, &mut t, 500, |t| {
        inputs(t, Tactile::Absent, Some(pressing))
    });
    assert_eq!(out.force, [800; 5]);
    assert_eq!(out.source, [ContactSource::PositionError; 5]);
    let steps = ramp_steps(&mut ff, &mut t, |t| inputs(t, Tactile::Absent, None));
    assert!(steps <= ramp_ms + 1, "took {steps} ms");
}

#[test]
fn invalid_fingertip_without_hand_ramps_only_that_finger() {
    let mut ff = law(FeedbackConfig::default());
    let mut t = 0;
    saturate(&mut ff, &mut t);
    let tactile = Tactile::Fresh(TactileInput {
        normal_n: [25.0; 5],
        valid: [true, true, false, true, true], // middle fingertip invalid
    });
    let out = run(&mut ff, &mut t, 200, |t| inputs(t, tactile, None));
    assert_eq!(out.force, [800, 800, 0, 800, 800]);
    assert_eq!(out.source[2], ContactSource::Ramping);
    assert_eq!(out.source[0], ContactSource::Tactile);
    assert!(out.stale);
}

#[test]
fn estop_zeroes_at_once_then_restarts_from_zero() {
    let mut ff = law(FeedbackConfig::default());
    let mut t = 0;
    saturate(&mut ff, &mut t);
    let out = ff.step(&Inputs {
        t_ns: t,
        tactile: fresh([25.0; 5]),
        hand: Some(quiet_hand()),
        estop: true,
        operator: None,
        remote: false,
    });
    t += MS;
    assert_eq!(out.force, [0; 5]);
    assert_eq!(out.source, [ContactSource::EStop; 5]);
    assert_eq!(out.clamped, 0);
    // Released: rises again from zero under the rate limit.
    let out = ff.step(&inputs(t, fresh([25.0; 5]), None));
    assert!(out.force.iter().all(|&f| f <= 21), "{:?}", out.force);
}

#[test]
fn invalid_tactile_falls_back_to_position_error_then_current() {
    let mut ff = law(direct_config());
    let invalid = Tactile::Fresh(TactileInput {
        normal_n: [25.0; 5],
        valid: [false; 5],
    });
    let mut hand = quiet_hand();
    // Index joint (2) -> glove index (3): position error 0.15 -> 4000 * 0.10.
    hand.commanded[2] = 0.65;
    hand.measured[2] = 0.5;
    // Middle joint (3) -> glove middle (2): 600 mA (sign ignored) -> 300.
    hand.current_ma[3] = -600.0;
    // Pinky joint (5) -> glove little (0): both; current (500) beats position (200).
    hand.commanded[5] = 0.3;
    hand.measured[5] = 0.2;
    hand.current_ma[5] = 800.0;
    // Thumb abduction (1) is not mapped to any glove finger.
    hand.current_ma[1] = 5000.0;
    let mut t = 0;
    let out = run(&mut ff, &mut t, 3, |t| inputs(t, invalid, Some(hand)));
    assert_eq!(out.force, [500, 0, 300, 400, 0]);
    assert_eq!(
        out.source,
        [
            ContactSource::Current,
            ContactSource::None,
            ContactSource::Current,
            ContactSource::PositionError,
            ContactSource::None,
        ]
    );

    // Position error alone when current estimation is off.
    let mut config = direct_config();
    config.estimate.use_current = false;
    let mut ff = law(config);
    let out = run(&mut ff, &mut t, 3, |t| inputs(t, invalid, Some(hand)));
    assert_eq!(out.force, [200, 0, 0, 400, 0]);
    assert_eq!(out.source[0], ContactSource::PositionError);
}

#[test]
fn non_finite_tactile_counts_as_invalid() {
    let mut config = direct_config();
    config.estimate.use_position_error = false;
    let mut ff = law(config);
    let mut hand = quiet_hand();
    hand.current_ma[..6].copy_from_slice(&[400.0, 0.0, f32::NAN, f32::INFINITY, 400.0, 400.0]);
    let tactile = fresh([f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1.3, 1.3]);
    let mut t = 0;
    let out = run(&mut ff, &mut t, 3, |t| inputs(t, tactile, Some(hand)));
    // little, ring: tactile 250; middle: -inf tactile -> current inf -> zero;
    // index: inf tactile -> current NaN -> zero; thumb: NaN tactile -> current 100.
    assert_eq!(out.force, [250, 250, 0, 0, 100]);
    assert_eq!(
        out.source,
        [
            ContactSource::Tactile,
            ContactSource::Tactile,
            ContactSource::None,
            ContactSource::None,
            ContactSource::Current,
        ]
    );
}

#[test]
fn finger_gain_scales_each_finger() {
    let mut config = direct_config();
    config.finger_gain = [1.0, 0.5, 2.0, 0.0, 1.0];
    let mut ff = law(config);
    let mut t = 0;
    // 0.3 + 1.6 N -> 400 units each.
    let out = run(&mut ff, &mut t, 3, |t| inputs(t, fresh([1.9; 5]), None));
    assert_eq!(out.force, [400, 200, 800, 0, 400]);
}

#[test]
fn timestamps_going_backwards_or_repeating_are_safe() {
    let config = FeedbackConfig::default();
    let mut ff = law(config);
    let stamps = [
        5 * MS,
        6 * MS,
        6 * MS,
        2 * MS,
        0,
        3 * MS,
        u64::MAX,
        0,
        u64::MAX,
    ];
    let mut prev = 0_i16;
    for (k, &t) in stamps.iter().enumerate() {
        let out = ff.step(&inputs(t, fresh([25.0; 5]), None));
        assert!(out.force.iter().all(|&f| (0..=800).contains(&f)), "{out:?}");
        if k > 0 && t <= stamps[k - 1] {
            assert_eq!(out.force[0], prev, "dt = 0 holds the output at step {k}");
        }
        prev = out.force[0];
    }
    // The reference re-synchronised on the backward jump: 0 -> 3 ms moved.
    let mut ff = law(FeedbackConfig {
        smoothing_tau_s: 0.0,
        ..FeedbackConfig::default()
    });
    ff.step(&inputs(10 * MS, fresh([25.0; 5]), None));
    ff.step(&inputs(11 * MS, fresh([25.0; 5]), None)); // +20
    ff.step(&inputs(MS, fresh([25.0; 5]), None)); // back: hold
    let out = ff.step(&inputs(2 * MS, fresh([25.0; 5]), None)); // +20
    assert_eq!(out.force, [40; 5]);
}

#[test]
fn reset_forgets_state() {
    let mut ff = law(FeedbackConfig::default());
    let mut t = 0;
    saturate(&mut ff, &mut t);
    ff.reset();
    let out = ff.step(&inputs(t, fresh([25.0; 5]), None));
    assert_eq!(out.force, [0; 5]);
}

#[test]
fn contact_source_codes_are_stable() {
    assert_eq!(ContactSource::None as u8, 0);
    assert_eq!(ContactSource::Tactile as u8, 1);
    assert_eq!(ContactSource::PositionError as u8, 2);
    assert_eq!(ContactSource::Current as u8, 3);
    assert_eq!(ContactSource::Ramping as u8, 4);
    assert_eq!(ContactSource::EStop as u8, 5);
}

// ---------------------------------------------------------------- proptest

/// Any f32, biased toward useful ranges but including NaN, ±inf, extremes
/// and subnormals.
fn wild(lo: f32, hi: f32) -> BoxedStrategy<f32> {
    prop_oneof![
        6 => lo..hi,
        1 => proptest::num::f32::ANY,
        1 => prop_oneof![
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
            Just(f32::MAX),
            Just(f32::MIN),
            Just(0.0),
            Just(-0.0),
        ],
    ]
    .boxed()
}

/// Non-negative finite value with extremes, for config thresholds/gains.
fn non_neg(lo: f32, hi: f32) -> BoxedStrategy<f32> {
    prop_oneof![
        6 => lo..hi,
        1 => Just(0.0_f32),
        1 => Just(f32::MAX),
        1 => Just(f32::MIN_POSITIVE),
    ]
    .boxed()
}

fn positive(lo: f32, hi: f32) -> BoxedStrategy<f32> {
    prop_oneof![
        6 => lo..hi,
        1 => Just(f32::MAX),
        1 => Just(f32::MIN_POSITIVE),
        1 => Just(1e-45_f32),
    ]
    .boxed()
}

fn estimate_config() -> BoxedStrategy<EstimateConfig> {
    (
        any::<bool>(),
        non_neg(0.0, 0.5),
        non_neg(0.0, 10_000.0),
        any::<bool>(),
        non_neg(0.0, 2000.0),
        non_neg(0.0, 5.0),
        (
            any::<bool>(),
            non_neg(0.0, 2.0),
            non_neg(0.0, 10_000.0),
            prop_oneof![Just(0.0_f32), Just(0.07), Just(0.5), Just(f32::MAX)],
        ),
        (
            any::<bool>(),
            prop_oneof![Just(0.0_f32), Just(0.07), Just(0.5), Just(f32::MAX)],
        ),
    )
        .prop_map(
            |(up, pt, pg, uc, ct, cg, (ue, et, eg, es), (cc, cs))| EstimateConfig {
                use_position_error: up,
                position_error_threshold: pt,
                position_gain: pg,
                use_current: uc,
                current_threshold_ma: ct,
                current_gain_per_ma: cg,
                current_toward_closing: cc,
                current_stall_speed_rad_s: cs,
                use_effort: ue,
                effort_threshold_nm: et,
                effort_gain_per_nm: eg,
                effort_stall_speed_rad_s: es,
            },
        )
        .boxed()
}

/// Any valid configuration, including extreme but legal values.
fn any_config() -> BoxedStrategy<FeedbackConfig> {
    (
        non_neg(0.0, 2.0),
        non_neg(0.0, 2000.0),
        prop_oneof![Just(0_i16), Just(1000_i16), 0_i16..=1000],
        positive(1.0, 1e6),
        prop_oneof![Just(0.0_f32), 0.0_f32..0.1, Just(f32::MAX), Just(1e-45_f32)],
        positive(1e-4, 1.0),
        estimate_config(),
        proptest::array::uniform5(prop_oneof![Just(0.0_f32), Just(2.0_f32), 0.0_f32..=2.0]),
        prop_oneof![Just(0.0_f32), 0.0_f32..100.0],
    )
        .prop_map(
            |(thr, gain, max, rate, tau, ramp, estimate, fg, hysteresis)| FeedbackConfig {
                contact_threshold_n: thr,
                gain_per_n: gain,
                max_force: max,
                rate_limit_per_s: rate,
                smoothing_tau_s: tau,
                stale_ramp_s: ramp,
                // Valid only below the saturation.
                hysteresis: if hysteresis < f32::from(max) {
                    hysteresis
                } else {
                    0.0
                },
                estimate,
                finger_gain: fg,
                pst: PstConfig::default(),
                passivity: PassivityConfig {
                    mode: PassivityMode::On,
                    ..PassivityConfig::default()
                },
            },
        )
        .boxed()
}

/// How the next timestamp is derived from the previous one.
#[derive(Debug, Clone, Copy)]
enum Clock {
    /// Advance by this many ns (0 = repeat).
    Advance(u64),
    /// Jump to this absolute value (often backwards).
    Jump(u64),
}

fn clock() -> BoxedStrategy<Clock> {
    prop_oneof![
        8 => (0_u64..5 * MS).prop_map(Clock::Advance),
        1 => any::<u64>().prop_map(Clock::Jump),
        1 => Just(Clock::Advance(0)),
    ]
    .boxed()
}

fn apply(t: u64, c: Clock) -> u64 {
    match c {
        Clock::Advance(d) => t.saturating_add(d),
        Clock::Jump(abs) => abs,
    }
}

fn any_tactile() -> BoxedStrategy<Tactile> {
    prop_oneof![
        6 => (
            proptest::array::uniform5(wild(-1.0, 30.0)),
            proptest::array::uniform5(any::<bool>()),
        )
            .prop_map(|(normal_n, valid)| Tactile::Fresh(TactileInput { normal_n, valid })),
        1 => Just(Tactile::Stale),
        1 => Just(Tactile::Absent),
    ]
    .boxed()
}

/// Joint state for up to 24 joints (any profile), with wild values everywhere.
fn any_hand() -> BoxedStrategy<Option<HandInput>> {
    let joints = |lo, hi| {
        prop::collection::vec(wild(lo, hi), MAX_JOINTS).prop_map(|v| {
            let mut a = [0.0; MAX_JOINTS];
            a.copy_from_slice(&v);
            a
        })
    };
    prop::option::weighted(
        0.8,
        (
            joints(-0.2, 1.2),
            joints(-0.2, 1.2),
            joints(-3000.0, 3000.0),
            joints(-10.0, 10.0),
        )
            .prop_map(|(commanded, measured, current_ma, effort_nm)| HandInput {
                commanded,
                measured,
                current_ma,
                effort_nm,
                speed_rad_s: effort_nm,
            }),
    )
    .boxed()
}

fn any_profile() -> BoxedStrategy<HandProfile> {
    prop::sample::select(HandProfile::builtin_names().collect::<Vec<_>>())
        .prop_map(|name| HandProfile::builtin(name).expect("shipped profile"))
        .boxed()
}

/// One step's inputs without the timestamp.
fn any_step() -> BoxedStrategy<(Clock, Tactile, Option<HandInput>, bool)> {
    (
        clock(),
        any_tactile(),
        any_hand(),
        prop::bool::weighted(0.03),
    )
        .boxed()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Whatever the inputs and timestamps, every force is in [0, max_force].
    #[test]
    fn prop_forces_always_within_limits(
        config in any_config(),
        profile in any_profile(),
        t0 in any::<u64>(),
        steps in prop::collection::vec(any_step(), 1..200),
        fingers in prop::collection::vec(prop::array::uniform5(-0.5f32..1.5), 200),
    ) {
        let max = config.max_force;
        let mut ff = ForceFeedback::new(config, &profile).expect("valid config");
        let mut t = t0;
        // The operator's fingers move anywhere (the passivity controller, on, acts on them).
        for ((c, tactile, hand, estop), position) in steps.into_iter().zip(fingers) {
            t = apply(t, c);
            let operator = Some(OperatorInput { t_ns: t, position });
            let out = ff.step(&Inputs { t_ns: t, tactile, hand, estop, operator, remote: true });
            for &f in &out.force {
                prop_assert!((0..=max).contains(&f), "force {f} outside 0..={max}: {out:?}");
            }
            prop_assert!(usize::from(out.clamped) <= GLOVE_FINGERS);
            for (f, source) in profile.feedback.iter().enumerate() {
                if source.is_none() && !estop {
                    prop_assert_eq!(out.force[f], 0, "finger {} has no source", f);
                }
            }
            if estop {
                prop_assert_eq!(out.force, [0; GLOVE_FINGERS]);
                prop_assert_eq!(out.source, [ContactSource::EStop; GLOVE_FINGERS]);
            }
        }
    }

    /// Valid normals all below the threshold, for any duration and clock:
    /// all forces stay exactly zero.
    #[test]
    fn prop_zero_without_contact(
        mut config in any_config(),
        thr in 0.01_f32..5.0,
        t0 in any::<u64>(),
        steps in prop::collection::vec(
            (clock(), proptest::array::uniform5(-1.0_f32..0.999), any_hand()),
            1..300,
        ),
    ) {
        config.contact_threshold_n = thr;
        let mut ff = law(config);
        let mut t = t0;
        for (c, fractions, hand) in steps {
            t = apply(t, c);
            let normal_n = fractions.map(|u| u * thr);
            let out = ff.step(&inputs(t, fresh(normal_n), hand));
            prop_assert_eq!(out.force, [0; GLOVE_FINGERS]);
            prop_assert_eq!(out.source, [ContactSource::None; GLOVE_FINGERS]);
        }
    }

    /// More contact force never gives less feedback: two fresh instances fed
    /// constant tactile A >= B per finger at 1 kHz.
    #[test]
    fn prop_monotone_in_contact_force(
        config in any_config(),
        b in proptest::array::uniform5(prop_oneof![4 => -1.0_f32..30.0, 1 => Just(f32::MAX)]),
        extra in proptest::array::uniform5(prop_oneof![4 => 0.0_f32..30.0, 1 => Just(0.0_f32)]),
        t0 in 0_u64..u64::MAX / 2,
        n in 1_usize..400,
    ) {
        let steps = (0..n).map(|k| (t0 + k as u64 * MS, b, extra));
        assert_more_force_never_less_feedback(config, steps)?;
    }

    /// The same for contact forces that change every step (the hysteresis and the filter keep
    /// state): two instances fed A(t) >= B(t) per finger at 1 kHz.
    #[test]
    fn prop_monotone_in_changing_contact_force(
        config in any_config(),
        steps in prop::collection::vec(
            (
                proptest::array::uniform5(-1.0_f32..10.0),
                proptest::array::uniform5(prop_oneof![3 => 0.0_f32..3.0, 1 => Just(0.0_f32)]),
            ),
            1..300,
        ),
    ) {
        let steps = steps
            .into_iter()
            .enumerate()
            .map(|(k, (b, extra))| (k as u64 * MS, b, extra));
        assert_more_force_never_less_feedback(config, steps)?;
    }
}

/// Feeds two fresh laws of `config`, at each step's time, the fingertip forces `b` and
/// `b + extra` (`extra >= 0`): the second's force is never below the first's on any finger.
fn assert_more_force_never_less_feedback(
    config: FeedbackConfig,
    steps: impl Iterator<Item = (u64, [f32; 5], [f32; 5])>,
) -> Result<(), TestCaseError> {
    let mut ff_a = law(config.clone());
    let mut ff_b = law(config);
    for (k, (t, b, extra)) in steps.enumerate() {
        let a: [f32; 5] = std::array::from_fn(|i| b[i] + extra[i]);
        let out_a = ff_a.step(&inputs(t, fresh(a), None));
        let out_b = ff_b.step(&inputs(t, fresh(b), None));
        for f in 0..GLOVE_FINGERS {
            prop_assert!(
                out_a.force[f] >= out_b.force[f],
                "step {k} finger {f}: A {:?} -> {:?}, B {:?} -> {:?}",
                a,
                out_a.force,
                b,
                out_b.force
            );
        }
    }
    Ok(())
}

#[test]
fn effort_counts_as_contact_only_while_the_joint_is_stalled() {
    // The Allegro's glove middle finger feels its middle flexion joints' effort (profile).
    let allegro = HandProfile::builtin("allegro").expect("shipped profile");
    let middle_1 = allegro.joint_index("middle_1").expect("joint");
    let mut config = direct_config();
    config.estimate = EstimateConfig {
        use_position_error: false,
        use_current: false,
        effort_threshold_nm: 0.03,
        effort_gain_per_nm: 5000.0,
        effort_stall_speed_rad_s: 0.07,
        ..EstimateConfig::default()
    };
    let mut ff = ForceFeedback::new(config, &allegro).expect("valid config");
    let hand = |speed: f32| {
        let mut h = HandInput::default();
        h.effort_nm[middle_1] = 0.1;
        h.speed_rad_s[middle_1] = speed;
        h
    };
    let mut t = 0;
    // Closing fast through free space: the effort is what moving takes, not contact.
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(hand(1.0)))
    });
    assert_eq!(out.force[2], 0);
    assert_eq!(out.source[2], ContactSource::None);
    // Stopped by the object while pushing: (0.1 - 0.03) N m x 5000 = 350.
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(hand(0.01)))
    });
    assert_eq!(out.force[2], 350);
    assert_eq!(out.source[2], ContactSource::Effort);
    // Unknown speed: the effort counts.
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(hand(f32::NAN)))
    });
    assert_eq!(out.source[2], ContactSource::Effort);
    // Zero (the default) counts effort at any speed.
    let mut config = direct_config();
    config.estimate.use_position_error = false;
    let mut ff = ForceFeedback::new(config, &allegro).expect("valid config");
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(hand(1.0)))
    });
    assert_eq!(out.source[2], ContactSource::Effort);
}

#[test]
fn a_servos_current_counts_only_toward_closing_and_while_stalled() {
    // The LEAP Hand's glove middle finger feels its middle flexion servos' current (profile).
    let leap = HandProfile::builtin("leap").expect("shipped profile");
    let pip = leap.joint_index("middle_pip").expect("joint");
    let mut config = direct_config();
    config.estimate = EstimateConfig {
        use_position_error: false,
        use_effort: false,
        current_threshold_ma: 150.0,
        current_gain_per_ma: 3.0,
        current_toward_closing: true,
        current_stall_speed_rad_s: 0.07,
        ..EstimateConfig::default()
    };
    let mut ff = ForceFeedback::new(config, &leap).expect("valid config");
    let hand = |current: f32, speed: f32, measured: f32| {
        let mut h = HandInput::default();
        h.current_ma[pip] = current;
        h.speed_rad_s[pip] = speed;
        h.measured[pip] = measured;
        h
    };
    let mut t = 0;
    // Stopped by the object, pushing closed: (250 - 150) mA x 3 = 300.
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(hand(250.0, 0.0, 0.5)))
    });
    assert_eq!((out.force[2], out.source[2]), (300, ContactSource::Current));
    // The same current while the finger moves through free space is what moving takes.
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(hand(250.0, 1.0, 0.5)))
    });
    assert_eq!((out.force[2], out.source[2]), (0, ContactSource::None));
    // Pulled open (negative current), or past its open angle: nothing in the hand.
    for (current, measured) in [(-250.0, 0.5), (250.0, -0.1)] {
        let out = run(&mut ff, &mut t, 3, |t| {
            inputs(t, Tactile::Absent, Some(hand(current, 0.0, measured)))
        });
        assert_eq!(
            (out.force[2], out.source[2]),
            (0, ContactSource::None),
            "{current} mA at {measured}"
        );
    }
    // Without the direction (the default), the magnitude counts.
    let mut config = direct_config();
    config.estimate.use_position_error = false;
    config.estimate.current_threshold_ma = 150.0;
    let mut ff = ForceFeedback::new(config, &leap).expect("valid config");
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(hand(-250.0, 1.0, 0.5)))
    });
    assert_eq!(out.source[2], ContactSource::Current);
}

#[test]
fn only_effort_toward_the_closed_angle_is_contact() {
    // A finger held open against its PD (effort pulling it open) is not closing on anything.
    let allegro = HandProfile::builtin("allegro").expect("shipped profile");
    let middle_1 = allegro.joint_index("middle_1").expect("joint");
    let mut config = direct_config();
    config.estimate.use_position_error = false;
    let mut ff = ForceFeedback::new(config, &allegro).expect("valid config");
    let hand = |effort: f32| {
        let mut h = HandInput::default();
        h.effort_nm[middle_1] = effort;
        h
    };
    let mut t = 0;
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(hand(-0.5)))
    });
    assert_eq!(out.source[2], ContactSource::None);
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(hand(0.5)))
    });
    assert_eq!(out.source[2], ContactSource::Effort);
    // More open than its open angle (normalised below 0): pulled back from its stop, not
    // pressed by an object.
    let mut beyond = hand(0.5);
    beyond.measured[middle_1] = -0.1;
    let out = run(&mut ff, &mut t, 3, |t| {
        inputs(t, Tactile::Absent, Some(beyond))
    });
    assert_eq!(out.source[2], ContactSource::None);
}
