//! Episodes: the operator's marks on the `episode` channel ([`teleop_msgs::Episode`]) turned
//! into spans of the recording.
//!
//! One rule, used by the recorder while it records (to close an episode with its health) and by
//! whoever reads a recording afterwards (the dataset export): a START opens an episode (an
//! episode still open is first closed, unlabelled); a STOP closes the open one with its
//! outcome; a DISCARD throws away the open episode, or else the last one closed, once. A mark
//! that asks for something impossible (a STOP with nothing open) changes nothing and says why.
//! Episodes are numbered from 1 in the order they start; times are the marks' own stamps
//! (`header.stamp_ns`, CLOCK_MONOTONIC), the clock of every sample's stamp.

use std::path::Path;

use teleop_msgs::{episode_event, episode_outcome, Episode, Message};

use crate::{read_messages, Filter, RecordingError};

/// One episode between its START and its STOP (or the START of the next).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EpisodeSpan {
    /// The episode's number in its recording, from 1.
    pub index: u32,
    /// The task given at its START.
    pub task: String,
    /// How it ended ([`episode_outcome`]).
    pub outcome: u8,
    /// Its START's stamp (ns).
    pub start_ns: u64,
    /// Its STOP's stamp (ns); an episode closed by the next START ends at that START.
    pub stop_ns: u64,
    /// Thrown away by a DISCARD.
    pub discarded: bool,
}

impl EpisodeSpan {
    /// The outcome's name, or `discarded`.
    pub fn label(&self) -> &'static str {
        if self.discarded {
            "discarded"
        } else {
            episode_outcome::name(self.outcome)
        }
    }

    /// Its length in seconds.
    pub fn duration_s(&self) -> f64 {
        self.stop_ns.saturating_sub(self.start_ns) as f64 * 1e-9
    }
}

/// An episode started and not yet stopped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OpenEpisode {
    /// Its number, from 1.
    pub index: u32,
    /// Its task.
    pub task: String,
    /// Its START's stamp (ns).
    pub start_ns: u64,
}

/// What one mark changed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Change {
    /// This episode began.
    Started(OpenEpisode),
    /// This episode ended (not discarded).
    Closed(EpisodeSpan),
    /// This episode was thrown away; `was_open` when it had not been closed.
    Discarded {
        /// The episode's number.
        index: u32,
        /// It was still open.
        was_open: bool,
    },
    /// Nothing changed, and why.
    Ignored(&'static str),
}

/// The episodes of one recording (or of its rotated parts in order), as the marks arrive.
#[derive(Debug, Clone, Default)]
pub struct Episodes {
    closed: Vec<EpisodeSpan>,
    open: Option<OpenEpisode>,
    started: u32,
}

impl Episodes {
    /// No episode yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Applies one mark: what changed, in order (a START over an open episode closes it first).
    pub fn apply(&mut self, mark: &Episode) -> Vec<Change> {
        let at = mark.header.stamp_ns;
        match mark.event {
            episode_event::START => {
                let mut changes = Vec::with_capacity(2);
                if let Some(span) = self.close(at, episode_outcome::UNLABELLED) {
                    changes.push(Change::Closed(span));
                }
                self.started += 1;
                let open = OpenEpisode {
                    index: self.started,
                    task: mark.task(),
                    start_ns: at,
                };
                self.open = Some(open.clone());
                changes.push(Change::Started(open));
                changes
            }
            episode_event::STOP => match self.close(at, mark.outcome) {
                Some(span) => vec![Change::Closed(span)],
                None => vec![Change::Ignored("no episode is open")],
            },
            episode_event::DISCARD => {
                if let Some(open) = self.open.take() {
                    self.closed.push(EpisodeSpan {
                        index: open.index,
                        task: open.task,
                        outcome: episode_outcome::UNLABELLED,
                        start_ns: open.start_ns,
                        stop_ns: at,
                        discarded: true,
                    });
                    return vec![Change::Discarded {
                        index: open.index,
                        was_open: true,
                    }];
                }
                match self.closed.last_mut() {
                    Some(last) if !last.discarded => {
                        last.discarded = true;
                        vec![Change::Discarded {
                            index: last.index,
                            was_open: false,
                        }]
                    }
                    Some(_) => vec![Change::Ignored("the last episode is already discarded")],
                    None => vec![Change::Ignored("there is no episode to discard")],
                }
            }
            _ => vec![Change::Ignored("not an episode event")],
        }
    }

    fn close(&mut self, at: u64, outcome: u8) -> Option<EpisodeSpan> {
        let open = self.open.take()?;
        let span = EpisodeSpan {
            index: open.index,
            task: open.task,
            outcome,
            start_ns: open.start_ns,
            stop_ns: at.max(open.start_ns),
            discarded: false,
        };
        self.closed.push(span.clone());
        Some(span)
    }

    /// Every episode closed so far (discarded ones marked), in order.
    pub fn closed(&self) -> &[EpisodeSpan] {
        &self.closed
    }

    /// The episode open now, if any.
    pub fn open(&self) -> Option<&OpenEpisode> {
        self.open.as_ref()
    }

    /// The closed episodes that were not discarded.
    pub fn kept(&self) -> impl Iterator<Item = &EpisodeSpan> {
        self.closed.iter().filter(|e| !e.discarded)
    }
}

/// The episodes of a recording given as its files in order (a rotated recording's parts): the
/// marks of every file's `episode` channel applied in turn.
pub fn read_episodes(files: &[impl AsRef<Path>]) -> Result<Episodes, RecordingError> {
    let mut episodes = Episodes::new();
    for file in files {
        for msg in read_messages(file.as_ref(), &Filter::topics([Episode::TOPIC]))? {
            if let Some(mark) = msg?.decode::<Episode>() {
                episodes.apply(&mark);
            }
        }
    }
    Ok(episodes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use teleop_msgs::fixed_text;

    fn mark(event: u8, outcome: u8, task: &str, at: u64) -> Episode {
        let mut m = Episode {
            event,
            outcome,
            task: fixed_text(task),
            ..Episode::default()
        };
        m.header.stamp_ns = at;
        m
    }

    #[test]
    fn start_stop_discard_follow_the_one_rule() {
        let mut e = Episodes::new();
        assert_eq!(
            e.apply(&mark(episode_event::STOP, 1, "", 5)),
            [Change::Ignored("no episode is open")]
        );
        assert!(matches!(
            e.apply(&mark(episode_event::START, 0, "pick", 10))[..],
            [Change::Started(OpenEpisode { index: 1, .. })]
        ));
        assert!(matches!(
            e.apply(&mark(episode_event::STOP, episode_outcome::SUCCESS, "", 20))[..],
            [Change::Closed(EpisodeSpan {
                index: 1,
                outcome: episode_outcome::SUCCESS,
                start_ns: 10,
                stop_ns: 20,
                ..
            })]
        ));
        // A START over an open episode closes it unlabelled first.
        e.apply(&mark(episode_event::START, 0, "place", 30));
        let changes = e.apply(&mark(episode_event::START, 0, "pour", 40));
        assert!(matches!(
            changes[..],
            [
                Change::Closed(EpisodeSpan {
                    index: 2,
                    outcome: episode_outcome::UNLABELLED,
                    stop_ns: 40,
                    ..
                }),
                Change::Started(OpenEpisode { index: 3, .. })
            ]
        ));
        // DISCARD throws away the open one, then the last closed one, never twice.
        assert_eq!(
            e.apply(&mark(episode_event::DISCARD, 0, "", 45)),
            [Change::Discarded {
                index: 3,
                was_open: true
            }]
        );
        assert_eq!(
            e.apply(&mark(episode_event::DISCARD, 0, "", 46)),
            [Change::Ignored("the last episode is already discarded")]
        );
        assert!(e.open().is_none());
        let kept: Vec<_> = e
            .kept()
            .map(|s| (s.index, s.task.as_str(), s.label()))
            .collect();
        assert_eq!(kept, [(1, "pick", "success"), (2, "place", "unlabelled")]);
        assert_eq!(e.closed()[2].label(), "discarded");
        assert_eq!(e.closed()[2].task, "pour");
    }

    #[test]
    fn discarding_the_last_closed_episode() {
        let mut e = Episodes::new();
        assert_eq!(
            e.apply(&mark(episode_event::DISCARD, 0, "", 1)),
            [Change::Ignored("there is no episode to discard")]
        );
        e.apply(&mark(episode_event::START, 0, "a", 10));
        e.apply(&mark(episode_event::STOP, episode_outcome::FAILURE, "", 20));
        assert_eq!(
            e.apply(&mark(episode_event::DISCARD, 0, "", 30)),
            [Change::Discarded {
                index: 1,
                was_open: false
            }]
        );
        assert_eq!(e.kept().count(), 0);
        assert_eq!(e.closed()[0].stop_ns, 20);
        assert_eq!(
            e.apply(&mark(9, 0, "", 40)),
            [Change::Ignored("not an episode event")]
        );
    }
}
