//! Progress of long work (seed sweeps, the insertion grid, benchmarks) on stderr: on a terminal
//! a bar (indicatif) with the runs done out of the total, the rate, the time left and the
//! failures so far by check; elsewhere (a pipe, a log, CI) a plain line every few seconds.
//! Nothing goes to stdout, so `--json` stays one clean JSON value there.

use afs_shared::check::Check;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// How often the plain line is printed where stderr is not a terminal.
pub const PLAIN_EVERY: Duration = Duration::from_secs(5);

/// Runs done of a known total, shared by the threads that do them.
pub struct Progress {
    what: String,
    /// What is counted: "runs", "parts".
    unit: &'static str,
    total: u64,
    bar: Option<ProgressBar>,
    state: Mutex<State>,
}

/// What the threads update.
struct State {
    done: u64,
    /// Failed runs by check identifier.
    failed: BTreeMap<String, u64>,
    started: Instant,
    /// When the plain line was last printed.
    printed: Instant,
}

impl Progress {
    /// `total` runs of `what` (e.g. "fig5.6 over seeds 1..=100"): a bar where stderr is a
    /// terminal, plain lines every [`PLAIN_EVERY`] otherwise.
    pub fn new(what: &str, total: u64) -> Self {
        Self::counting(what, total, "runs")
    }

    /// [`Self::new`] counting `unit` ("parts" of a benchmark) instead of runs.
    pub fn counting(what: &str, total: u64, unit: &'static str) -> Self {
        let on_terminal = std::io::stderr().is_terminal();
        Self::with_bar(what, total, unit, on_terminal)
    }

    /// [`Self::counting`] with the choice of the bar made by the caller.
    pub fn with_bar(what: &str, total: u64, unit: &'static str, bar: bool) -> Self {
        let now = Instant::now();
        let bar = bar.then(|| {
            let b = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
            // The template is a constant; a bad one would be a bug caught by the tests.
            if let Ok(style) = ProgressStyle::with_template(&format!(
                "{{prefix}} [{{bar:30}}] {{pos}}/{{len}} {unit}, {{per_sec}}, {{eta}} left {{msg}}"
            )) {
                b.set_style(style.progress_chars("=> "));
            }
            b.set_prefix(what.to_string());
            // The rate and the time left move between runs too (a grid's runs take seconds).
            b.enable_steady_tick(Duration::from_millis(500));
            b
        });
        Self {
            what: what.to_string(),
            unit,
            total,
            bar,
            state: Mutex::new(State {
                done: 0,
                failed: BTreeMap::new(),
                started: now,
                printed: now,
            }),
        }
    }

    /// One run (or part) done with its checks: counted, its failed checks tallied, the bar or
    /// the plain line brought up to date.
    pub fn run_done(&self, checks: &[Check]) {
        let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        s.done += 1;
        for c in checks.iter().filter(|c| !c.pass) {
            *s.failed.entry(c.id.clone()).or_default() += 1;
        }
        match &self.bar {
            Some(b) => {
                b.set_position(s.done);
                b.set_message(failures(&s.failed));
            }
            None if s.printed.elapsed() >= PLAIN_EVERY => {
                s.printed = Instant::now();
                eprintln!("{}", self.line(&s));
            }
            None => {}
        }
    }

    /// The work is over: the bar is cleared, or the last plain line printed.
    pub fn finish(&self) {
        let s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        match &self.bar {
            Some(b) => b.finish_and_clear(),
            None => eprintln!("{}", self.line(&s)),
        }
    }

    /// The plain line as it stands now.
    #[doc(hidden)]
    pub fn plain_line(&self) -> String {
        self.line(&self.state.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// The plain line: "afs: WHAT: 40/100 runs, 2.1 runs/s, about 28 s left; failed: ...".
    fn line(&self, s: &State) -> String {
        let secs = s.started.elapsed().as_secs_f64();
        let rate = if secs > 0.0 {
            s.done as f64 / secs
        } else {
            0.0
        };
        let left = if s.done >= self.total {
            "done".to_string()
        } else if rate > 0.0 {
            format!(
                "about {} left",
                seconds((self.total - s.done) as f64 / rate)
            )
        } else {
            "time left unknown".to_string()
        };
        let unit = self.unit;
        format!(
            "afs: {}: {}/{} {unit}, {rate:.1} {unit}/s, {left}; {}",
            self.what,
            s.done,
            self.total,
            match failures(&s.failed) {
                f if f.is_empty() => "no check failed".to_string(),
                f => f,
            }
        )
    }

    /// Runs done so far.
    pub fn done(&self) -> u64 {
        self.state.lock().unwrap_or_else(|e| e.into_inner()).done
    }
}

/// "failed: inserted 3, peak_force 1", or nothing when no check failed.
fn failures(failed: &BTreeMap<String, u64>) -> String {
    if failed.is_empty() {
        return String::new();
    }
    let list: Vec<String> = failed.iter().map(|(id, n)| format!("{id} {n}")).collect();
    format!("failed: {}", list.join(", "))
}

/// A duration in words a person reads at a glance: "42 s", "7 min", "1.5 h".
#[doc(hidden)]
pub fn seconds(s: f64) -> String {
    if s < 90.0 {
        format!("{s:.0} s")
    } else if s < 5400.0 {
        format!("{:.0} min", s / 60.0)
    } else {
        format!("{:.1} h", s / 3600.0)
    }
}
