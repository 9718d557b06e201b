//! `teleop episode start|stop|discard`: the operator's episode marks (the `episode` topic,
//! without a namespace: one operator's episode covers every side), acknowledged by the running
//! recorders.
//!
//! A mark is only worth sending when a recorder takes it: before sending, the command listens to
//! the recorders' health reports for a report period (each carries `episode_marks`, the marks
//! it has written with what they changed, and `episode_ignored`, those that changed nothing),
//! then sends the mark and waits until every recorder heard counts it; it says what the
//! recorder now holds (the episode's number, open or closed). No recorder, one that does not
//! count the mark in time, or one that ignored it (a STOP with no episode open) is an error:
//! the operator must know.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use teleop_msgs::{episode_event, episode_outcome, fixed_text, Episode, NodeHealth};
use teleop_runtime::{IpcSettings, NodeRuntime};

/// How long to wait for the recorders' first health reports (they report every 500 ms).
const FIND_RECORDERS: Duration = Duration::from_millis(1500);
/// How long to go on listening once a recorder reported: every recorder reports within it.
const LISTEN: Duration = Duration::from_millis(600);
/// How long a recorder has to count the mark.
const ACK_WAIT: Duration = Duration::from_secs(3);
/// The health detail a recorder counts marks in.
const MARKS: &str = "episode_marks";
/// The health detail a recorder counts ignored marks in.
const IGNORED: &str = "episode_ignored";

/// An episode mark.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Mark {
    /// Begin an episode of this task.
    Start {
        /// The task, in words (at most [`teleop_msgs::EPISODE_TASK_BYTES`] bytes).
        task: String,
    },
    /// End the open episode ([`episode_outcome`]).
    Stop {
        /// How it ended.
        outcome: u8,
    },
    /// Throw away the open episode, or the last one closed.
    Discard,
}

impl Mark {
    /// The payload (the header is stamped when it is sent).
    fn payload(&self) -> Episode {
        let mut m = Episode::default();
        match self {
            Mark::Start { task } => {
                m.event = episode_event::START;
                m.task = fixed_text(task);
            }
            Mark::Stop { outcome } => {
                m.event = episode_event::STOP;
                m.outcome = *outcome;
            }
            Mark::Discard => m.event = episode_event::DISCARD,
        }
        m
    }
}

/// Checks a task text: not empty, fits the payload.
pub fn parse_task(s: &str) -> Result<String, String> {
    let task = s.trim();
    if task.is_empty() {
        return Err("the task is empty: say in words what the episode does".into());
    }
    if task.len() > teleop_msgs::EPISODE_TASK_BYTES {
        return Err(format!(
            "the task is {} bytes; at most {} fit",
            task.len(),
            teleop_msgs::EPISODE_TASK_BYTES
        ));
    }
    Ok(task.to_string())
}

/// Sends `mark` and waits until every running recorder has counted it; returns what the
/// recorders now hold, one line each (`recorder: episode 3 open, 1.2 s`).
pub fn send(ipc: &IpcSettings, mark: &Mark) -> anyhow::Result<String> {
    let runtime = NodeRuntime::new("teleop-episode", ipc)?;
    let health = runtime.subscriber::<NodeHealth>()?;
    let mut recorders: BTreeMap<String, NodeHealth> = BTreeMap::new();
    let mut deadline = Instant::now() + FIND_RECORDERS;
    while Instant::now() < deadline {
        health.drain(|h| {
            if h.detail(MARKS).is_some() {
                recorders.insert(h.name(), *h);
            }
        });
        if !recorders.is_empty() {
            deadline = deadline.min(Instant::now() + LISTEN);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    if recorders.is_empty() {
        anyhow::bail!(
            "no recorder is running on this pipeline (no recorder's health report within {} ms); \
             the mark was not sent: start the session's recorder, or `teleop record`",
            FIND_RECORDERS.as_millis()
        );
    }
    let taken = |h: &NodeHealth| h.detail(MARKS).unwrap_or(0.0) + h.detail(IGNORED).unwrap_or(0.0);
    let before: BTreeMap<String, f64> = recorders
        .iter()
        .map(|(name, h)| (name.clone(), taken(h)))
        .collect();
    // The publisher stays until the recorders counted the mark (iceoryx2 takes back the
    // samples of a publisher that is gone before they are read).
    let mut publisher = runtime.publisher::<Episode>()?;
    publisher.publish(&mark.payload())?;
    let deadline = Instant::now() + ACK_WAIT;
    let mut counted: BTreeMap<String, NodeHealth> = BTreeMap::new();
    while counted.len() < before.len() && Instant::now() < deadline {
        health.drain(|h| {
            let name = h.name();
            if before.get(&name).is_some_and(|was| taken(h) > *was) {
                counted.insert(name, *h);
            }
        });
        std::thread::sleep(Duration::from_millis(20));
    }
    let missing: Vec<&String> = before
        .keys()
        .filter(|n| !counted.contains_key(*n))
        .collect();
    if !missing.is_empty() {
        anyhow::bail!(
            "the mark was sent, but {} did not count it within {} ms: check that recorder \
             (`teleop stats`) before going on",
            missing
                .iter()
                .map(|n| n.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            ACK_WAIT.as_millis()
        );
    }
    let ignored: Vec<&String> = counted
        .iter()
        .filter(|(name, h)| {
            h.detail(IGNORED) > recorders.get(*name).and_then(|r| r.detail(IGNORED))
        })
        .map(|(name, _)| name)
        .collect();
    if !ignored.is_empty() {
        let why = match mark {
            Mark::Stop { .. } => "no episode is open",
            Mark::Discard => "there is no episode left to discard",
            Mark::Start { .. } => "the recorder refused it",
        };
        anyhow::bail!(
            "{} ignored the mark: {why} ({})",
            ignored
                .iter()
                .map(|n| n.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            counted
                .values()
                .map(describe)
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
    Ok(counted
        .iter()
        .map(|(name, h)| format!("{name}: {}", describe(h)))
        .collect::<Vec<_>>()
        .join("\n"))
}

/// A recorder's episode as its health report gives it: `episode 3 open, 12.0 s`,
/// `episode 3 closed (12.0 s), 2 kept`, `no episode`.
pub fn describe(h: &NodeHealth) -> String {
    let index = h.detail("episode").unwrap_or(0.0);
    let seconds = h.detail("episode_s").unwrap_or(0.0);
    let kept = h.detail("episodes_kept").unwrap_or(0.0);
    if index < 1.0 {
        return "no episode".into();
    }
    if h.detail("episode_open") == Some(1.0) {
        format!("episode {index:.0} open, {seconds:.1} s")
    } else {
        format!("episode {index:.0} closed ({seconds:.1} s), {kept:.0} kept")
    }
}

/// `teleop episode stop`'s flags as an outcome.
pub fn outcome(success: bool, failure: bool) -> u8 {
    match (success, failure) {
        (true, _) => episode_outcome::SUCCESS,
        (_, true) => episode_outcome::FAILURE,
        _ => episode_outcome::UNLABELLED,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marks_become_payloads() {
        let start = Mark::Start {
            task: "pick the ball".into(),
        }
        .payload();
        assert_eq!(
            (start.event, start.task()),
            (episode_event::START, "pick the ball".into())
        );
        let stop = Mark::Stop {
            outcome: outcome(false, true),
        }
        .payload();
        assert_eq!(
            (stop.event, stop.outcome),
            (episode_event::STOP, episode_outcome::FAILURE)
        );
        assert_eq!(Mark::Discard.payload().event, episode_event::DISCARD);
        assert_eq!(outcome(false, false), episode_outcome::UNLABELLED);
    }

    #[test]
    fn tasks_are_checked() {
        assert_eq!(parse_task("  pour  ").as_deref(), Ok("pour"));
        assert!(parse_task(" ").is_err());
        assert!(parse_task(&"x".repeat(121)).is_err());
        assert!(parse_task(&"x".repeat(120)).is_ok());
    }

    #[test]
    fn a_recorders_report_reads_as_its_episode() {
        let mut h = NodeHealth::default();
        assert_eq!(describe(&h), "no episode");
        h.set_detail("episode", 3.0);
        h.set_detail("episode_open", 1.0);
        h.set_detail("episode_s", 1.3);
        assert_eq!(describe(&h), "episode 3 open, 1.3 s");
        h.set_detail("episode_open", 0.0);
        h.set_detail("episodes_kept", 2.0);
        assert_eq!(describe(&h), "episode 3 closed (1.3 s), 2 kept");
    }
}
