//! Benchmark: the closed haptic loop across a delay (`teleop_e2e::haptics`), plain force feedback
//! beside passivity-controlled feedback, for round-trip delays 0 to 500 ms and a soft and a
//! rigid object: how true the felt force is, whether the held grasp oscillates, how long it
//! takes to settle, the energy the feedback channel generates, and whether force is felt at all.
//!
//! The method is printed before the table (what is simulated, rates, delays, how each figure is
//! measured); the configuration is the repository's `config/` (glove, Revo2 session, bridges).
//!
//! Every case runs with two simulated operators: the glove simulator's default one, and a loose
//! one (`haptics::loose_operator`, a quarter of the finger's stiffness), whose fingers the
//! glove moves far enough for delayed feedback to oscillate.
//!
//! Options: `--delays 0,10,50` (round trips, ms), `--grasps N` (grasp cycles per case), and to
//! run one operator of your own instead (the default one so changed): `--operator-stiffness
//! N_PER_M`, `--operator-stiffening PER_M`, `--operator-damping N_S_PER_M`, `--operator-mass KG`.
//!
//! Run: `cargo run --release -p teleop-e2e --example bench_haptics`
#![allow(clippy::print_stdout)]

use std::process::ExitCode;
use std::time::Instant;

use teleop_e2e::bench::loadavg;
use teleop_e2e::haptics::{
    analyse, loose_operator, run, Case, Feedback, Hold, Metrics, Object, Stations, CONTACT_MIN,
    CYCLE_CROSSINGS, CYCLE_FINGER_P2P, CYCLE_FORCE_P2P, CYCLE_KEEPS, FINGER_NAMES, SETTLE_BAND,
    SETTLE_BAND_MIN,
};
use teleop_sim_glove::hand::HandModel;

/// The round-trip delays, ms.
const DELAYS_MS: [u64; 6] = [0, 10, 50, 100, 200, 500];

fn main() -> ExitCode {
    match bench() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("bench_haptics: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The command line's choices.
struct Args {
    delays: Vec<u64>,
    grasps: u32,
    /// The operators to run every case with, by name.
    operators: Vec<(&'static str, HandModel)>,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        delays: DELAYS_MS.to_vec(),
        grasps: Case::new(0, Object::RIGID, Feedback::Plain).grasps,
        operators: vec![
            ("default", HandModel::default()),
            ("loose", loose_operator()),
        ],
    };
    // Any --operator-* option runs one operator instead: the default one so changed.
    let mut custom: Option<HandModel> = None;
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it
            .next()
            .ok_or_else(|| format!("{flag}: expected a value after it"))?;
        let number = |what: &str, least: f32| -> Result<f32, String> {
            value
                .parse::<f32>()
                .ok()
                .filter(|v| v.is_finite() && *v >= least)
                .ok_or_else(|| format!("{flag} {value}: expected {what}"))
        };
        match flag.as_str() {
            "--delays" => {
                args.delays = value
                    .split(',')
                    .map(|d| d.trim().parse::<u64>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| format!("--delays {value}: {e}"))?;
            }
            "--grasps" => args.grasps = number("a count of at least 1", 1.0)?.round() as u32,
            "--operator-stiffness" => {
                custom
                    .get_or_insert_with(HandModel::default)
                    .stiffness_n_per_m = number("a stiffness > 0, N/m", f32::MIN_POSITIVE)?
            }
            "--operator-stiffening" => {
                custom
                    .get_or_insert_with(HandModel::default)
                    .stiffening_per_m = number("a stiffening >= 0, 1/m", 0.0)?
            }
            "--operator-damping" => {
                custom
                    .get_or_insert_with(HandModel::default)
                    .damping_n_s_per_m = number("a damping > 0, N s/m", f32::MIN_POSITIVE)?
            }
            "--operator-mass" => {
                custom.get_or_insert_with(HandModel::default).mass_kg =
                    number("a mass > 0, kg", f32::MIN_POSITIVE)?
            }
            _ => {
                return Err(format!(
                    "{flag}: unknown option (--delays, --grasps, --operator-stiffness, \
                     --operator-stiffening, --operator-damping, --operator-mass)"
                ))
            }
        }
    }
    if let Some(model) = custom {
        args.operators = vec![("custom", model)];
    }
    Ok(args)
}

fn bench() -> Result<(), String> {
    let args = parse_args()?;
    let stations = Stations::repository()?;
    let template = Case::new(0, Object::RIGID, Feedback::Plain);
    let law = stations.feedback();
    println!(
        "# bench_haptics: the closed haptic loop across a delay (load {})",
        loadavg()
    );
    println!();
    println!("Method. One process, a simulated clock stepped every 1 ms, no wall-clock waits:");
    println!(
        "- operator: the glove simulator's hand (a mass-spring-damper finger per channel), \
         script grasp ({} s per cycle, {} cycles: reach, close, squeeze, hold 55-80 % of the \
         cycle, release); operators: {};",
        template.grasp_period_s,
        args.grasps,
        args.operators
            .iter()
            .map(|(name, m)| format!(
                "{name} (mass {} kg, stiffness {} N/m + {} /m x effort up to {} N/m, damping {} \
                 N s/m)",
                m.mass_kg,
                m.stiffness_n_per_m,
                m.stiffening_per_m,
                m.max_stiffness_n_per_m,
                m.damping_n_s_per_m
            ))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "- glove node: force frame (the newest force command if fresh, clamped) then positions \
         -> glove/state (raw/1000); retargeting: RetargetEngine, config/revo2/retarget.toml;"
    );
    println!(
        "- link: a delay line each way, one way = round trip / 2, the bridges' max_age_ms \
         (plus the measured one-way delay) applied on arrival; each station's bridge's health \
         report (link up, latency_p50_ms = one way) once a second to the hand node and to \
         force feedback;"
    );
    println!(
        "- robot: the Revo2 node's command path (freshness by stamp, teleop-hand-node's \
         Admission and Resume, the driver's position+speed outputs or hold) on the Revo2 \
         simulator with its ball, touched by the fingertip pads by geometry ({} {} N/m, {} {} \
         N/m); hand/state and hand/tactile as the node fills them;",
        Object::SPONGE.name,
        Object::SPONGE.stiffness_n_per_m,
        Object::RIGID.name,
        Object::RIGID.stiffness_n_per_m,
    );
    println!(
        "- operator station: FeedbackEngine, config/revo2/feedback.toml (gain {} per N above \
         {} N, max {}, hysteresis {}), passivity mode off (plain) or on (passivity: tolerance \
         {}, max_damping {}, recovery_per_s {}); its force commands to the glove without \
         delay.",
        law.gain_per_n,
        law.contact_threshold_n,
        law.max_force,
        law.hysteresis,
        law.passivity.tolerance,
        law.passivity.max_damping,
        law.passivity.recovery_per_s
    );
    println!("- rates and limits: {}.", stations.describe());
    println!();
    println!(
        "Figures, per case, over each grasp's held part (the last half of the hold, 67.5-80 % \
         of the cycle); fingers in glove order, `index` the glove's index finger:"
    );
    println!(
        "- err: felt force (the glove's measured force between finger and actuator) against \
         the robot's measured fingertip force after the configured gain (threshold, finger \
         gain, saturation), mean over the held part, % of the expected, mean of the grasps; \
         `idx` the index, `mean` the mean over the fingers expecting at least {CONTACT_MIN} \
         units;"
    );
    println!(
        "- p2p: peak-to-peak of the felt force (glove units; `idx` the index, `max` the \
         finger swinging most) and of the finger's raw position (the finger moving most), \
         largest over the grasps;"
    );
    println!(
        "- cycle: a limit cycle persists when, in the last grasp's held part, a finger's felt \
         force (or position) swings more than {CYCLE_FORCE_P2P} units ({CYCLE_FINGER_P2P} raw), \
         its second half keeps at least {CYCLE_KEEPS} of the first half's swing and it crosses \
         its mean at least {CYCLE_CROSSINGS} times; shown: the finger whose force swings most \
         and the period (the autocorrelation's highest peak after its first zero; two periods \
         must fit in the held part, so a slower swing shows only in p2p); `n/N` = grasps whose \
         held part oscillates;"
    );
    println!(
        "- settle: from the first tactile force above the threshold on the robot's index to \
         the index's felt force staying within +-{:.0} % (at least +-{SETTLE_BAND_MIN} units) \
         of its held mean until the hold ends, mean of the grasps that settle (s);",
        SETTLE_BAND * 100.0
    );
    println!(
        "- energy: `own`, the most negative running sum over the run of the actuators' force \
         x the finger's closing velocity (the glove simulator's) x 1 ms, summed over the \
         fingers (glove units x travel: 1000 = full-scale force over a finger's whole travel, \
         3 N x 0.169 m = 0.51 J; positive flows into the channel, so the figure is the energy \
         the channel generated); `obs`, the most negative energy the passivity observer \
         reported on any finger;"
    );
    println!("- stale: share of the holds (55-80 %) whose newest force command was flagged STALE.");
    let start = Instant::now();
    let mut cases = 0;
    for (name, operator) in &args.operators {
        println!();
        println!("Operator: {name}.");
        println!();
        println!(
            "| RTT ms | object | feedback | err idx % | err mean % | p2p F idx | p2p F max | \
             p2p x max | cycle | period ms | settle s | E own | E obs | stale % |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
        for &delay in &args.delays {
            for object in [Object::SPONGE, Object::RIGID] {
                for feedback in [Feedback::Plain, Feedback::Passivity] {
                    let case = Case {
                        round_trip_ms: delay,
                        object,
                        feedback,
                        grasps: args.grasps,
                        operator: *operator,
                        ..template.clone()
                    };
                    let ticks = run(&stations, &case)?;
                    println!("{}", row(&case, &analyse(&stations, &case, &ticks)));
                    cases += 1;
                }
            }
        }
    }
    println!();
    println!("{cases} cases in {:.1} s.", start.elapsed().as_secs_f64());
    Ok(())
}

/// One table row.
fn row(case: &Case, m: &Metrics) -> String {
    let mean = |f: &dyn Fn(&Hold) -> Option<f32>| {
        let v: Vec<f32> = m.holds.iter().filter_map(f).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f32>() / v.len() as f32)
    };
    let max = |f: &dyn Fn(&Hold) -> f32| m.holds.iter().map(f).fold(0.0f32, f32::max);
    let opt =
        |v: Option<f32>, digits: usize| v.map_or("-".to_string(), |v| format!("{v:.digits$}"));
    let cycles = m.holds.iter().filter(|h| h.cycle.is_some()).count();
    let persists = m.holds.last().and_then(|h| h.cycle);
    format!(
        "| {} | {} | {} | {} | {} | {:.0} | {:.0} | {:.0} | {} {}/{} | {} | {} | {:.1} | {:.1} | {:.0} |",
        case.round_trip_ms,
        case.object.name,
        case.feedback.name(),
        opt(mean(&|h| h.error_index_pct), 1),
        opt(mean(&|h| h.error_mean_pct), 1),
        max(&|h| h.felt_p2p_index),
        max(&|h| h.felt_p2p),
        max(&|h| h.finger_p2p),
        persists.map_or("no".to_string(), |(f, _)| format!("yes ({})", FINGER_NAMES[f])),
        cycles,
        m.holds.len(),
        opt(persists.map(|(_, s)| s * 1000.0), 0),
        opt(mean(&|h| h.settle_s), 2),
        m.generated,
        m.observed,
        mean(&|h| Some(h.stale_share * 100.0)).unwrap_or(0.0),
    )
}
