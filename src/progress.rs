//! Progress on stderr: a line per stage and a bar for long loops, shown only when stderr is a
//! terminal and `--quiet` is not given, so pipelines and logs stay clean.
//!
//! `BLENDSIM_PROGRESS=lines` (or `1`) forces progress on when stderr is not a terminal (a CI log,
//! a render farm's job output): then a bar's first frame and at most one frame a second after it are plain lines
//! (`solve: spacetime [=====>   ] 40/200 3s eta 12s`), never cursor movements. `--quiet` wins
//! over it; `BLENDSIM_PROGRESS=0` hides progress even on a terminal.

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle, TermLike};

/// How progress is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Hidden,
    /// indicatif's terminal drawing (one line redrawn in place).
    Terminal,
    /// One plain line per redraw, for logs.
    Lines,
}

/// Where progress goes: stderr when visible, nowhere otherwise.
#[derive(Debug, Clone)]
pub struct Progress {
    mode: Mode,
    /// Warnings go to stderr (the CLI, quiet or not); the library's hidden progress keeps them
    /// in the stage data only.
    warnings: bool,
}

impl Progress {
    /// Visible when not `quiet` and stderr is a terminal or `BLENDSIM_PROGRESS` asks for it
    /// (see the module documentation).
    pub fn new(quiet: bool) -> Progress {
        let forced = std::env::var("BLENDSIM_PROGRESS").ok();
        let mode = match forced.as_deref().map(str::trim) {
            _ if quiet => Mode::Hidden,
            Some("0" | "off" | "never") => Mode::Hidden,
            Some("1" | "lines" | "always") if !std::io::stderr().is_terminal() => Mode::Lines,
            _ if std::io::stderr().is_terminal() => Mode::Terminal,
            _ => Mode::Hidden,
        };
        Progress { mode, warnings: true }
    }

    /// Never drawn (library use, tests).
    pub fn hidden() -> Progress {
        Progress { mode: Mode::Hidden, warnings: false }
    }

    /// Whether anything is drawn.
    pub fn is_visible(&self) -> bool {
        self.mode != Mode::Hidden
    }

    fn target(&self) -> ProgressDrawTarget {
        match self.mode {
            Mode::Hidden => ProgressDrawTarget::hidden(),
            Mode::Terminal => ProgressDrawTarget::stderr(),
            Mode::Lines => ProgressDrawTarget::term_like_with_hz(Box::new(Lines::default()), 4),
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

    /// A bar over `len` steps, with the time left estimated from the steps' rate.
    pub fn bar(&self, len: u64, message: impl Into<String>) -> ProgressBar {
        let bar = ProgressBar::with_draw_target(Some(len), self.target());
        bar.set_style(
            ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {elapsed} eta {eta}").expect("valid template").progress_chars("=> "),
        );
        bar.set_message(message.into());
        // Redrawn at least once a second even while a step runs long (elapsed keeps moving).
        bar.enable_steady_tick(Duration::from_millis(500));
        bar
    }
}

/// A "terminal" that writes drawn frames as plain lines on stderr: the first frame, then at most
/// one a second (indicatif's own limiter allows bursts). What indicatif draws on the last line of
/// a frame (`write_str`) is ended by the flush; cursor movements and clears are dropped.
#[derive(Debug, Default)]
struct Lines {
    pending: Mutex<String>,
    last: Mutex<Option<Instant>>,
}

impl Lines {
    /// Write `line` if it is not blank and a second has passed since the last one written.
    fn emit(&self, line: &str) -> std::io::Result<()> {
        let line = line.trim_matches(|c: char| c.is_whitespace() || c == '\r');
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if line.is_empty() || last.is_some_and(|t| t.elapsed() < Duration::from_secs(1)) {
            return Ok(());
        }
        *last = Some(Instant::now());
        let mut err = std::io::stderr().lock();
        writeln!(err, "{line}")?;
        err.flush()
    }
}

impl TermLike for Lines {
    fn width(&self) -> u16 {
        100
    }
    fn move_cursor_up(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_down(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_right(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_left(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn write_line(&self, s: &str) -> std::io::Result<()> {
        let line = std::mem::take(&mut *self.pending.lock().unwrap_or_else(|e| e.into_inner())) + s;
        self.emit(&line)
    }
    fn write_str(&self, s: &str) -> std::io::Result<()> {
        self.pending.lock().unwrap_or_else(|e| e.into_inner()).push_str(s);
        Ok(())
    }
    fn clear_line(&self) -> std::io::Result<()> {
        Ok(())
    }
    fn flush(&self) -> std::io::Result<()> {
        let line = std::mem::take(&mut *self.pending.lock().unwrap_or_else(|e| e.into_inner()));
        self.emit(&line)
    }
}
