//! The console's keys: what each does in each state (no prompt, the release confirmation, the
//! task prompt), pure, so that tests press keys without a terminal.
//!
//! The e-stop is one key in every state: `Esc` always; `e` and space too, except while a task
//! is typed (where they are text). Any e-stop closes the open prompt.

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use teleop_msgs::episode_outcome;

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
}

impl Keys {
    /// Takes one key press; returns what it asks for, if anything.
    pub fn press(&mut self, key: KeyEvent) -> Option<Action> {
        let ctrl_c =
            key.code == KeyCode::Char('c') && key.modifiers.contains(KeyModifiers::CONTROL);
        if key.code == KeyCode::Esc {
            self.prompt = Prompt::None;
            return Some(Action::EStop);
        }
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
        if matches!(key.code, KeyCode::Char('e') | KeyCode::Char(' ')) {
            self.prompt = Prompt::None;
            return Some(Action::EStop);
        }
        if self.prompt == Prompt::ConfirmRelease {
            self.prompt = Prompt::None;
            return (key.code == KeyCode::Char('y')).then_some(Action::Release);
        }
        match key.code {
            KeyCode::Char('r') => {
                self.prompt = Prompt::ConfirmRelease;
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

    fn typed(keys: &mut Keys, text: &str) -> Vec<Option<Action>> {
        text.chars()
            .map(|c| keys.press(key(KeyCode::Char(c))))
            .collect()
    }

    #[test]
    fn the_estop_is_one_key_in_every_state() {
        for estop in [KeyCode::Esc, KeyCode::Char('e'), KeyCode::Char(' ')] {
            let mut keys = Keys::default();
            assert_eq!(keys.press(key(estop)), Some(Action::EStop));
            keys.press(key(KeyCode::Char('r')));
            assert_eq!(keys.prompt, Prompt::ConfirmRelease);
            assert_eq!(keys.press(key(estop)), Some(Action::EStop));
            assert_eq!(keys.prompt, Prompt::None);
        }
        // While a task is typed, Esc engages it (and e and space are text).
        let mut keys = Keys::default();
        keys.press(key(KeyCode::Char('s')));
        assert!(typed(&mut keys, "e ").iter().all(Option::is_none));
        assert_eq!(keys.prompt, Prompt::Task("e ".into()));
        assert_eq!(keys.press(key(KeyCode::Esc)), Some(Action::EStop));
        assert_eq!(keys.prompt, Prompt::None);
    }

    #[test]
    fn release_needs_its_confirmation() {
        let mut keys = Keys::default();
        assert_eq!(keys.press(key(KeyCode::Char('r'))), None);
        assert_eq!(keys.press(key(KeyCode::Char('y'))), Some(Action::Release));
        keys.press(key(KeyCode::Char('r')));
        assert_eq!(keys.press(key(KeyCode::Char('n'))), None);
        assert_eq!(keys.prompt, Prompt::None);
        // `y` alone does nothing.
        assert_eq!(keys.press(key(KeyCode::Char('y'))), None);
    }

    #[test]
    fn episodes_ask_for_their_task_once() {
        let mut keys = Keys::default();
        assert_eq!(keys.press(key(KeyCode::Char('s'))), None);
        typed(&mut keys, "pick the ball");
        keys.press(key(KeyCode::Backspace));
        assert_eq!(
            keys.press(key(KeyCode::Enter)),
            Some(Action::Start("pick the bal".into()))
        );
        // The next start takes the same task without asking.
        assert_eq!(
            keys.press(key(KeyCode::Char('s'))),
            Some(Action::Start("pick the bal".into()))
        );
        assert_eq!(
            keys.press(key(KeyCode::Char('k'))),
            Some(Action::Stop(episode_outcome::SUCCESS))
        );
        assert_eq!(
            keys.press(key(KeyCode::Char('f'))),
            Some(Action::Stop(episode_outcome::FAILURE))
        );
        assert_eq!(keys.press(key(KeyCode::Char('d'))), Some(Action::Discard));
        // An empty task cancels.
        let mut keys = Keys::default();
        keys.press(key(KeyCode::Char('s')));
        typed(&mut keys, "  ");
        assert_eq!(keys.press(key(KeyCode::Enter)), None);
        assert_eq!((keys.prompt, keys.task), (Prompt::None, None));
    }

    #[test]
    fn q_and_ctrl_c_quit_but_q_is_text_in_a_task() {
        let mut keys = Keys::default();
        assert_eq!(keys.press(key(KeyCode::Char('q'))), Some(Action::Quit));
        keys.press(key(KeyCode::Char('s')));
        assert_eq!(keys.press(key(KeyCode::Char('q'))), None);
        assert_eq!(
            keys.press(KeyEvent::new(KeyCode::Char('c'), KeyModifiers::CONTROL)),
            Some(Action::Quit)
        );
    }
}
