//! Progress for long work: a bar on a terminal once the work has taken more than a
//! second, and nothing at all when standard error is not a terminal (CI logs, pipes).

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Work shorter than this shows no bar.
const QUIET_FOR: Duration = Duration::from_secs(1);

pub struct Progress {
    bar: ProgressBar,
    started: Instant,
    shown: bool,
    terminal: bool,
}

impl Progress {
    /// `len` units of work (steps, runs), described as `what`.
    pub fn new(len: u64, what: &str) -> Progress {
        Progress::drawn_on(len, what, std::io::stderr().is_terminal())
    }

    /// As [`Progress::new`], with whether standard error is a terminal given.
    fn drawn_on(len: u64, what: &str, terminal: bool) -> Progress {
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
        bar.set_style(
            ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta} left)")
                .expect("a valid template")
                .progress_chars("=> "),
        );
        bar.set_message(what.to_string());
        Progress {
            bar,
            started: Instant::now(),
            shown: false,
            terminal,
        }
    }

    /// As [`Progress::new`], for work whose units may each take long (one CasADi
    /// derivation): after a second the bar appears on a terminal by itself and keeps
    /// ticking, whether or not a unit has finished.
    pub fn ticking(len: u64, what: &str) -> Progress {
        let p = Progress::new(len, what);
        if p.terminal {
            let bar = p.bar.clone();
            std::thread::spawn(move || {
                std::thread::sleep(QUIET_FOR);
                if !bar.is_finished() {
                    bar.set_draw_target(ProgressDrawTarget::stderr());
                    bar.enable_steady_tick(Duration::from_millis(200));
                }
            });
        }
        p
    }

    /// What is being done now.
    pub fn message(&self, what: String) {
        self.bar.set_message(what);
    }

    /// `pos` units done.
    pub fn set(&mut self, pos: u64) {
        if !self.shown && self.terminal && self.started.elapsed() >= QUIET_FOR {
            self.bar.set_draw_target(ProgressDrawTarget::stderr());
            self.shown = true;
        }
        self.bar.set_position(pos);
    }

    /// Whether the bar is drawn (a terminal, and more than a second of work so far).
    pub fn is_shown(&self) -> bool {
        self.shown
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        // The bar goes away with the work; what the command prints stays.
        self.bar.finish_and_clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bar_on_a_terminal_after_a_second_and_never_off_one() {
        for terminal in [true, false] {
            let mut p = Progress::drawn_on(10, "test", terminal);
            p.set(5);
            // Within a second: hidden, terminal or not.
            assert!(!p.is_shown());
            p.started -= Duration::from_secs(2);
            p.set(6);
            assert_eq!(p.is_shown(), terminal);
            assert_eq!(p.bar.position(), 6);
        }
    }
}
