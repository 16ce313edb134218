//! The one progress bar of the long commands (sweep, crowd, simulate, report, check): drawn on
//! stderr only when it is a terminal, so logs and captured output never get one.

/// A progress bar on stderr counting `what`, drawn only when stderr is a terminal (and not
/// `quiet`), cleared when dropped.
pub struct Progress(indicatif::ProgressBar);

impl Progress {
    pub fn new(what: &str, quiet: bool) -> Self {
        use std::io::IsTerminal as _;
        let template = format!("{{bar:40}} {{pos}}/{{len}} {what} {{elapsed}} {{msg}}");
        Self(match indicatif::ProgressStyle::with_template(&template) {
            Ok(style) if !quiet && std::io::stderr().is_terminal() => {
                indicatif::ProgressBar::new(0).with_style(style)
            }
            _ => indicatif::ProgressBar::hidden(),
        })
    }

    /// `done` of `total`.
    pub fn set(&self, done: usize, total: usize) {
        self.0.set_length(total as u64);
        self.0.set_position(done as u64);
    }

    /// Prints `line` on stderr, above the bar.
    pub fn say(&self, line: &str) {
        self.0.suspend(|| eprintln!("{line}"));
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}
