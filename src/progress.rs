//! Progress on stderr: a line per stage and a bar for long loops, shown only when stderr is a
//! terminal and `--quiet` is not given, so pipelines and logs stay clean.

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Where progress goes: stderr when visible, nowhere otherwise.
#[derive(Debug, Clone)]
pub struct Progress {
    visible: bool,
    /// Warnings go to stderr (the CLI, quiet or not); the library's hidden progress keeps them
    /// in the stage data only.
    warnings: bool,
}

impl Progress {
    /// Visible when stderr is a terminal and not `quiet`.
    pub fn new(quiet: bool) -> Progress {
        Progress { visible: !quiet && std::io::stderr().is_terminal(), warnings: true }
    }

    /// Never drawn (library use, tests).
    pub fn hidden() -> Progress {
        Progress { visible: false, warnings: false }
    }

    fn target(&self) -> ProgressDrawTarget {
        if self.visible {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        }
    }

    /// One warning line on stderr, `blendsim: warning: LINE` (control characters folded), shown
    /// even with `--quiet`; the stage data keep it for the report.
    pub fn warn(&self, line: &str) {
        if self.warnings {
            let line: String = line.chars().map(|c| if c.is_control() { ' ' } else { c }).collect();
            eprintln!("blendsim: warning: {line}");
        }
    }

    /// A spinner naming a stage; call `finish` on it (or drop it) when the stage is done.
    pub fn stage(&self, message: impl Into<String>) -> ProgressBar {
        let bar = ProgressBar::with_draw_target(None, self.target());
        bar.set_style(ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("valid template"));
        bar.set_message(message.into());
        bar.enable_steady_tick(Duration::from_millis(120));
        bar
    }

    /// A bar over `len` steps.
    pub fn bar(&self, len: u64, message: impl Into<String>) -> ProgressBar {
        let bar = ProgressBar::with_draw_target(Some(len), self.target());
        bar.set_style(
            ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {elapsed}").expect("valid template").progress_chars("=> "),
        );
        bar.set_message(message.into());
        bar
    }
}
