//! A progress bar on stderr for a command that reads a long recording or log: drawn only
//! when stderr is a terminal, so a piped or logged run gets none of its escape codes.

use std::io::IsTerminal;

/// How far a long read has come, in whatever units its total counts.
pub struct Progress(Option<indicatif::ProgressBar>);

impl Progress {
    /// A bar for `what` (`replaying run-42`), of `total` units, when stderr is a terminal.
    pub fn bar(what: &str, total: u64) -> Self {
        if !std::io::stderr().is_terminal() {
            return Self(None);
        }
        Self::drawn(what, total)
    }

    /// A bar that is drawn whatever stderr is.
    fn drawn(what: &str, total: u64) -> Self {
        let bar = indicatif::ProgressBar::new(total.max(1));
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{msg} [{bar:40}] {percent:>3}% ({elapsed} / about {duration})",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        bar.set_message(what.to_owned());
        Self(Some(bar))
    }

    /// Nothing drawn.
    pub fn none() -> Self {
        Self(None)
    }

    /// `done` of the total units are behind.
    pub fn set(&self, done: u64) {
        if let Some(bar) = &self.0 {
            bar.set_position(done);
        }
    }

    /// Whether a bar is drawn.
    pub fn is_drawn(&self) -> bool {
        self.0.is_some()
    }
}

impl Drop for Progress {
    /// The bar leaves the terminal as it found it, for the summary that follows.
    fn drop(&mut self) {
        if let Some(bar) = self.0.take() {
            bar.finish_and_clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bar_counts_up_to_its_total_and_none_ignores_everything() {
        let bar = Progress::drawn("reading", 10);
        bar.set(4);
        assert_eq!(
            bar.0.as_ref().map(indicatif::ProgressBar::position),
            Some(4)
        );
        let none = Progress::none();
        none.set(4);
        assert!(!none.is_drawn());
    }
}
