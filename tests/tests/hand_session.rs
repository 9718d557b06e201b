//! Each hand's simulated session end to end, one test per hand over the same steps: the
//! launch file's session comes up (every stage flowing, the hand node's state naming its hand,
//! joint count and link), the scripted operator's grasp closes the hand on the simulated ball,
//! the hand's own measure of it rises (the Revo2's tactile force, the Allegro's effort, the
//! Shadow Hand's PST pressure, the LEAP Hand's servo current), the glove's finger on the ball feels force from it, the session
//! stops cleanly with its summary, the recording holds it all, and `teleop reprocess`
//! reproduces the recorded hand commands. Every failure names the hand.
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use teleop_e2e::watch::{fresh, Watcher};
use teleop_e2e::{Sandbox, Session};
use teleop_msgs::{contact_source, device_model, link_kind, Message, Tactile};
use teleop_runtime::Subscriber;

/// The glove's fingers: little, ring, middle, index, thumb.
const GLOVE_RING: usize = 1;
const GLOVE_MIDDLE: usize = 2;
const GLOVE_INDEX: usize = 3;

/// A hand's session and what its grasp shows.
struct Hand {
    name: &'static str,
    /// The launch file, relative to the repository.
    launch: &'static str,
    /// The folder of its retargeting and feedback configurations, relative to the sandbox.
    config: &'static str,
    model: u8,
    joints: u8,
    link: u8,
    /// The contact source of the glove force it gives.
    source: u8,
    /// The glove finger on the ball and the two beside it, which close on nothing (`None`:
    /// the hand's grasp presses with several fingers, any glove finger may feel the most).
    on_the_ball: Option<usize>,
    /// A glove finger this hand has no finger for, which never feels anything.
    numb: Option<usize>,
    /// Whether the hand has fingertip sensors (`hand/tactile` in the session summary).
    tactile: bool,
    /// Whether the test replays the recording's fingertip samples and finds the grasp in them.
    replay: bool,
    /// How long the scripted grasp is watched; `early` ends the watch once it is shown.
    watch_for: Duration,
    early: bool,
    grasp: fn() -> Box<dyn Grasp>,
}

/// The hand's own measure of the grasp, gathered from the watcher while the operator grasps.
trait Grasp {
    /// Takes one fingertip sample.
    fn tactile(&mut self, _: &Tactile) {}
    /// Takes the samples queued since the last call.
    fn observe(&mut self, w: &Watcher) {
        w.tactile.drain(|t| self.tactile(t));
    }
    /// True once the hand shows the grasp.
    fn shown(&self) -> bool;
    /// Asserts the hand showed the grasp; `sandbox` has the simulator's control socket,
    /// `session` the logs.
    fn check(&self, hand: &str, sandbox: &Sandbox, session: &Session);
}

/// The Revo2's fingertips feel the ball (tactile normal force, N).
#[derive(Default)]
struct Revo2Grasp {
    max_normal: f32,
}

impl Grasp for Revo2Grasp {
    fn tactile(&mut self, t: &Tactile) {
        self.max_normal = t
            .fingertips
            .iter()
            .fold(self.max_normal, |m, f| m.max(f.normal_n));
    }
    fn shown(&self) -> bool {
        self.max_normal > 1.0
    }
    fn check(&self, hand: &str, _: &Sandbox, session: &Session) {
        assert!(
            self.shown(),
            "{hand}: tactile force on the ball: {} N\n{}",
            self.max_normal,
            session.log()
        );
    }
}

/// An Allegro finger (the flexion joints 1-3, 5-7, 9-11 and 13-15 in the profile's and the CAN
/// order) is stopped by the ball short of its target while its PD pushes (effort, N m). Which
/// one depends on the retargeting: the glove map drives the middle finger into the ball; pinch
/// mode (the default) puts each fingertip where the operator's is, and the scripted grasp
/// closes only a third of a fist, so the thumb and the fingers squeezed in beside the middle
/// one press, the middle one barely.
#[derive(Default)]
struct AllegroGrasp {
    max_effort: f32,
    max_gap: f32,
}

impl Grasp for AllegroGrasp {
    fn observe(&mut self, w: &Watcher) {
        let mut target = [f32::NAN; 16];
        w.cmd.drain(|c| {
            for (j, t) in target.iter_mut().enumerate() {
                *t = c.joints[j].target;
            }
        });
        w.state.drain(|s| {
            for j in [1, 2, 3, 5, 6, 7, 9, 10, 11, 13, 14, 15] {
                self.max_effort = self.max_effort.max(s.joints[j].effort);
                if target[j].is_finite() {
                    self.max_gap = self.max_gap.max(target[j] - s.joints[j].position);
                }
            }
        });
    }
    fn shown(&self) -> bool {
        self.max_effort > 0.06 && self.max_gap > 0.1
    }
    fn check(&self, hand: &str, sandbox: &Sandbox, session: &Session) {
        let status = sandbox.control("teleop-sim-allegro.ctl", "stats");
        assert!(
            self.shown(),
            "{hand}: the ball stops a finger short of its target ({} rad) and the PD pushes \
             ({} N m); sim: {status}\n{}",
            self.max_gap,
            self.max_effort,
            session.log()
        );
    }
}

/// The Shadow Hand's middle fingertip (1 in the profile's order ff, mf, rf, lf, th) is pressed
/// by the ball (PST pressure).
#[derive(Default)]
struct ShadowGrasp {
    pressure: [i32; 5],
}

/// The Shadow Hand's middle fingertip in the profile's fingertip order.
const SHADOW_MF_TIP: usize = 1;

impl Grasp for ShadowGrasp {
    fn tactile(&mut self, t: &Tactile) {
        for (p, tip) in self.pressure.iter_mut().zip(t.active_fingertips()) {
            *p = (*p).max(tip.pressure);
        }
    }
    fn shown(&self) -> bool {
        self.pressure[SHADOW_MF_TIP] > 100
    }
    fn check(&self, hand: &str, sandbox: &Sandbox, session: &Session) {
        let joints = sandbox.control("teleop-sim-shadow.ctl", "joints");
        assert!(
            self.shown(),
            "{hand}: the ball presses the middle fingertip: {:?}; {joints}\n{}",
            self.pressure,
            session.log()
        );
    }
}

/// The LEAP Hand's middle finger (flexion servos 5, 6, 7 in the profile's and the motor-ID
/// order) is stopped by the ball short of its target while the servos' current-based position
/// loop pushes: the finger's closure (the three joints' sum) short of the command's, and the
/// largest present current among them (mA), both in the same state: a finger lagging its
/// target on the way, or a current spike while it swings, is not the ball stopping it.
#[derive(Default)]
struct LeapGrasp {
    /// The newest command's closure of the finger (none before the first command).
    target: Option<f32>,
    max_current: f32,
    /// The largest shortfall of the closure among the states with the finger pushing.
    max_gap: f32,
}

/// The present current (mA) over which a LEAP middle-finger servo counts as pushing.
const LEAP_PUSHING_MA: f32 = 200.0;

/// The LEAP Hand's middle-finger flexion servos.
const LEAP_MIDDLE: [usize; 3] = [5, 6, 7];

impl Grasp for LeapGrasp {
    fn observe(&mut self, w: &Watcher) {
        let mut target = self.target;
        w.cmd
            .drain(|c| target = Some(LEAP_MIDDLE.iter().map(|&j| c.joints[j].target).sum()));
        self.target = target;
        w.state.drain(|s| {
            let current = LEAP_MIDDLE
                .iter()
                .map(|&j| s.joints[j].current_ma.abs())
                .fold(0.0, f32::max);
            self.max_current = self.max_current.max(current);
            let closure: f32 = LEAP_MIDDLE.iter().map(|&j| s.joints[j].position).sum();
            if let Some(target) = target.filter(|_| current > LEAP_PUSHING_MA) {
                self.max_gap = self.max_gap.max(target - closure);
            }
        });
    }
    fn shown(&self) -> bool {
        self.max_current > LEAP_PUSHING_MA && self.max_gap > 0.15
    }
    fn check(&self, hand: &str, sandbox: &Sandbox, session: &Session) {
        let status = sandbox.control("teleop-sim-leap.ctl", "stats");
        assert!(
            self.shown(),
            "{hand}: the ball stops the middle finger short of its target ({} rad) and its \
             servos push ({} mA); sim: {status}\n{}",
            self.max_gap,
            self.max_current,
            session.log()
        );
    }
}

const REVO2: Hand = Hand {
    name: "Revo2",
    launch: "launch.toml",
    config: "config/revo2",
    model: device_model::REVO2,
    joints: 6,
    link: link_kind::ETHERCAT,
    source: contact_source::TACTILE,
    on_the_ball: None,
    numb: None,
    tactile: true,
    replay: false,
    watch_for: Duration::from_secs(7),
    early: true,
    grasp: || Box::<Revo2Grasp>::default(),
};

const ALLEGRO: Hand = Hand {
    name: "Allegro",
    launch: "launch/allegro.toml",
    config: "config/allegro",
    model: device_model::ALLEGRO,
    joints: 16,
    link: link_kind::CAN,
    source: contact_source::EFFORT,
    on_the_ball: None, // see AllegroGrasp
    numb: Some(0),
    tactile: false,
    replay: false,
    watch_for: Duration::from_secs(8),
    early: false,
    grasp: || Box::<AllegroGrasp>::default(),
};

const SHADOW: Hand = Hand {
    name: "Shadow",
    launch: "launch/shadow.toml",
    config: "config/shadow",
    model: device_model::SHADOW,
    joints: 24,
    link: link_kind::ETHERCAT,
    source: contact_source::TACTILE,
    on_the_ball: Some(GLOVE_MIDDLE),
    numb: None,
    tactile: true,
    replay: true,
    watch_for: Duration::from_secs(8),
    early: false,
    grasp: || Box::<ShadowGrasp>::default(),
};

const LEAP: Hand = Hand {
    name: "LEAP",
    launch: "launch/leap.toml",
    config: "config/leap",
    model: device_model::LEAP,
    joints: 16,
    link: link_kind::SERIAL,
    source: contact_source::CURRENT,
    on_the_ball: None,
    numb: Some(0),
    tactile: false,
    replay: false,
    watch_for: Duration::from_secs(8),
    early: true,
    grasp: || Box::<LeapGrasp>::default(),
};

#[test]
fn the_revo2_session_closes_the_loop_and_reprocesses() {
    session(&REVO2);
}

#[test]
fn the_allegro_session_closes_the_loop_and_reprocesses() {
    session(&ALLEGRO);
}

#[test]
fn the_shadow_session_closes_the_loop_and_reprocesses() {
    session(&SHADOW);
}

#[test]
fn the_leap_session_closes_the_loop_and_reprocesses() {
    session(&LEAP);
}

/// The sessions run one at a time, as they did when each hand's was a test binary of its own:
/// several hands' sessions at once on a small machine would test the machine.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn session(hand: &Hand) {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let name = hand.name;
    let sandbox = Sandbox::new();
    let launch = sandbox.session(hand.launch);
    let mut session = sandbox.launch(&launch);
    let watch = Watcher::new(&sandbox, "hand-session-test");
    watch.until(
        &session,
        Duration::from_secs(30),
        &format!("the {name} session running"),
        |w| {
            fresh(&w.glove)
                && fresh(&w.cmd)
                && fresh(&w.state)
                && fresh(&w.force)
                && (!hand.tactile || fresh(&w.tactile))
        },
    );

    let state = watch.state.latest().unwrap();
    assert_eq!(state.hand_model, hand.model, "{name}");
    assert_eq!(state.joint_count, hand.joints, "{name}");
    assert_eq!(state.link_kind, hand.link, "{name}");
    assert_eq!(state.link_up, 1, "{name}");

    // The scripted grasp (about 6 s): every finger closes, the ball stops the finger(s) under
    // it; the hand measures it, the feedback turns it into glove force, the operator feels it.
    let mut grasp = (hand.grasp)();
    let (mut force, mut felt) = ([0i16; 5], 0i16);
    let felt_enough = |force: &[i16; 5], felt: i16| {
        felt > 50
            && hand
                .on_the_ball
                .map_or(force.iter().max(), |k| Some(&force[k]))
                > Some(&100)
    };
    let start = Instant::now();
    while start.elapsed() < hand.watch_for
        && !(hand.early && grasp.shown() && felt_enough(&force, felt))
    {
        grasp.observe(&watch);
        watch.force.drain(|f| {
            for (k, &v) in f.force.iter().enumerate() {
                if f.source[k] == hand.source {
                    force[k] = force[k].max(v);
                }
            }
            if let Some(k) = hand.numb {
                assert_eq!(
                    f.force[k], 0,
                    "{name}: no finger of the hand for glove finger {k}"
                );
            }
        });
        watch
            .diag
            .drain(|d| felt = d.force.iter().fold(felt, |m, &v| m.max(v)));
        watch.drain_all();
        std::thread::sleep(Duration::from_millis(5));
    }
    eprintln!("{name}: glove force (little, ring, middle, index, thumb) {force:?}; felt {felt}");
    grasp.check(name, &sandbox, &session);
    match hand.on_the_ball {
        Some(k) => {
            assert!(force[k] > 100, "{name}: glove force on the ball: {force:?}");
            // Fingers closing on nothing feel far less than the one on the ball (idle:
            // nothing; on a loaded machine a starved loop lets a finger lag and stall for a
            // moment, felt briefly).
            assert!(
                2 * force[GLOVE_RING].max(force[GLOVE_INDEX]) < force[k],
                "{name}: the ring and index fingers close on nothing: {force:?}"
            );
        }
        None => assert!(
            force.iter().max() > Some(&100),
            "{name}: glove force from the hand: {force:?}"
        ),
    }
    assert!(felt > 50, "{name}: the simulated operator feels it: {felt}");

    let status = session.stop();
    assert!(status.success(), "{name}: {status:?}");
    let log = session.log();
    assert!(log.contains("session summary"), "{name}: {log}");
    if hand.tactile {
        assert!(log.contains(Tactile::TOPIC), "{name}: {log}");
    }
    let recording = log
        .lines()
        .find_map(|l| l.strip_prefix("recording: "))
        .unwrap_or_else(|| panic!("{name}: the summary says where the recording is"));
    let recording = launch.parent().unwrap().join(recording);
    let info = teleop_recording::info(&recording).unwrap();
    assert!(
        info.complete && info.messages > 2_000,
        "{name}: {} messages",
        info.messages
    );

    if hand.replay {
        replays_tactile(hand, &sandbox, &watch, &recording);
    }

    // Reprocessing with the session's own configuration reproduces the hand commands (the
    // recording embeds the hand's profile).
    let config = sandbox.dir.path().join(hand.config);
    let out = sandbox.dir.path().join("reprocessed.mcap");
    let (ok, report) = sandbox.cli(&[
        "reprocess",
        recording.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--retarget-config",
        config.join("retarget.toml").to_str().unwrap(),
        "--feedback-config",
        config.join("feedback.toml").to_str().unwrap(),
    ]);
    assert!(ok, "{name}: {report}");
    let line = report
        .lines()
        .find(|l| l.starts_with("hand/command"))
        .unwrap_or_else(|| panic!("{name}: {report}"));
    let differ: u64 = line.split_whitespace().nth(3).unwrap().parse().unwrap();
    assert_eq!(
        differ, 0,
        "{name}: reprocess reproduces the hand commands:\n{report}"
    );
}

/// Replayed: the recorded fingertip samples come back on `hand/tactile`, the grasp among them
/// (a fingertip pressed as the hand's own grasp check has it).
fn replays_tactile(hand: &Hand, sandbox: &Sandbox, watch: &Watcher, recording: &std::path::Path) {
    let name = hand.name;
    let tactile: Subscriber<Tactile> = watch.node.subscriber().unwrap();
    let mut replay = sandbox
        .teleop()
        .args(["replay", recording.to_str().unwrap(), "--speed", "8"])
        .args(["--topics", Tactile::TOPIC])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let (mut replayed, mut pressed) = (0, 0);
    let mut count = |t: &Tactile| {
        replayed += 1;
        let mut grasp = (hand.grasp)();
        grasp.tactile(t);
        pressed += usize::from(grasp.shown());
    };
    let start = Instant::now();
    let status = loop {
        tactile.drain(&mut count);
        if let Some(status) = replay.try_wait().unwrap() {
            break status;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "{name}: the replay did not end"
        );
        std::thread::sleep(Duration::from_millis(2));
    };
    tactile.drain(&mut count);
    assert!(status.success(), "{name}: {status:?}");
    assert!(
        replayed > 1_000 && pressed > 100,
        "{name}: replayed {replayed} tactile samples, {pressed} with a fingertip pressed"
    );
}
