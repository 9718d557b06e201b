//! The console's keys: what each does in each state (no prompt, the release confirmation, the
//! task prompt), pure, so that tests press keys without a terminal.
//!
//! The e-stop is one key in every state: `Esc` always; `e`, `E` (caps lock) and space too,
//! except while a task is typed (where they are text). Any e-stop closes the open prompt. A key
//! held down repeats only the e-stop.
//!
//! The release asks for `y`, and takes it only from a later read of the keyboard than its `r`
//! (so after the screen showed the question: a pasted `ry` does not release), within
//! [`CONFIRM_FOR`], and while the e-stop stays as it was when `r` was pressed.

use std::time::{Duration, Instant};

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyEventKind, KeyModifiers};
use teleop_msgs::episode_outcome;

/// How long the release question waits for its `y`.
pub const CONFIRM_FOR: Duration = Duration::from_secs(5);

/// When a key was read: the time, and which read of the keyboard (the console counts them; the
/// keys queued at one wake are one read).
#[derive(Debug, Clone, Copy)]
pub struct Read {
    pub at: Instant,
    pub batch: u64,
}

/// The prompt open at the foot of the screen.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub enum Prompt {
    /// None: the keys are the commands.
    #[default]
    None,
    /// `r` was pressed: `y` releases the e-stop, any other key keeps it.
    ConfirmRelease,
    /// `s` was pressed without `--task`: the task typed so far.
    Task(String),
}

/// What a key asks for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Action {
    EStop,
    Release,
    /// The release question was answered otherwise than with a `y` after it was shown: why.
    NotReleased(&'static str),
    Start(String),
    /// Stop the open episode with this [`episode_outcome`].
    Stop(u8),
    Discard,
    Quit,
}

/// The console's key state: the open prompt and the task to start episodes of.
#[derive(Debug, Clone, Default)]
pub struct Keys {
    pub prompt: Prompt,
    /// `--task`, or the last task typed: `s` starts an episode of it without asking.
    pub task: Option<String>,
    /// While [`Prompt::ConfirmRelease`] is open: the read its `r` came in.
    asked: Option<Read>,
    /// The e-stop state last shown ([`Keys::estop_shown`]).
    engaged: Option<bool>,
}

impl Keys {
    /// Keys with `task` as the task of `s`.
    pub fn new(task: Option<String>) -> Self {
        Self {
            task,
            ..Default::default()
        }
    }

    /// Closes the release question once [`CONFIRM_FOR`] has passed since its `r`; true when it
    /// closed it.
    pub fn expire(&mut self, now: Instant) -> bool {
        match self.asked {
            Some(asked) if now.saturating_duration_since(asked.at) >= CONFIRM_FOR => {
                self.close();
                true
            }
            _ => false,
        }
    }

    /// The e-stop state the screen shows now: a change closes the release question (it was
    /// asked about another state). True when it closed it.
    pub fn estop_shown(&mut self, engaged: bool) -> bool {
        let changed = self.engaged.is_some_and(|was| was != engaged);
        self.engaged = Some(engaged);
        if changed && self.prompt == Prompt::ConfirmRelease {
            self.close();
            return true;
        }
        false
    }

    fn close(&mut self) {
        self.prompt = Prompt::None;
        self.asked = None;
    }

    /// Takes one key event read at `read` (a release of a key is nothing); returns what it asks
    /// for, if anything.
    pub fn press(&mut self, key: KeyEvent, read: Read) -> Option<Action> {
        let estop = match key.code {
            KeyCode::Esc => true,
            KeyCode::Char('e' | 'E' | ' ') => !matches!(self.prompt, Prompt::Task(_)),
            _ => false,
        };
        if estop && key.kind != KeyEventKind::Release {
            self.close();
            return Some(Action::EStop);
        }
        // A key held down repeats the e-stop only; a key let go is nothing.
        if key.kind != KeyEventKind::Press {
            return None;
        }
        self.expire(read.at);
        let ctrl_c =
            key.code == KeyCode::Char('c') && key.modifiers.contains(KeyModifiers::CONTROL);
        if ctrl_c {
            return Some(Action::Quit);
        }
        if let Prompt::Task(text) = &mut self.prompt {
            match key.code {
                KeyCode::Enter => {
                    let task = crate::episode::parse_task(text).ok();
                    self.prompt = Prompt::None;
                    if let Some(task) = &task {
                        self.task = Some(task.clone());
                    }
                    return task.map(Action::Start);
                }
                KeyCode::Backspace => {
                    text.pop();
                }
                KeyCode::Char(c)
                    if text.len() + c.len_utf8() <= teleop_msgs::EPISODE_TASK_BYTES =>
                {
                    text.push(c);
                }
                _ => {}
            }
            return None;
        }
        if self.prompt == Prompt::ConfirmRelease {
            // A `y` read with its `r` (pasted) was not an answer to the question shown.
            let answered = self.asked.is_some_and(|asked| read.batch > asked.batch);
            self.close();
            return Some(match (key.code == KeyCode::Char('y'), answered) {
                (true, true) => Action::Release,
                (true, false) => Action::NotReleased("the `y` came with its `r` (pasted?)"),
                (false, _) => Action::NotReleased("a key other than `y`"),
            });
        }
        match key.code {
            KeyCode::Char('r') => {
                self.prompt = Prompt::ConfirmRelease;
                self.asked = Some(read);
                None
            }
            KeyCode::Char('s') => match &self.task {
                Some(task) => Some(Action::Start(task.clone())),
                None => {
                    self.prompt = Prompt::Task(String::new());
                    None
                }
            },
            KeyCode::Char('k') => Some(Action::Stop(episode_outcome::SUCCESS)),
            KeyCode::Char('f') => Some(Action::Stop(episode_outcome::FAILURE)),
            KeyCode::Char('d') => Some(Action::Discard),
            KeyCode::Char('q') => Some(Action::Quit),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(code: KeyCode) -> KeyEvent {
        KeyEvent::new(code, KeyModifiers::NONE)
    }

    /// A read of the keyboard `batch` at `at`.
    fn read(at: Instant, batch: u64) -> Read {
        Read { at, batch }
    }

    /// `key` pressed in a read of its own (the next batch), now.
    fn press(keys: &mut Keys, key: KeyEvent) -> Option<Action> {
        use std::sync::atomic::{AtomicU64, Ordering};
        static BATCH: AtomicU64 = AtomicU64::new(1);
        let batch = BATCH.fetch_add(1, Ordering::Relaxed);
        keys.press(key, read(Instant::now(), batch))
    }

    fn typed(keys: &mut Keys, text: &str) -> Vec<Option<Action>> {
        text.chars()
            .map(|c| press(keys, key(KeyCode::Char(c))))
            .collect()
    }

    #[test]
    fn the_estop_is_one_key_in_every_state() {
        for estop in [KeyCode::Esc, KeyCode::Char('e'), KeyCode::Char(' ')] {
            let mut keys = Keys::default();
            assert_eq!(press(&mut keys, key(estop)), Some(Action::EStop));
            press(&mut keys, key(KeyCode::Char('r')));
            assert_eq!(keys.prompt, Prompt::ConfirmRelease);
            assert_eq!(press(&mut keys, key(estop)), Some(Action::EStop));
            assert_eq!(keys.prompt, Prompt::None);
        }
        // While a task is typed, Esc engages it (and e and space are text).
        let mut keys = Keys::default();
        press(&mut keys, key(KeyCode::Char('s')));
        assert!(typed(&mut keys, "e ").iter().all(Option::is_none));
        assert_eq!(keys.prompt, Prompt::Task("e ".into()));
        assert_eq!(press(&mut keys, key(KeyCode::Esc)), Some(Action::EStop));
        assert_eq!(keys.prompt, Prompt::None);
    }

    #[test]
    fn release_needs_its_confirmation() {
        let mut keys = Keys::default();
        assert_eq!(press(&mut keys, key(KeyCode::Char('r'))), None);
        assert_eq!(
            press(&mut keys, key(KeyCode::Char('y'))),
            Some(Action::Release)
        );
        press(&mut keys, key(KeyCode::Char('r')));
        assert_eq!(
            press(&mut keys, key(KeyCode::Char('n'))),
            Some(Action::NotReleased("a key other than `y`"))
        );
        assert_eq!(keys.prompt, Prompt::None);
        // `y` alone does nothing.
        assert_eq!(press(&mut keys, key(KeyCode::Char('y'))), None);
    }

    #[test]
    fn episodes_ask_for_their_task_once() {
        let mut keys = Keys::default();
        assert_eq!(press(&mut keys, key(KeyCode::Char('s'))), None);
        typed(&mut keys, "pick the ball");
        press(&mut keys, key(KeyCode::Backspace));
        assert_eq!(
            press(&mut keys, key(KeyCode::Enter)),
            Some(Action::Start("pick the bal".into()))
        );
        // The next start takes the same task without asking.
        assert_eq!(
            press(&mut keys, key(KeyCode::Char('s'))),
            Some(Action::Start("pick the bal".into()))
        );
        assert_eq!(
            press(&mut keys, key(KeyCode::Char('k'))),
            Some(Action::Stop(episode_outcome::SUCCESS))
        );
        assert_eq!(
            press(&mut keys, key(KeyCode::Char('f'))),
            Some(Action::Stop(episode_outcome::FAILURE))
        );
        assert_eq!(
            press(&mut keys, key(KeyCode::Char('d'))),
            Some(Action::Discard)
        );
        // An empty task cancels.
        let mut keys = Keys::default();
        press(&mut keys, key(KeyCode::Char('s')));
        typed(&mut keys, "  ");
        assert_eq!(press(&mut keys, key(KeyCode::Enter)), None);
        assert_eq!((keys.prompt, keys.task), (Prompt::None, None));
    }

    #[test]
    fn q_and_ctrl_c_quit_but_q_is_text_in_a_task() {
        let mut keys = Keys::default();
        assert_eq!(
            press(&mut keys, key(KeyCode::Char('q'))),
            Some(Action::Quit)
        );
        press(&mut keys, key(KeyCode::Char('s')));
        assert_eq!(press(&mut keys, key(KeyCode::Char('q'))), None);
        assert_eq!(
            press(
                &mut keys,
                KeyEvent::new(KeyCode::Char('c'), KeyModifiers::CONTROL)
            ),
            Some(Action::Quit)
        );
    }

    #[test]
    fn shifted_e_engages_too() {
        let mut keys = Keys::default();
        let shifted = KeyEvent::new(KeyCode::Char('E'), KeyModifiers::SHIFT);
        assert_eq!(press(&mut keys, shifted), Some(Action::EStop));
        // Caps lock on, no shift.
        assert_eq!(
            press(&mut keys, key(KeyCode::Char('E'))),
            Some(Action::EStop)
        );
    }

    #[test]
    fn a_y_read_with_its_r_does_not_release() {
        let mut keys = Keys::default();
        let now = Instant::now();
        // Pasted "ry": one read of the keyboard.
        assert_eq!(keys.press(key(KeyCode::Char('r')), read(now, 7)), None);
        assert_eq!(
            keys.press(key(KeyCode::Char('y')), read(now, 7)),
            Some(Action::NotReleased("the `y` came with its `r` (pasted?)"))
        );
        assert_eq!(keys.prompt, Prompt::None);
        // The same keys in two reads release.
        keys.press(key(KeyCode::Char('r')), read(now, 8));
        assert_eq!(
            keys.press(key(KeyCode::Char('y')), read(now, 9)),
            Some(Action::Release)
        );
    }

    #[test]
    fn the_release_question_expires() {
        let mut keys = Keys::default();
        let asked = Instant::now();
        keys.press(key(KeyCode::Char('r')), read(asked, 1));
        let almost = asked + CONFIRM_FOR - Duration::from_millis(1);
        assert!(!keys.expire(almost));
        assert_eq!(keys.prompt, Prompt::ConfirmRelease);
        // A `y` after the time is up releases nothing, even before the screen closed it.
        let late = asked + CONFIRM_FOR;
        assert_eq!(keys.press(key(KeyCode::Char('y')), read(late, 2)), None);
        assert_eq!(keys.prompt, Prompt::None);
        keys.press(key(KeyCode::Char('r')), read(late, 3));
        assert!(keys.expire(late + CONFIRM_FOR));
        assert_eq!(keys.prompt, Prompt::None);
    }

    #[test]
    fn a_change_of_the_estop_closes_the_release_question() {
        let mut keys = Keys::default();
        assert!(!keys.estop_shown(true));
        press(&mut keys, key(KeyCode::Char('r')));
        assert!(!keys.estop_shown(true));
        assert_eq!(keys.prompt, Prompt::ConfirmRelease);
        // Released elsewhere (`teleop estop --release`) while the question was open.
        assert!(keys.estop_shown(false));
        assert_eq!(keys.prompt, Prompt::None);
        assert_eq!(press(&mut keys, key(KeyCode::Char('y'))), None);
        // A change with no question open changes no prompt.
        press(&mut keys, key(KeyCode::Char('s')));
        assert!(!keys.estop_shown(true));
        assert_eq!(keys.prompt, Prompt::Task(String::new()));
    }

    #[test]
    fn a_held_key_repeats_only_the_estop() {
        let held = |code| KeyEvent::new_with_kind(code, KeyModifiers::NONE, KeyEventKind::Repeat);
        let mut keys = Keys::new(Some("pick".into()));
        for code in [KeyCode::Char('s'), KeyCode::Char('k'), KeyCode::Char('d')] {
            assert_eq!(press(&mut keys, held(code)), None, "{code:?}");
        }
        press(&mut keys, key(KeyCode::Char('r')));
        assert_eq!(press(&mut keys, held(KeyCode::Char('y'))), None);
        assert_eq!(keys.prompt, Prompt::ConfirmRelease);
        for code in [KeyCode::Char('e'), KeyCode::Char(' '), KeyCode::Esc] {
            assert_eq!(press(&mut keys, held(code)), Some(Action::EStop));
        }
        // A key let go is nothing, not even the e-stop's.
        let let_go =
            KeyEvent::new_with_kind(KeyCode::Esc, KeyModifiers::NONE, KeyEventKind::Release);
        assert_eq!(press(&mut keys, let_go), None);
    }
}
