//! The progress bar of long work: indicatif on stderr, quiet with `-q` and when stderr is
//! not a terminal.

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressStyle};
use rigidcells::Observer;
use rigidcells::internal::estimate::Estimate;

/// A progress bar on a terminal (a spinner for stages of unknown length), a new one for each
/// stage (a finished bar draws no more); silent otherwise.
/// A solve expected to take longer than `estimate::LONG_RUN_SECONDS` is announced on stderr
/// before it starts, with its cells, time and memory (not with `-q`).
pub(super) struct Bar {
    shown: bool,
    quiet: bool,
    bar: std::sync::Mutex<Option<ProgressBar>>,
}

impl Bar {
    pub(super) fn new(quiet: bool) -> Self {
        Self {
            shown: !quiet && std::io::stderr().is_terminal(),
            quiet,
            bar: std::sync::Mutex::new(None),
        }
    }

    fn with(&self, f: impl FnOnce(&ProgressBar)) {
        if let Some(b) = self.bar.lock().expect("not poisoned").as_ref() {
            f(b);
        }
    }
}

impl Observer for Bar {
    fn stage(&self, name: &str, len: u64) {
        if !self.shown {
            return;
        }
        let template = if len == 0 {
            "{prefix:>11} {spinner} {elapsed} {msg}"
        } else {
            "{prefix:>11} [{bar:20}] {pos}/{len} {elapsed} {msg}"
        };
        let b = ProgressBar::with_draw_target(Some(len), indicatif::ProgressDrawTarget::stderr())
            .with_style(ProgressStyle::with_template(template).expect("valid template"))
            .with_prefix(name.to_string());
        if len == 0 {
            b.enable_steady_tick(std::time::Duration::from_millis(120));
        }
        if let Some(old) = self.bar.lock().expect("not poisoned").replace(b) {
            old.finish_and_clear();
        }
    }
    fn advance(&self, n: u64) {
        self.with(|b| b.inc(n));
    }
    fn message(&self, text: &str) {
        self.with(|b| b.set_message(text.to_string()));
    }
    fn finish(&self) {
        if let Some(b) = self.bar.lock().expect("not poisoned").take() {
            b.finish_and_clear();
        }
    }
    fn estimate(&self, estimate: &Estimate) {
        if self.quiet || !estimate.is_long() {
            return;
        }
        let line = format!(
            "the solve: {} (--cell-size or --cells trade detail for time)",
            estimate.summary()
        );
        match self.bar.lock().expect("not poisoned").as_ref() {
            Some(b) => b.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }
}
