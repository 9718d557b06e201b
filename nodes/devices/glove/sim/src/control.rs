//! The glove's control socket: the simulator kit's common words and the glove's own
//! (`garbage P`, `corrupt P`, `other-id P`, `late MS`, `state`).

use std::time::Duration;

use teleop_sim_kit::command::{Args, DeviceCommand, ParseError};
use teleop_sim_kit::{Simulator, Stats};

use crate::serve::{Faults, SimGlove};

/// Longest `late` delay, ms: the simulator serves nothing else meanwhile (not even a stop).
pub const MAX_LATE_MS: u64 = 10_000;

/// The glove's own control commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GloveCommand {
    /// `garbage P`: random bytes before an answer, with this probability.
    Garbage(f64),
    /// `corrupt P`: an answer's checksum corrupted, with this probability.
    Corrupt(f64),
    /// `other-id P`: an answer sent as another id, with this probability.
    OtherId(f64),
    /// `late MS`: the next answer this much later than usual.
    Late(Duration),
    /// `state`: the device's force set-points and positions.
    State,
}

impl DeviceCommand for GloveCommand {
    const WORDS: &'static str = "garbage P, corrupt P, other-id P, late MS, state";

    fn parse(word: &str, args: &mut Args<'_>) -> Option<Result<Self, ParseError>> {
        Some(match word {
            "garbage" => args.probability().map(Self::Garbage),
            "corrupt" => args.probability().map(Self::Corrupt),
            "other-id" => args.probability().map(Self::OtherId),
            "late" => args.millis(MAX_LATE_MS).map(Self::Late),
            "state" => Ok(Self::State),
            _ => return None,
        })
    }
}

impl SimGlove {
    /// Changes the fault probabilities; `done` says what changed.
    fn change_faults(
        &self,
        done: String,
        change: impl FnOnce(&mut Faults),
    ) -> Result<String, String> {
        let mut faults = self.faults();
        change(&mut faults);
        self.set_faults(faults);
        tracing::warn!("fault injection now {faults:?}");
        Ok(done)
    }
}

impl Simulator for SimGlove {
    type Command = GloveCommand;

    fn unplug(&self, pause: Duration) -> Result<String, String> {
        SimGlove::unplug(self, pause);
        Ok(format!("unplug {} ms", pause.as_millis()))
    }

    fn set_drop(&self, p: f64) -> Result<String, String> {
        self.change_faults(format!("drop {p}"), |f| f.drop = p)
    }

    fn clear(&self) -> Result<String, String> {
        self.change_faults(String::new(), |f| *f = Faults::default())
    }

    fn stats(&self) -> Stats {
        Stats::new().counters("", &SimGlove::stats(self))
    }

    fn command(&self, command: GloveCommand) -> Result<String, String> {
        match command {
            GloveCommand::Garbage(p) => {
                self.change_faults(format!("garbage {p}"), |f| f.garbage = p)
            }
            GloveCommand::Corrupt(p) => {
                self.change_faults(format!("corrupt {p}"), |f| f.corrupt = p)
            }
            GloveCommand::OtherId(p) => {
                self.change_faults(format!("other-id {p}"), |f| f.other_id = p)
            }
            GloveCommand::Late(by) => {
                self.answer_late(by);
                Ok(format!("late {} ms", by.as_millis()))
            }
            GloveCommand::State => Ok(match self.device() {
                Some(d) => format!(
                    "id={} baud={} force_set={:?} positions={:?}",
                    d.id,
                    d.baud.bits_per_second(),
                    d.force_set,
                    d.positions
                ),
                None => "no exchange yet".into(),
            }),
        }
    }
}
