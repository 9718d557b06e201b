//! `teleop top`: the operator's console, a terminal UI over a running session.
//!
//! Owns the console's loop: the terminal (raw mode and the alternate screen, restored on exit,
//! on error and on panic), the keys ([`keys`]) and their actions, run on threads of their own so
//! that the screen keeps refreshing while they wait: the e-stop is `teleop estop`'s own code
//! ([`inspect::estop_action`]), episodes are `teleop episode`'s ([`episode::send`]). What is
//! shown is [`screen`]'s (pure drawing from a [`Screen`]), gathered by [`live`] on its own
//! thread.
//!
//! [`inspect::estop_action`]: crate::inspect::estop_action
//! [`episode::send`]: crate::episode::send

mod keys;
mod live;
mod screen;

use std::io::IsTerminal;
use std::process::ExitCode;
use std::sync::mpsc::{channel, Sender, TryRecvError};
use std::time::Duration;

use ratatui::crossterm::event::{self, Event, KeyEventKind};
use teleop_msgs::episode_outcome;
use teleop_runtime::{IpcSettings, Namespace};

use crate::episode::{self, Mark};
use crate::inspect;
use keys::{Action, Keys};
use live::Update;
use screen::Screen;

/// Runs the console until `q` (or Ctrl-C, SIGINT, SIGTERM): the namespaces `given`, or else every side found;
/// `task` is the task `s` starts episodes of (without it, `s` asks).
pub fn run(
    ipc: &IpcSettings,
    given: &[Namespace],
    task: Option<String>,
) -> anyhow::Result<ExitCode> {
    // Subscribe before taking the terminal: an error is then printed on a normal terminal.
    let gatherer = live::Gatherer::start(ipc, given)?;
    let mut terminal = ratatui::try_init().map_err(|e| {
        // Raw mode or the alternate screen may have been set before the failure; a terminal
        // gets both undone, anything else raw mode only (no escape codes into a file).
        if std::io::stdout().is_terminal() {
            ratatui::restore();
        } else {
            let _ = ratatui::crossterm::terminal::disable_raw_mode();
        }
        anyhow::anyhow!(
            "teleop top draws on a terminal, and standard input and output are not one ({e})"
        )
    })?;
    let _terminal_back = TerminalGuard;
    let mut keys = Keys {
        task,
        ..Default::default()
    };
    let mut screen = Screen::default();
    let mut message = String::new();
    let (done_tx, done) = channel::<Done>();
    let mut pending: Option<&'static str> = None;
    // Drawn again only when something changed: a new screen, a key, an action's answer.
    let mut changed = true;
    loop {
        match gatherer.updates.try_recv() {
            Ok(Update::Screen(gathered)) => {
                screen = *gathered;
                changed = true;
            }
            Ok(Update::Signal) => return Ok(ExitCode::SUCCESS),
            Ok(Update::Failed(e)) => anyhow::bail!("the console stopped gathering: {e}"),
            Err(TryRecvError::Empty) => {}
            Err(TryRecvError::Disconnected) => anyhow::bail!("the console stopped gathering"),
        }
        while let Ok(d) = done.try_recv() {
            if d.estop {
                pending = None;
            }
            message = d.message;
            changed = true;
        }
        if changed {
            screen.prompt = keys.prompt.clone();
            screen.message = message.clone();
            screen.estop.pending = pending;
            terminal.draw(|frame| screen::draw(frame, &screen))?;
            changed = false;
        }
        // Waiting for a key is the loop's sleep; the screen refreshes as gathered.
        if !event::poll(Duration::from_millis(50))? {
            continue;
        }
        // Every queued key, so that an e-stop behind others is not kept waiting.
        changed = true;
        loop {
            if let Event::Key(key) = event::read()? {
                if key.kind != KeyEventKind::Release {
                    match keys.press(key) {
                        Some(Action::Quit) => return Ok(ExitCode::SUCCESS),
                        Some(action) => {
                            if let Some(what) = act(ipc, given, action, &done_tx) {
                                pending = Some(what);
                            }
                        }
                        None => {}
                    }
                }
            }
            if !event::poll(Duration::ZERO)? {
                break;
            }
        }
    }
}

/// Restores the terminal when the console ends, however it ends (a panic's hook is ratatui's).
struct TerminalGuard;

impl Drop for TerminalGuard {
    fn drop(&mut self) {
        ratatui::restore();
    }
}

/// An action that finished: what it said.
struct Done {
    /// It was an e-stop engage or release.
    estop: bool,
    message: String,
}

/// Starts `action` on a thread of its own; returns what is under way when it is the e-stop's
/// (`engaging the e-stop`, `releasing the e-stop`).
fn act(
    ipc: &IpcSettings,
    given: &[Namespace],
    action: Action,
    done: &Sender<Done>,
) -> Option<&'static str> {
    let under_way = match action {
        Action::EStop => Some("engaging the e-stop"),
        Action::Release => Some("releasing the e-stop"),
        _ => None,
    };
    let (ipc, given, tell) = (ipc.clone(), given.to_vec(), done.clone());
    let work = move || {
        let message = match action {
            Action::EStop => estop_message(inspect::estop_action(&ipc, true, &given)),
            Action::Release => estop_message(inspect::estop_action(&ipc, false, &given)),
            Action::Start(task) => episode_message(
                &format!("start {task:?}"),
                episode::send(&ipc, &Mark::Start { task }),
            ),
            Action::Stop(outcome) => episode_message(
                &format!("stop ({})", episode_outcome::name(outcome)),
                episode::send(&ipc, &Mark::Stop { outcome }),
            ),
            Action::Discard => episode_message("discard", episode::send(&ipc, &Mark::Discard)),
            Action::Quit => return,
        };
        // The console may have quit meanwhile: nobody to tell.
        let _ = tell.send(Done {
            estop: under_way.is_some(),
            message,
        });
    };
    if let Err(e) = std::thread::Builder::new()
        .name("top-action".into())
        .spawn(work)
    {
        let _ = done.send(Done {
            estop: false,
            message: format!("FAILED: cannot start the action: {e}"),
        });
        return None;
    }
    under_way
}

/// What an e-stop engage or release did, in one line: `teleop estop`'s headline, who
/// acknowledged, and what went wrong.
fn estop_message(report: anyhow::Result<inspect::EStopReport>) -> String {
    match report {
        Err(e) => format!("e-stop release FAILED: {e:#}"),
        Ok(report) => {
            // The headline's state, without its explanation (the screen shows the rest).
            let state = report.headline().split(':').next().unwrap_or_default();
            let mut text = state.to_string();
            for line in report.ack_lines() {
                text.push_str(&format!("; {line}"));
            }
            if let Some(problem) = report.problem() {
                text.push_str(&format!("; {}", problem.replace('\n', " ")));
            }
            text
        }
    }
}

/// What an episode mark did: the recorders' answer, or why it failed.
fn episode_message(what: &str, said: anyhow::Result<String>) -> String {
    match said {
        Ok(said) => format!("episode {what}: {}", said.replace('\n', "; ")),
        Err(e) => format!("episode {what} FAILED: {e:#}"),
    }
}
