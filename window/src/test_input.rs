//! Scripted input for tests: `STUDY_TEST_INPUT=FILE` makes the window take its keys from a
//! script instead of (as well as) the keyboard, one event per frame, each only while the screen
//! it names is shown, and say on standard error every screen it shows and every rule it has
//! carried out. A test then waits for a state (a screen, a rule carried out, a file), never
//! for a number of seconds, and nothing depends on how many frames fit in a second or on
//! whether the X server delivers synthetic keys.
//!
//! A script is a list of rules, one a line (`#` starts a comment):
//!
//! ```text
//! welcome/ready: Tab "33" Tab "33" Escape Enter
//! trial/open once: 4 Enter
//! end/ready: Enter
//! ```
//!
//! - Before the colon, the screen the rule is for ([`crate::screens::StudyUi::screen`]
//!   lists the names), then optionally how many times it may fire: `once`, or `times N`;
//!   without it, every time the screen is entered.
//! - After it, the events: a key by egui's name (`Enter`, `Tab`, `Escape`, `Backspace`,
//!   `Left`, `Up`, `4`, `A`, ...) with optional modifiers (`Ctrl+Shift+P`), or text in double
//!   quotes (`"33"`, typed into the focused field).
//! - A rule fires when its screen is entered: the first screen of the window, a change of
//!   screen, or the next trial on the same screen. Its events go in one a frame, in order, while
//!   the screen stays; when the screen changes first, the rest are dropped. The first rule
//!   (in file order) for the screen that may still fire is the one that does.
//!
//! What it says on standard error, one line each, prefixed `test input:`: `screen NAME` when
//! the window shows a new screen (or trial), `done LINE` after the frame that took a rule's
//! last event (its line number), `dropped LINE` when a screen change cut a rule short.

use std::fmt;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};

/// The environment variable naming a script.
pub const ENV: &str = "STUDY_TEST_INPUT";

/// The prefix of every line the script writes to standard error.
pub const PREFIX: &str = "test input:";

/// Scripts longer than this are refused (a test's script is a few lines).
const MAX_BYTES: u64 = 64 * 1024;

/// One input event of a rule.
#[derive(Debug, Clone, PartialEq)]
enum Input {
    /// A key pressed and released, with its modifiers.
    Key(egui::Key, egui::Modifiers),
    /// Text typed into the focused field.
    Text(String),
}

impl fmt::Display for Input {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Input::Key(k, m) => {
                for (on, name) in [(m.ctrl, "Ctrl+"), (m.shift, "Shift+"), (m.alt, "Alt+")] {
                    if on {
                        f.write_str(name)?;
                    }
                }
                f.write_str(k.name())
            }
            Input::Text(t) => write!(f, "{t:?}"),
        }
    }
}

/// One line of a script.
#[derive(Debug, Clone, PartialEq)]
struct Rule {
    /// The line it was on (1-based), for what the script says.
    line: usize,
    /// The screen it is for.
    screen: String,
    /// How many more times it may fire (`None`: always).
    left: Option<u32>,
    inputs: Vec<Input>,
}

/// A rule on its way in: which, and how many of its events went in.
#[derive(Debug, Clone, Copy)]
struct Firing {
    rule: usize,
    sent: usize,
}

/// A parsed script and where it stands.
#[derive(Debug)]
pub struct TestInput {
    rules: Vec<Rule>,
    /// The screen shown at the end of the last frame (`None` before the first).
    screen: Option<String>,
    firing: Option<Firing>,
    /// Set when the last frame took a rule's last event: its line.
    finished: Option<usize>,
}

impl TestInput {
    /// The script named by [`ENV`], if set.
    ///
    /// # Errors
    /// The file cannot be read or a line is not a rule (naming the file, line and token).
    pub fn from_env() -> anyhow::Result<Option<TestInput>> {
        let Some(path) = std::env::var_os(ENV).filter(|p| !p.is_empty()) else {
            return Ok(None);
        };
        let path = PathBuf::from(path);
        let input = TestInput::read(&path)?;
        eprintln!(
            "{PREFIX} keys from {} ({ENV}; for tests, not for subjects)",
            path.display()
        );
        Ok(Some(input))
    }

    /// Reads the script at `path`.
    ///
    /// # Errors
    /// As [`TestInput::from_env`].
    pub fn read(path: &Path) -> anyhow::Result<TestInput> {
        let size = std::fs::metadata(path)
            .with_context(|| format!("{}: reading the test input script ({ENV})", path.display()))?
            .len();
        if size > MAX_BYTES {
            bail!(
                "{}: a test input script of {size} bytes; at most {MAX_BYTES} are read",
                path.display()
            );
        }
        let text = std::fs::read_to_string(path).with_context(|| {
            format!("{}: reading the test input script ({ENV})", path.display())
        })?;
        TestInput::parse(&text)
            .map(|rules| TestInput {
                rules,
                screen: None,
                firing: None,
                finished: None,
            })
            .map_err(|e| anyhow::anyhow!("{}:{e}", path.display()))
    }

    /// The rules of `text`; an error is `LINE: reason`.
    fn parse(text: &str) -> Result<Vec<Rule>, String> {
        let mut rules = Vec::new();
        for (k, raw) in text.lines().enumerate() {
            let line = k + 1;
            let body = raw.split_once('#').map_or(raw, |(b, _)| b).trim();
            if body.is_empty() {
                continue;
            }
            let (head, events) = body
                .split_once(':')
                .ok_or_else(|| format!("{line}: expected `SCREEN: EVENTS`, got {body:?}"))?;
            let mut words = head.split_whitespace();
            let screen = words
                .next()
                .ok_or_else(|| format!("{line}: no screen before the colon"))?
                .to_string();
            let left = match (words.next(), words.next(), words.next()) {
                (None, ..) => None,
                (Some("once"), None, _) => Some(1),
                (Some("times"), Some(n), None) => Some(
                    n.parse::<u32>()
                        .ok()
                        .filter(|n| *n > 0)
                        .ok_or_else(|| format!("{line}: `times {n}`: expected a count ≥ 1"))?,
                ),
                _ => {
                    return Err(format!(
                        "{line}: {head:?}: expected a screen, then `once` or `times N`"
                    ));
                }
            };
            let inputs = parse_events(events).map_err(|e| format!("{line}: {e}"))?;
            if inputs.is_empty() {
                return Err(format!("{line}: no events after the colon"));
            }
            rules.push(Rule {
                line,
                screen,
                left,
                inputs,
            });
        }
        Ok(rules)
    }

    /// Before a frame: adds the next event of the rule under way, or of the rule that the
    /// screen shown at the end of the last frame fires, to `raw`. The script stands for a
    /// keyboard at a window that has the keyboard focus, so the frame is marked focused:
    /// without a window manager (Xvfb) the window never gets it, and egui hands keys to a
    /// focused widget (a slider) only in a focused window.
    pub fn inject(&mut self, raw: &mut egui::RawInput) {
        raw.focused = true;
        let Some(f) = &mut self.firing else {
            return;
        };
        let rule = &self.rules[f.rule];
        let input = &rule.inputs[f.sent];
        match input {
            Input::Key(key, modifiers) => {
                for pressed in [true, false] {
                    raw.events.push(egui::Event::Key {
                        key: *key,
                        physical_key: None,
                        pressed,
                        repeat: false,
                        modifiers: *modifiers,
                    });
                }
            }
            Input::Text(t) => raw.events.push(egui::Event::Text(t.clone())),
        }
        f.sent += 1;
        if f.sent == rule.inputs.len() {
            self.finished = Some(rule.line);
            self.firing = None;
        }
    }

    /// After a frame: the screen it left on `screen` (a name, then ` #N` for trial N where
    /// there is a trial). A new screen cuts short a rule under way and fires the first rule
    /// for it that may still fire.
    pub fn observe(&mut self, screen: &str) {
        if let Some(line) = self.finished.take() {
            eprintln!("{PREFIX} done {line}");
        }
        if self.screen.as_deref() == Some(screen) {
            return;
        }
        eprintln!("{PREFIX} screen {screen}");
        self.screen = Some(screen.to_string());
        if let Some(f) = self.firing.take() {
            eprintln!("{PREFIX} dropped {}", self.rules[f.rule].line);
        }
        let name = screen.split(" #").next().unwrap_or(screen);
        if let Some(k) = self
            .rules
            .iter()
            .position(|r| r.screen == name && r.left != Some(0))
        {
            if let Some(left) = &mut self.rules[k].left {
                *left -= 1;
            }
            self.firing = Some(Firing { rule: k, sent: 0 });
        }
    }

    /// Whether an event waits for the next frame (the window then draws one at once).
    pub fn pending(&self) -> bool {
        self.firing.is_some() || self.finished.is_some()
    }
}

/// The events of one rule: whitespace-separated keys, or text in double quotes.
fn parse_events(s: &str) -> Result<Vec<Input>, String> {
    let mut out = Vec::new();
    let mut rest = s.trim_start();
    while !rest.is_empty() {
        if let Some(quoted) = rest.strip_prefix('"') {
            let end = quoted
                .find('"')
                .ok_or_else(|| format!("text {rest:?} has no closing quote"))?;
            out.push(Input::Text(quoted[..end].to_string()));
            rest = quoted[end + 1..].trim_start();
            continue;
        }
        let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
        out.push(parse_key(&rest[..end])?);
        rest = rest[end..].trim_start();
    }
    Ok(out)
}

/// `Ctrl+Shift+P`, `Enter`, `4`: a key by egui's name with modifiers before it.
fn parse_key(token: &str) -> Result<Input, String> {
    let mut parts: Vec<&str> = token.split('+').collect();
    // `+` alone is the Plus key.
    let name = if token.ends_with("++") || token == "+" {
        parts.truncate(parts.len().saturating_sub(2));
        "+"
    } else {
        parts.pop().unwrap_or_default()
    };
    let mut modifiers = egui::Modifiers::NONE;
    for m in parts {
        match m {
            "Ctrl" => {
                modifiers.ctrl = true;
                modifiers.command = true;
            }
            "Shift" => modifiers.shift = true,
            "Alt" => modifiers.alt = true,
            _ => {
                return Err(format!(
                    "{token:?}: unknown modifier {m:?} (Ctrl, Shift, Alt)"
                ));
            }
        }
    }
    let key = egui::Key::from_name(name)
        .ok_or_else(|| format!("{token:?}: no key named {name:?} (egui's key names)"))?;
    Ok(Input::Key(key, modifiers))
}

#[cfg(test)]
mod tests {
    use egui::{Event, Key, Modifiers};

    use super::{Input, TestInput};

    fn script(text: &str) -> TestInput {
        TestInput {
            rules: TestInput::parse(text).unwrap(),
            screen: None,
            firing: None,
            finished: None,
        }
    }

    /// The events each frame gets, for the screens the frames end on.
    fn frames(input: &mut TestInput, screens: &[&str]) -> Vec<Vec<Event>> {
        let mut out = Vec::new();
        for s in screens {
            let mut raw = egui::RawInput::default();
            input.inject(&mut raw);
            out.push(raw.events);
            input.observe(s);
        }
        out
    }

    fn press(key: Key) -> Vec<Event> {
        [true, false]
            .map(|pressed| Event::Key {
                key,
                physical_key: None,
                pressed,
                repeat: false,
                modifiers: Modifiers::NONE,
            })
            .to_vec()
    }

    #[test]
    fn rules_parse_with_counts_text_and_modifiers() {
        let rules = TestInput::parse(
            "# a comment\n\nwelcome/ready: Tab \"3 3\" Enter # trailing\ntrial/open times 2: Ctrl+Shift+P 4\nend/ready once: Return\n",
        )
        .unwrap();
        assert_eq!(rules.len(), 3);
        assert_eq!(rules[0].line, 3);
        assert_eq!(
            rules[0].inputs,
            [
                Input::Key(Key::Tab, Modifiers::NONE),
                Input::Text("3 3".into()),
                Input::Key(Key::Enter, Modifiers::NONE)
            ]
        );
        assert_eq!(rules[1].left, Some(2));
        let chord = Modifiers {
            ctrl: true,
            shift: true,
            command: true,
            ..Modifiers::NONE
        };
        assert_eq!(rules[1].inputs[0], Input::Key(Key::P, chord));
        assert_eq!(rules[1].inputs[0].to_string(), "Ctrl+Shift+P");
        assert_eq!(rules[2].left, Some(1));
    }

    #[test]
    fn bad_lines_are_named_with_the_reason() {
        for (text, says) in [
            ("welcome Enter", "1: expected `SCREEN: EVENTS`"),
            ("\nwelcome: Entr", "2: \"Entr\": no key named \"Entr\""),
            ("welcome: Hyper+A", "unknown modifier \"Hyper\""),
            ("welcome: \"33", "has no closing quote"),
            ("welcome:", "1: no events"),
            ("welcome times 0: A", "expected a count ≥ 1"),
            (
                "welcome twice: A",
                "expected a screen, then `once` or `times N`",
            ),
        ] {
            let e = TestInput::parse(text).unwrap_err();
            assert!(e.contains(says), "{text:?}: {e}");
        }
    }

    #[test]
    fn a_rule_sends_one_event_a_frame_while_its_screen_stays() {
        let mut input = script("welcome: Tab \"33\" Enter\ntrial/open once: 4 Enter\n");
        let got = frames(
            &mut input,
            &[
                "welcome",
                "welcome",
                "welcome",
                "trial/playing #0",
                "trial/open #0",
                "trial/open #0",
                "gap",
                "trial/open #1",
                "trial/open #1",
            ],
        );
        assert!(got[0].is_empty(), "nothing before the first screen is seen");
        assert_eq!(got[1], press(Key::Tab));
        assert_eq!(got[2], [Event::Text("33".into())]);
        assert_eq!(got[3], press(Key::Enter));
        assert!(got[4].is_empty(), "no rule for trial/playing");
        assert_eq!(got[5], press(Key::Num4));
        assert_eq!(got[6], press(Key::Enter));
        // `once`: the next trial gets nothing.
        assert!(got[7..].iter().all(Vec::is_empty), "{got:?}");
        assert!(!input.pending());
    }

    #[test]
    fn a_screen_change_drops_the_rest_and_each_trial_fires_again() {
        let mut input = script("trial/open: 4 Enter\n");
        let got = frames(
            &mut input,
            &["trial/open #0", "trial/open #1", "trial/open #1", "end"],
        );
        assert_eq!(got[1], press(Key::Num4));
        // The next trial began before Enter: Enter is dropped, the rule fires anew.
        assert_eq!(got[2], press(Key::Num4));
        assert_eq!(got[3], press(Key::Enter));
    }
}
