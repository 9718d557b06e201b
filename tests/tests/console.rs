//! `teleop top`, the operator's console, in a real terminal: tmux runs it against the default
//! simulated session; the test reads the screen (`tmux capture-pane -p`), presses the keys as an
//! operator would, and checks both the screen and the topics: the e-stop key zeroes the glove
//! forces and holds the hand, `r` then `y` releases it, `s` (with a typed task) and `k` start and
//! stop an episode the recorder counts, the layout follows a resize to 80x24, and `q` gives the
//! terminal back as it was (normal screen, canonical mode), also when pressed right after the
//! e-stop key (the e-stop is done first). With two sides: one key stops both, a pasted `ry`
//! releases nothing, `r` and `y` release both, and SIGTERM ends the console as `q` does.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

use teleop_e2e::watch::{fresh, Watcher};
use teleop_e2e::{bin, Sandbox, Session};
use teleop_msgs::force_flags;

/// A tmux server of the test's own (its socket in the sandbox) running one window.
struct Tmux {
    socket: PathBuf,
}

impl Tmux {
    /// Starts `command` (a shell command) in a detached `width` x `height` window.
    fn start(sandbox: &Sandbox, width: u16, height: u16, command: &str) -> Self {
        let tmux = Self {
            socket: sandbox.dir.path().join("tmux.sock"),
        };
        let (w, h) = (width.to_string(), height.to_string());
        tmux.run(&[
            "new-session",
            "-d",
            "-s",
            "top",
            "-x",
            &w,
            "-y",
            &h,
            command,
        ]);
        tmux
    }

    fn run(&self, args: &[&str]) -> String {
        let out = Command::new("tmux")
            .arg("-S")
            .arg(&self.socket)
            .args(args)
            .output()
            .expect("tmux is installed");
        assert!(
            out.status.success(),
            "tmux {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// The screen as text.
    fn screen(&self) -> String {
        self.run(&["capture-pane", "-p", "-t", "top"])
    }

    /// Presses keys (tmux key names: `e`, `Space`, `Enter`).
    fn keys(&self, keys: &[&str]) {
        let mut args = vec!["send-keys", "-t", "top"];
        args.extend(keys);
        self.run(&args);
    }

    /// Types `text` literally.
    fn type_text(&self, text: &str) {
        self.run(&["send-keys", "-t", "top", "-l", text]);
    }

    /// Polls the screen until `ok` holds and returns it; panics after `timeout` with the
    /// screen and the session's log.
    fn until(
        &self,
        session: &Session,
        timeout: Duration,
        what: &str,
        ok: impl Fn(&str) -> bool,
    ) -> String {
        let start = Instant::now();
        loop {
            let screen = self.screen();
            if ok(&screen) {
                return screen;
            }
            assert!(
                start.elapsed() < timeout,
                "timed out after {timeout:?} waiting for the screen to show {what}; it shows:\n\
                 {screen}\n---- teleop launch output ----\n{}",
                session.log()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = Command::new("tmux")
            .arg("-S")
            .arg(&self.socket)
            .arg("kill-server")
            .output();
    }
}

/// The glove force column's values on the screen: per finger row, the integer after its bar
/// (positions and tactile forces have decimals).
fn forces_on_screen(screen: &str) -> Vec<i32> {
    let bar = |t: &str| !t.is_empty() && t.chars().all(|c| c == '█' || c == '·');
    let mut forces = Vec::new();
    for line in screen.lines() {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        for w in tokens.windows(3) {
            if ["little", "ring", "middle", "index", "thumb"].contains(&w[0]) && bar(w[1]) {
                if let Ok(f) = w[2].trim_end_matches('│').parse::<i32>() {
                    forces.push(f);
                }
            }
        }
    }
    forces
}

/// The two tests that run a whole simulated session take turns: side by side on two cores
/// (a bimanual session of ten processes next to a single one) the simulated Revo2s' EtherCAT
/// links timed out over and over (seen once in CI), and the screen never showed both sides
/// running. Held for the test's whole length; a test that panicked does not block the other.
fn one_session_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static SESSIONS: std::sync::Mutex<()> = std::sync::Mutex::new(());
    SESSIONS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// `teleop top` in a 120x40 tmux window, in the sandbox's IPC settings; after it ends the window
/// shows `top exited <status>` and the terminal's `icanon` or `-icanon`.
fn console(sandbox: &Sandbox) -> Tmux {
    let env: Vec<String> = sandbox
        .ipc
        .to_env()
        .into_iter()
        .map(|(k, v)| format!("{k}='{v}'"))
        .collect();
    // After the console: its exit status and whether the terminal is back in canonical mode.
    let command = format!(
        "cd '{}' && env {} '{}' top; echo \"top exited $?\"; stty -a | tr ' ;' '\\n\\n' | grep -x -- '-\\?icanon'; sleep 600",
        sandbox.dir.path().display(),
        env.join(" "),
        bin("teleop").display()
    );
    Tmux::start(sandbox, 120, 40, &command)
}

#[test]
fn the_console_shows_the_session_and_its_keys_act_on_it() {
    let _one = one_session_at_a_time();
    let sandbox = Sandbox::new();
    let launch = sandbox.default_session(|t| t);
    let session = sandbox.launch(&launch);
    let watch = Watcher::new(&sandbox, "console-test");
    watch.until(
        &session,
        Duration::from_secs(30),
        "the whole pipeline running",
        |w| fresh(&w.glove) && fresh(&w.cmd) && fresh(&w.state) && fresh(&w.force),
    );
    // The glove pushes back somewhere (the simulated grasp closes on the ball).
    watch.until(&session, Duration::from_secs(20), "a glove force", |w| {
        w.force
            .latest()
            .is_some_and(|f| f.force.iter().any(|&v| v != 0))
    });

    let tmux = console(&sandbox);
    let long = Duration::from_secs(15);

    // The session on screen: its nodes, topics, bars, the recorder, the e-stop released.
    tmux.until(&session, long, "the running session", |s| {
        s.contains("e-stop released")
            && ["glove ", "revo2 ", "feedback ", "retarget ", "recorder "]
                .iter()
                .all(|n| s.lines().any(|l| l.contains(n) && l.contains("alive")))
            && s.contains("glove/state")
            && s.contains("recording: recorder:")
            && forces_on_screen(s).len() == 5
            && s.contains("hand revo2 link up")
    });

    // The simulated grasp closes on the ball: the glove pushes back, on screen too.
    let screen = tmux.until(
        &session,
        Duration::from_secs(30),
        "a glove force on screen",
        |s| s.contains("rates over 2.0 s") && forces_on_screen(s).iter().any(|&f| f != 0),
    );
    // For the README's capture (`-- --nocapture`).
    eprintln!("the console during the grasp:\n{screen}");

    // The e-stop key: the screen says engaged, the forces on screen and on the topic go to
    // zero, and the hand holds.
    tmux.keys(&["e"]);
    let screen = tmux.until(&session, long, "the e-stop engaged and held", |s| {
        // The action's answer lists who acknowledged within `teleop estop`'s wait (all three
        // unless the machine is slow); the live acknowledgements show every node that holds it.
        s.contains("e-stop ENGAGED (latched); namespace (none): acknowledged by")
            && s.contains("E-STOP ENGAGED latched: (none)")
            && s.contains("held by feedback, glove, revo2")
            && s.contains("HOLDING")
            && forces_on_screen(s) == [0; 5]
    });
    assert!(
        !screen.contains("ringing the e-stop's doorbells..."),
        "{screen}"
    );
    watch.until(&session, long, "zero glove forces flagged e-stop", |w| {
        w.force
            .latest()
            .is_some_and(|f| f.force == [0; 5] && f.flags & force_flags::ESTOP != 0)
            && w.state.latest().is_some_and(|s| s.holding == 1)
    });

    // Release: `r` asks, `y` releases; the forces come back.
    tmux.keys(&["r"]);
    tmux.until(&session, long, "the release confirmation", |s| {
        s.contains("y: release")
    });
    tmux.keys(&["y"]);
    tmux.until(&session, long, "the e-stop released", |s| {
        s.contains("e-stop released") && !s.contains("E-STOP ENGAGED")
    });
    watch.until(&session, long, "glove forces after the release", |w| {
        w.force
            .latest()
            .is_some_and(|f| f.flags & force_flags::ESTOP == 0)
    });

    // An episode: `s` asks for the task, `k` stops it with success; the recorder counts both.
    tmux.keys(&["s"]);
    tmux.until(&session, long, "the task prompt", |s| {
        s.contains("task (Enter starts")
    });
    tmux.type_text("pick the ball");
    tmux.keys(&["Enter"]);
    tmux.until(&session, long, "the episode open", |s| {
        s.contains("episode start \"pick the ball\": recorder: episode 1 open")
            && s.contains("recorder: episode 1 open")
    });
    tmux.keys(&["k"]);
    tmux.until(&session, long, "the episode closed", |s| {
        s.contains("episode stop (success): recorder: episode 1 closed")
    });

    // A node killed and restarted by the launcher: one restart on its row.
    let pid = sandbox.pid_of("retarget").unwrap();
    // SAFETY: kill(2) of a process of this test's own session.
    unsafe {
        libc::kill(pid as libc::pid_t, libc::SIGKILL);
    }
    tmux.until(
        &session,
        Duration::from_secs(20),
        "retarget's restart",
        |s| {
            s.lines().any(|l| {
                let row: Vec<&str> = l.split_whitespace().collect();
                row.first() == Some(&"│retarget")
                    && row.get(1) == Some(&"alive")
                    && row.get(6) == Some(&"1")
            })
        },
    );

    // Smaller: the layout follows, the keys line still at the foot.
    tmux.run(&["resize-window", "-t", "top", "-x", "80", "-y", "24"]);
    let screen = tmux.until(&session, long, "the 80x24 layout", |s| {
        let lines: Vec<&str> = s.lines().collect();
        lines.len() == 24
            && lines[0].contains("teleop top")
            && lines[23].contains("q quit")
            && forces_on_screen(s).len() == 5
    });
    assert!(screen.lines().all(|l| l.chars().count() <= 80), "{screen}");

    // `q` right behind the e-stop key (one read of the keyboard): the console ends with success
    // once the e-stop is done, and the terminal is as it was.
    tmux.keys(&["e", "q"]);
    let screen = tmux.until(
        &session,
        long,
        "the console gone and the terminal's mode",
        |s| s.lines().any(|l| l.trim().ends_with("icanon")),
    );
    assert!(screen.contains("top exited 0"), "{screen}");
    assert!(
        screen.lines().any(|l| l.trim() == "icanon"),
        "the terminal left in raw mode: {screen}"
    );
    assert!(
        !screen.contains("teleop top"),
        "the console's screen left behind: {screen}"
    );
    assert!(
        teleop_runtime::latch_path(&sandbox.ipc, None).exists(),
        "the console quit without latching the e-stop"
    );
    watch.until(
        &session,
        long,
        "the e-stop engaged after the console",
        |w| {
            w.force
                .latest()
                .is_some_and(|f| f.force == [0; 5] && f.flags & force_flags::ESTOP != 0)
                && w.state.latest().is_some_and(|s| s.holding == 1)
        },
    );
}

#[test]
fn the_console_shows_both_sides_and_stops_both() {
    let _one = one_session_at_a_time();
    let sandbox = Sandbox::new();
    let session = sandbox.launch(&sandbox.bimanual_session());
    let tmux = console(&sandbox);
    let long = Duration::from_secs(30);
    tmux.until(&session, long, "both sides running", |s| {
        s.contains("sides: (none), left, right")
            && s.contains("side left: hand revo2 link up")
            && s.contains("side right: hand revo2 link up")
            && forces_on_screen(s).len() == 10
            && [
                "left/glove ",
                "right/glove ",
                "left/feedback",
                "right/feedback",
            ]
            .iter()
            .all(|n| s.lines().any(|l| l.contains(n) && l.contains("alive")))
    });
    tmux.keys(&["Space"]);
    tmux.until(&session, long, "both sides stopped", |s| {
        s.contains("E-STOP ENGAGED latched: (none)")
            && s.contains("side left: hand revo2 link up, HOLDING")
            && s.contains("side right: hand revo2 link up, HOLDING")
            && s.contains("held by left/feedback")
            && forces_on_screen(s) == [0; 10]
    });
    // A pasted `ry` (one read of the keyboard): the `y` never saw the question; the question
    // closes and nothing is released.
    tmux.type_text("ry");
    let screen = tmux.until(&session, long, "the paste answered", |s| {
        s.contains("release not asked: the `y` came with its `r`")
    });
    assert!(
        screen.contains("E-STOP ENGAGED latched: (none)") && !screen.contains("releasing"),
        "{screen}"
    );
    assert!(teleop_runtime::latch_path(&sandbox.ipc, None).exists());
    tmux.keys(&["r"]);
    tmux.until(&session, long, "the release confirmation", |s| {
        s.contains("y: release")
    });
    tmux.keys(&["y"]);
    tmux.until(&session, long, "both sides released", |s| {
        s.contains("e-stop released")
            && s.contains("side left: hand revo2 link up, following")
            && s.contains("side right: hand revo2 link up, following")
            && forces_on_screen(s).len() == 10
    });
    // SIGTERM, as from a process manager: the console ends with success.
    let pid = sandbox.pid_of("teleop-top").unwrap();
    // SAFETY: kill(2) of the console this test started.
    unsafe {
        libc::kill(pid as libc::pid_t, libc::SIGTERM);
    }
    let screen = tmux.until(&session, long, "the console gone", |s| {
        s.contains("top exited")
    });
    assert!(screen.contains("top exited 0"), "{screen}");
}

#[test]
fn without_a_terminal_the_console_says_so_and_fails() {
    let sandbox = Sandbox::new();
    let (ok, out) = sandbox.cli(&["top"]);
    assert!(!ok, "{out}");
    assert!(
        out.contains("teleop top draws on a terminal") && !out.contains('\u{1b}'),
        "{out}"
    );
}
