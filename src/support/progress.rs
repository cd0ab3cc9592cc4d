//! Progress on stderr: a line per stage and a bar for long loops, shown only when stderr is a
//! terminal and `--quiet` is not given, so pipelines and logs stay clean.
//!
//! `BLENDSIM_PROGRESS=lines` (or `1`) forces progress on when stderr is not a terminal (a CI log,
//! a render farm's job output): then a bar's first frame and at most one frame a second after it are plain lines
//! (`solve: spacetime [=====>   ] 40/200 3s eta 12s`), never cursor movements, and every stage
//! that finishes prints `MESSAGE: done in 1.2s`. `--quiet` wins over it; `BLENDSIM_PROGRESS=0`
//! hides progress even on a terminal; any other value is an error ([`Progress::from_env`]).
//!
//! Every bar estimates the time left: a loop over counted steps from their rate
//! ([`Progress::bar`]); a solve whose iteration count is predicted as it goes from that
//! prediction and the rate ([`Progress::iterations`]); a phase whose work cannot be counted
//! (an external process, one library call) from a cost model's predicted duration
//! ([`Progress::predicted`]).

use std::fmt::Write as _;
use std::io::{IsTerminal, Write};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use indicatif::{HumanDuration, ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle, TermLike, WeakProgressBar};

/// The values `BLENDSIM_PROGRESS` takes (empty: as if unset).
const PROGRESS_VALUES: [&str; 7] = ["", "0", "off", "never", "1", "lines", "always"];

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
#[derive(Clone)]
pub struct Progress {
    mode: Mode,
    /// Warnings go to stderr (the CLI, quiet or not); the library's hidden progress keeps them
    /// in the stage data only.
    warnings: bool,
    /// The bars made here (and their clones'), so that a warning can take the one being drawn
    /// off the terminal while it prints.
    bars: Arc<Mutex<Vec<WeakProgressBar>>>,
}

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Progress").field("mode", &self.mode).field("warnings", &self.warnings).finish_non_exhaustive()
    }
}

impl Progress {
    /// Visible when not `quiet` and stderr is a terminal or `BLENDSIM_PROGRESS` asks for it
    /// (see the module documentation); an unknown `BLENDSIM_PROGRESS` is taken as unset.
    pub fn new(quiet: bool) -> Progress {
        Progress::with_setting(quiet, std::env::var("BLENDSIM_PROGRESS").ok().as_deref())
            .unwrap_or_else(|_| Progress::with_setting(quiet, None).expect("unset is valid"))
    }

    /// [`Progress::new`], with an unknown `BLENDSIM_PROGRESS` value an error (the CLI's choice:
    /// a typo in a farm's environment should not silently hide the progress it asked for).
    pub fn from_env(quiet: bool) -> std::result::Result<Progress, String> {
        Progress::with_setting(quiet, std::env::var("BLENDSIM_PROGRESS").ok().as_deref())
    }

    fn with_setting(quiet: bool, setting: Option<&str>) -> std::result::Result<Progress, String> {
        let terminal = std::io::stderr().is_terminal();
        let mode = match setting.map(str::trim).filter(|v| !v.is_empty()) {
            Some(v) if !PROGRESS_VALUES.contains(&v) => {
                return Err(format!(
                    "BLENDSIM_PROGRESS={v:?} is not a progress setting: use lines (or 1, always) for plain lines, 0 (or off, never) for none, or leave it unset"
                ))
            }
            _ if quiet => Mode::Hidden,
            Some("0" | "off" | "never") => Mode::Hidden,
            Some(_) if !terminal => Mode::Lines,
            _ if terminal => Mode::Terminal,
            _ => Mode::Hidden,
        };
        Ok(Progress { mode, warnings: true, bars: Arc::default() })
    }

    /// Never drawn (library use, tests).
    pub fn hidden() -> Progress {
        Progress { mode: Mode::Hidden, warnings: false, bars: Arc::default() }
    }

    /// The same progress with its warnings kept in the stage data only, not printed (`--strict`
    /// prints them once, as errors).
    pub fn without_warnings(&self) -> Progress {
        Progress { warnings: false, ..self.clone() }
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
    /// even with `--quiet`; the stage data keep it for the report. A bar being drawn is taken
    /// off the terminal while the line prints and drawn again below it.
    pub fn warn(&self, line: &str) {
        if self.warnings {
            let line: String = line.chars().map(|c| if c.is_control() { ' ' } else { c }).collect();
            let print = || eprintln!("blendsim: warning: {line}");
            match self.drawn() {
                Some(bar) => bar.suspend(print),
                None => print(),
            }
        }
    }

    /// The bar being drawn, if any (the last one made that is not finished).
    fn drawn(&self) -> Option<ProgressBar> {
        let bars = self.bars.lock().unwrap_or_else(|e| e.into_inner());
        bars.iter().rev().filter_map(WeakProgressBar::upgrade).find(|b| !b.is_finished() && !b.is_hidden())
    }

    /// `bar` with `style` and `message`, redrawn every `tick`, and remembered for [`Progress::warn`].
    fn start(&self, bar: ProgressBar, style: ProgressStyle, message: String, tick: Duration) -> Bar {
        bar.set_style(style);
        bar.set_message(message.clone());
        bar.enable_steady_tick(tick);
        let mut bars = self.bars.lock().unwrap_or_else(|e| e.into_inner());
        bars.retain(|b| b.upgrade().is_some_and(|b| !b.is_finished()));
        bars.push(bar.downgrade());
        let started = (self.mode == Mode::Lines).then(Instant::now);
        Bar { bar, started, label: message, done: Arc::default() }
    }

    /// A spinner naming a stage too short to need an estimate; call `finish` on it (or drop it)
    /// when the stage is done.
    pub fn stage(&self, message: impl Into<String>) -> Bar {
        let style = ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("valid template");
        self.start(ProgressBar::with_draw_target(None, self.target()), style, message.into(), Duration::from_millis(120))
    }

    /// A bar over `len` steps, with the time left estimated from the steps' rate.
    pub fn bar(&self, len: u64, message: impl Into<String>) -> Bar {
        let style = ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {elapsed} eta {eta}").expect("valid template").progress_chars("=> ");
        // Redrawn at least once a second even while a step runs long (elapsed keeps moving).
        self.start(ProgressBar::with_draw_target(Some(len), self.target()), style, message.into(), Duration::from_millis(500))
    }

    /// A bar over iterations whose total is not known up front but predicted as they go: set it
    /// with `set_length` (and `unset_length` while there is no prediction). Shows `K/~N` and the
    /// time left at the iterations' measured rate, or `?` for both without a prediction.
    pub fn iterations(&self, message: impl Into<String>) -> Bar {
        let style = ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{total} {elapsed} eta {left}")
            .expect("valid template")
            .progress_chars("=> ")
            .with_key("total", |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = match s.len() {
                    Some(n) => write!(w, "~{n}"),
                    None => write!(w, "?"),
                };
            })
            .with_key("left", |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = match s.len() {
                    Some(_) => write!(w, "{:#}", HumanDuration(s.eta())),
                    None => write!(w, "?"),
                };
            });
        self.start(ProgressBar::with_draw_target(None, self.target()), style, message.into(), Duration::from_millis(500))
    }

    /// A bar over a phase whose work cannot be counted as it runs (an external process, one
    /// library call), filled by the elapsed time against `seconds`, the duration its cost
    /// model predicts on this machine's threads: shows `elapsed of ~predicted` and the time
    /// left of the prediction, or `?` once the phase runs over it (a loaded machine).
    pub fn predicted(&self, message: impl Into<String>, seconds: f64) -> Bar {
        let predicted = Duration::try_from_secs_f64(seconds).unwrap_or(Duration::ZERO);
        let style = ProgressStyle::with_template("{msg} [{fill}] {elapsed} of ~{predicted} eta {left}")
            .expect("valid template")
            .with_key("fill", move |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                let fraction = if predicted.is_zero() { 1.0 } else { (s.elapsed().as_secs_f64() / predicted.as_secs_f64()).min(1.0) };
                let full = (fraction * 30.0) as usize;
                let _ = write!(w, "{}{}", "=".repeat(full), " ".repeat(30 - full));
            })
            .with_key("predicted", move |_: &ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = write!(w, "{}", short(predicted));
            })
            .with_key("left", move |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = match predicted.checked_sub(s.elapsed()) {
                    Some(left) => write!(w, "{}", short(left)),
                    None => write!(w, "? (over the estimate)"),
                };
            });
        self.start(ProgressBar::with_draw_target(None, self.target()), style, message.into(), Duration::from_millis(120))
    }
}

/// A stage's spinner or bar: an indicatif [`ProgressBar`] (through `Deref`) whose `finish*`
/// methods, in `lines` mode, also print `MESSAGE: done in 1.2s` (once, however many clones).
#[derive(Debug, Clone)]
pub struct Bar {
    bar: ProgressBar,
    /// When the stage started, in `lines` mode only.
    started: Option<Instant>,
    /// The stage's name, as first given (the message may change as it runs).
    label: String,
    done: Arc<std::sync::atomic::AtomicBool>,
}

impl std::ops::Deref for Bar {
    type Target = ProgressBar;
    fn deref(&self) -> &ProgressBar {
        &self.bar
    }
}

impl Bar {
    /// Finish, leaving the last frame drawn.
    pub fn finish(&self) {
        self.bar.finish();
        self.done_line();
    }

    /// Finish and take the bar off the terminal.
    pub(crate) fn finish_and_clear(&self) {
        self.bar.finish_and_clear();
        self.done_line();
    }

    /// Finish with `message` as the last frame.
    pub fn finish_with_message(&self, message: impl Into<std::borrow::Cow<'static, str>>) {
        self.bar.finish_with_message(message);
        self.done_line();
    }

    fn done_line(&self) {
        if let Some(started) = self.started {
            if !self.done.swap(true, std::sync::atomic::Ordering::Relaxed) {
                let label: String = self.label.chars().map(|c| if c.is_control() { ' ' } else { c }).collect();
                eprintln!("{}: done in {}", label.trim_end_matches(|c: char| c == ':' || c.is_whitespace()), short(started.elapsed()));
            }
        }
    }
}

/// A duration as `0.4s`, `12s` or `3m05s`.
fn short(d: Duration) -> String {
    let s = d.as_secs_f64();
    let mut out = String::new();
    let _ = if s < 10.0 {
        write!(out, "{s:.1}s")
    } else if s < 120.0 {
        write!(out, "{s:.0}s")
    } else {
        write!(out, "{}m{:02}s", (s / 60.0) as u64, (s as u64) % 60)
    };
    out
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `warn` takes the bar being drawn off the terminal: the last unfinished visible one.
    #[test]
    fn warnings_suspend_the_bar_being_drawn() {
        let progress = Progress { mode: Mode::Lines, warnings: false, bars: Arc::default() };
        assert!(progress.drawn().is_none());
        let outer = progress.stage("outer");
        let inner = progress.predicted("inner", 1.0);
        assert_eq!(progress.drawn().map(|b| b.message()).as_deref(), Some("inner"));
        inner.finish_and_clear();
        assert_eq!(progress.drawn().map(|b| b.message()).as_deref(), Some("outer"), "a finished bar is not drawn");
        drop(inner);
        outer.finish_and_clear();
        assert!(progress.drawn().is_none());
        let hidden = Progress::hidden();
        let _bar = hidden.bar(3, "hidden");
        assert!(hidden.drawn().is_none(), "hidden bars are never drawn");
    }

    #[test]
    fn short_durations() {
        assert_eq!(short(Duration::from_millis(430)), "0.4s");
        assert_eq!(short(Duration::from_secs(42)), "42s");
        assert_eq!(short(Duration::from_secs(185)), "3m05s");
    }
}
