//! `teleop top`: the operator's console, a terminal UI over a running session.
//!
//! Owns the console's loop: the terminal (raw mode and the alternate screen, restored on exit,
//! on error and on panic), the keys ([`keys`]) and their actions, none of which holds the loop
//! up: the e-stop is `teleop estop`'s own code, its latches written at once and the rest run in
//! order on one worker thread ([`estop`]); episodes are `teleop episode`'s
//! ([`episode::send`]), one at a time on a thread of their own. What is shown is [`screen`]'s
//! (pure drawing from a [`Screen`]), gathered by [`live`] on its own thread, which the loop never
//! waits for: the screen says when its values are old, and a failed gathering is started again
//! ([`live::Gathering`]). Quitting (`q`, Ctrl-C, SIGINT, SIGTERM) waits for the e-stop's actions under way.
//!
//! [`episode::send`]: crate::episode::send

mod estop;
mod keys;
mod live;
mod screen;

use std::io::IsTerminal;
use std::process::ExitCode;
use std::sync::mpsc::{channel, Sender};
use std::time::{Duration, Instant};

use ratatui::crossterm::event::{self, Event};
use teleop_msgs::episode_outcome;
use teleop_runtime::{IpcSettings, Namespace};

use crate::episode::{self, Mark};
use keys::{Action, Keys, Read};
use screen::Screen;

/// How long quitting waits for the e-stop's actions under way (an engage waits at most a second
/// for its acknowledgements, a release five: a release, an engage and another release queued
/// take about 11 s).
const QUIT_WAIT: Duration = Duration::from_secs(15);

/// Runs the console until `q` (or Ctrl-C, SIGINT, SIGTERM): the namespaces `given`, or else every side found;
/// `task` is the task `s` starts episodes of (without it, `s` asks).
pub fn run(
    ipc: &IpcSettings,
    given: &[Namespace],
    task: Option<String>,
) -> anyhow::Result<ExitCode> {
    // Subscribe before taking the terminal: an error is then printed on a normal terminal.
    let mut gathering = live::Gathering::new(live::Gatherer::start(ipc, given)?, Instant::now());
    // SIGINT and SIGTERM are recorded, for this loop to read, whatever the gathering does.
    teleop_runtime::take_over_stop_signals();
    let (done_tx, done) = channel::<Done>();
    let worker = estop::EStopWorker::start(ipc, given, done_tx.clone())?;
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
    let mut keys = Keys::new(task);
    let mut screen = Screen::default();
    let mut message = String::new();
    // The e-stop actions queued on the worker and not done, and the last one's words.
    let mut estop_in_flight = 0usize;
    let mut pending: Option<&'static str> = None;
    let mut episode_busy = false;
    // Quitting: until when it waits for the e-stop's actions.
    let mut quitting: Option<Instant> = None;
    let mut batch = 0u64;
    // Drawn again only when something changed: a new screen, a key, an action's answer.
    let mut changed = true;
    loop {
        let now = Instant::now();
        if quitting.is_none() && teleop_runtime::stop_signal().is_some() {
            quitting = Some(now + QUIT_WAIT);
            changed = true;
        }
        if let Some(deadline) = quitting {
            if estop_in_flight == 0 {
                return Ok(ExitCode::SUCCESS);
            }
            if now >= deadline {
                anyhow::bail!(
                    "the console quit before the e-stop's actions were done ({}, waited {} s): \
                     see `teleop stats` and run `teleop estop` again",
                    pending.unwrap_or("e-stop action"),
                    QUIT_WAIT.as_secs()
                );
            }
        }
        let (gathered, gathering_changed) =
            gathering.poll(now, || live::Gatherer::spawn(ipc, given));
        if let Some(gathered) = gathered {
            screen = gathered;
            if keys.estop_shown(screen.estop.engaged()) {
                message = "release not asked: the e-stop changed meanwhile".into();
            }
            changed = true;
        }
        changed |= gathering_changed;
        let stale = gathering.stale_s(now);
        if stale != screen.stale_s {
            screen.stale_s = stale;
            changed = true;
        }
        if keys.expire(now) {
            message = format!(
                "release not asked: no `y` within {} s",
                keys::CONFIRM_FOR.as_secs()
            );
            changed = true;
        }
        while let Ok(d) = done.try_recv() {
            if d.estop {
                estop_in_flight = estop_in_flight.saturating_sub(1);
                if estop_in_flight == 0 {
                    pending = None;
                }
            } else {
                episode_busy = false;
            }
            message = d.message;
            changed = true;
        }
        if changed {
            screen.prompt = keys.prompt.clone();
            screen.message = match quitting {
                Some(_) => format!("quitting once the e-stop's actions are done; {message}"),
                None => message.clone(),
            };
            screen.estop.pending = pending;
            screen.gathering = gathering
                .failed
                .as_ref()
                .map(|e| format!("gathering failed ({e}); starting it again"));
            terminal.draw(|frame| screen::draw(frame, &screen))?;
            changed = false;
        }
        // Waiting for a key is the loop's sleep; the screen refreshes as gathered.
        if !key_waiting(Duration::from_millis(50))? {
            continue;
        }
        // Every queued key, so that an e-stop behind others is not kept waiting: one read of
        // the keyboard (a `y` must come in a later one than its `r`).
        changed = true;
        batch += 1;
        let read = Read {
            at: Instant::now(),
            batch,
        };
        loop {
            if let Event::Key(key) = event::read()? {
                match keys.press(key, read) {
                    None => {}
                    Some(Action::NotReleased(why)) => {
                        message = format!("release not asked: {why}");
                    }
                    Some(Action::Quit) => {
                        quitting.get_or_insert(Instant::now() + QUIT_WAIT);
                    }
                    Some(Action::EStop) => {
                        let engaged = worker.engage();
                        message = engaged.message;
                        if engaged.queued {
                            estop_in_flight += 1;
                            pending = Some("ringing the e-stop's doorbells");
                        }
                    }
                    Some(Action::Release) => {
                        if worker.release() {
                            estop_in_flight += 1;
                            pending = Some("releasing the e-stop");
                            message = "releasing the e-stop".into();
                        } else {
                            message = "e-stop release FAILED: the e-stop's worker ended".into();
                        }
                    }
                    Some(action) => {
                        if let Some((what, mark)) = episode_mark(action) {
                            if episode_busy {
                                message = format!(
                                    "busy: the last episode action is not done; episode {what} \
                                     not sent"
                                );
                            } else {
                                episode_busy = send_episode(ipc, what, mark, &done_tx);
                            }
                        }
                    }
                }
            }
            if !key_waiting(Duration::ZERO)? {
                break;
            }
        }
    }
}

/// Whether a key (or another terminal event) is waiting, after waiting at most `timeout`; a
/// wait cut short by a signal is no event (the loop reads the signal).
fn key_waiting(timeout: Duration) -> std::io::Result<bool> {
    match event::poll(timeout) {
        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => Ok(false),
        other => other,
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
pub struct Done {
    /// It was an e-stop engage or release (else an episode mark).
    pub estop: bool,
    pub message: String,
}

/// The episode mark `action` asks for, in words and as sent; `None` for the other actions.
fn episode_mark(action: Action) -> Option<(String, Mark)> {
    Some(match action {
        Action::Start(task) => (format!("start {task:?}"), Mark::Start { task }),
        Action::Stop(outcome) => (
            format!("stop ({})", episode_outcome::name(outcome)),
            Mark::Stop { outcome },
        ),
        Action::Discard => ("discard".into(), Mark::Discard),
        Action::EStop | Action::Release | Action::NotReleased(_) | Action::Quit => return None,
    })
}

/// Sends the episode mark on a thread of its own; false when the thread could not start (said
/// on `done`).
fn send_episode(ipc: &IpcSettings, what: String, mark: Mark, done: &Sender<Done>) -> bool {
    let (ipc, tell) = (ipc.clone(), done.clone());
    let work = move || {
        let message = episode_message(&what, episode::send(&ipc, &mark));
        // The console may have quit meanwhile: nobody to tell.
        let _ = tell.send(Done {
            estop: false,
            message,
        });
    };
    match std::thread::Builder::new()
        .name("top-episode".into())
        .spawn(work)
    {
        Ok(_) => true,
        Err(e) => {
            let _ = done.send(Done {
                estop: false,
                message: format!("episode mark FAILED: cannot start its thread: {e}"),
            });
            false
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_episode_actions_are_marks() {
        assert!(matches!(
            episode_mark(Action::Stop(episode_outcome::FAILURE)),
            Some((what, Mark::Stop { .. })) if what == "stop (failure)"
        ));
        for other in [
            Action::EStop,
            Action::Release,
            Action::NotReleased(""),
            Action::Quit,
        ] {
            assert!(episode_mark(other).is_none());
        }
    }
}
