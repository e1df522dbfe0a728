//! What an insertion measured, tick by tick: the one monitor `afs experiment insertion`, the
//! `insertion` scenario's lockstep reference and the supervisor watching the stack all feed, so
//! the three are measured by the same code.

use super::controller::Phase;
use super::estimate::class;
use super::plant::{ContactState, PegTruth};
use super::whitney::Fit;
use serde::{Deserialize, Serialize};

/// One tick, after its step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PegTick {
    /// Time at the end of the tick (s).
    pub t: f64,
    /// The controller's phase after the tick.
    pub phase: Phase,
    /// The estimated contact state of the tick (from the readings of the state before it).
    pub estimated: ContactState,
    /// The truth after the tick.
    pub truth: PegTruth,
}

/// The jamming diagram shows the applied wrench only while the wrist presses the peg in with at
/// least this force (N): below it, F_x/F_z and M/(r F_z) divide by next to nothing.
pub const WHITNEY_LEAST_FZ_N: f64 = 0.25;

/// Ticks on either side of a change of the true contact state left out of the accuracy (s).
pub const TRANSITION_S: f64 = 0.01;

/// Every how many ticks the trace and the jamming diagram take a sample.
const SAMPLE_EVERY: u64 = 50;

/// The figures of one insertion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InsertionRun {
    /// Depth reached without exceeding the force limit.
    pub inserted: bool,
    /// Time from the first contact to the depth (s), if reached.
    pub insertion_time_s: Option<f64>,
    /// Largest contact force (N).
    pub peak_force_n: f64,
    /// Largest depth (mm).
    pub depth_mm: f64,
    /// Ticks spent jammed (true state).
    pub jammed_ticks: u64,
    /// Ticks spent wedged.
    pub wedged_ticks: u64,
    /// Ticks whose estimated contact state was the true one, over those counted (outside
    /// 10 ms of a change of the true state; two-point, jammed and wedged are one class).
    pub state_classification_accuracy: f64,
    /// Ticks counted.
    pub classified_ticks: usize,
    /// The counted ticks estimated wrong, by true and estimated class, most first.
    #[serde(default)]
    pub wrong_states: Vec<WrongStates>,
    /// Time each phase began (s): find, align, insert, done.
    pub phase_starts_s: [Option<f64>; 4],
    /// Samples of the applied wrench while the wrist pressed the peg in the hole with at least
    /// [`WHITNEY_LEAST_FZ_N`].
    pub jamming_diagram_samples: usize,
    /// The fraction of them inside Whitney's jamming parallelogram at the depth of the moment.
    pub inside_parallelogram: Option<f64>,
    /// Ticks seen (with those of the hold at depth).
    pub ticks: u64,
    /// The force limit the insertion was held to (N).
    #[serde(default)]
    pub force_limit_n: f64,
    /// Time of the last tick seen (s): where a run shorter than the time limit was cut.
    #[serde(default)]
    pub duration_s: f64,
}

/// Counted ticks of one true class estimated as another.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct WrongStates {
    /// The true class.
    pub truth: ContactState,
    /// The estimated class.
    pub estimated: ContactState,
    /// How many ticks.
    pub ticks: usize,
}

/// Turns an insertion's ticks into an [`InsertionRun`].
#[derive(Debug, Clone)]
pub struct InsertionMonitor {
    dt: f64,
    fit: Fit,
    limit_n: f64,
    /// (tick start, true class before the tick, estimated class).
    states: Vec<(f64, ContactState, ContactState)>,
    changes: Vec<f64>,
    true_before: ContactState,
    phase: Phase,
    starts: [Option<f64>; 4],
    contact_t: Option<f64>,
    peak: f64,
    depth: f64,
    jammed: u64,
    wedged: u64,
    /// Every 5 ms: time, depth (mm), F_x, F_y (N), tilt (deg).
    trace: Vec<[f64; 5]>,
    /// Every 5 ms in the hole: the applied wrench on Whitney's axes.
    whitney: Vec<[f64; 2]>,
    inside: usize,
    ticks: u64,
    last_t: f64,
}

impl InsertionMonitor {
    /// A monitor for ticks of `dt` of a peg in `fit`, failed above `limit_n` of contact force.
    pub fn new(dt: f64, fit: Fit, limit_n: f64) -> Self {
        Self {
            dt,
            fit,
            limit_n,
            states: Vec::new(),
            changes: Vec::new(),
            true_before: ContactState::Free,
            phase: Phase::Approach,
            starts: [None; 4],
            contact_t: None,
            peak: 0.0,
            depth: 0.0,
            jammed: 0,
            wedged: 0,
            trace: Vec::new(),
            whitney: Vec::new(),
            inside: 0,
            ticks: 0,
            last_t: 0.0,
        }
    }

    /// One tick. Once the insertion is done, the ticks of the hold at depth (the `insertion`
    /// scenario runs to its time limit) are counted and nothing else: the figures are the
    /// insertion's.
    pub fn push(&mut self, k: &PegTick) {
        self.ticks += 1;
        self.last_t = k.t;
        if self.phase == Phase::Done {
            return;
        }
        let start = k.t - self.dt;
        let before = class(self.true_before);
        if self.states.last().is_none_or(|s| s.1 != before) {
            self.changes.push(start);
        }
        self.states.push((start, before, class(k.estimated)));
        self.true_before = k.truth.state;
        if k.phase != self.phase {
            self.phase = k.phase;
            let i = match k.phase {
                Phase::Approach | Phase::Find => 0,
                Phase::Align => 1,
                Phase::Insert => 2,
                Phase::Done => 3,
            };
            self.starts[i] = Some(start);
            // The end of the approach: at the first contact, or in the bore untouched.
            if self.contact_t.is_none() {
                self.contact_t = Some(start);
            }
        }
        let tr = &k.truth;
        self.peak = self.peak.max(tr.force.norm());
        self.depth = self.depth.max(tr.depth_m);
        match tr.state {
            ContactState::Jammed => self.jammed += 1,
            ContactState::Wedged => self.wedged += 1,
            _ => {}
        }
        if ((k.t / self.dt).round() as u64).is_multiple_of(SAMPLE_EVERY) {
            // The wrench the wrist applies, on Whitney's axes, while the peg is pressed in the hole.
            let fz = -tr.applied_force.y;
            if tr.depth_m > 0.0 && fz > WHITNEY_LEAST_FZ_N {
                let r = 0.5 * self.fit.peg_width_m;
                let w = [
                    tr.applied_force.x / fz,
                    tr.applied_moment_about_tip / (r * fz),
                ];
                self.inside += usize::from(self.fit.slides(tr.depth_m, w[0], w[1]));
                self.whitney.push(w);
            }
            self.trace.push([
                k.t,
                tr.depth_m * 1e3,
                tr.force.x,
                tr.force.y,
                tr.pose[2].to_degrees(),
            ]);
        }
    }

    /// Depth, forces and tilt every 5 ms: time, depth (mm), F_x, F_y (N), tilt (deg).
    pub fn trace(&self) -> &[[f64; 5]] {
        &self.trace
    }

    /// The applied wrench in the hole every 5 ms, on Whitney's axes (F_x/F_z, M/(r F_z)).
    pub fn whitney(&self) -> &[[f64; 2]] {
        &self.whitney
    }

    /// The figures so far.
    pub fn report(&self) -> InsertionRun {
        let inserted = self.phase == Phase::Done && self.peak <= self.limit_n;
        let time = match (inserted, self.contact_t, self.starts[3]) {
            (true, Some(a), Some(b)) => Some(b - a),
            _ => None,
        };
        let (wrong, counted) = classification(&self.states, &self.changes, TRANSITION_S);
        let right = counted - wrong.iter().map(|w| w.ticks).sum::<usize>();
        InsertionRun {
            inserted,
            insertion_time_s: time,
            peak_force_n: self.peak,
            depth_mm: self.depth * 1e3,
            jammed_ticks: self.jammed,
            wedged_ticks: self.wedged,
            state_classification_accuracy: right as f64 / counted.max(1) as f64,
            classified_ticks: counted,
            wrong_states: wrong,
            phase_starts_s: self.starts,
            jamming_diagram_samples: self.whitney.len(),
            inside_parallelogram: (!self.whitney.is_empty())
                .then(|| self.inside as f64 / self.whitney.len() as f64),
            ticks: self.ticks,
            force_limit_n: self.limit_n,
            duration_s: self.last_t,
        }
    }
}

/// The ticks of `states` (time, true class, estimated class) counted, those farther than
/// `window` from every time in `changes`: the wrong ones by true and estimated class (most
/// first), and how many.
fn classification(
    states: &[(f64, ContactState, ContactState)],
    changes: &[f64],
    window: f64,
) -> (Vec<WrongStates>, usize) {
    let (mut wrong, mut counted, mut k) = (Vec::<WrongStates>::new(), 0, 0);
    for &(t, truth, estimated) in states {
        while k + 1 < changes.len() && changes[k + 1] <= t {
            k += 1;
        }
        let near = |i: usize| changes.get(i).is_some_and(|c| (c - t).abs() < window);
        if near(k) || near(k + 1) {
            continue;
        }
        counted += 1;
        if truth == estimated {
            continue;
        }
        match wrong
            .iter_mut()
            .find(|w| w.truth == truth && w.estimated == estimated)
        {
            Some(w) => w.ticks += 1,
            None => wrong.push(WrongStates {
                truth,
                estimated,
                ticks: 1,
            }),
        }
    }
    wrong.sort_by_key(|w| std::cmp::Reverse(w.ticks));
    (wrong, counted)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The wrong ticks are counted by true and estimated class, outside the transitions: on
    /// the face from the first tick, estimated right for 0.1 s and then as the chamfer.
    #[test]
    fn wrong_ticks_are_counted_by_class() {
        let fit = Fit {
            peg_width_m: 0.01,
            clearance_ratio: 0.002,
            friction: 0.3,
        };
        let mut m = InsertionMonitor::new(1e-3, fit, 15.0);
        for k in 1..=200 {
            let mut tick = PegTick {
                t: f64::from(k) * 1e-3,
                phase: Phase::Find,
                estimated: ContactState::Face,
                ..PegTick::default()
            };
            tick.truth.state = ContactState::Face;
            if k > 100 {
                tick.estimated = ContactState::Chamfer;
            }
            m.push(&tick);
        }
        let run = m.report();
        let wrong = WrongStates {
            truth: ContactState::Face,
            estimated: ContactState::Chamfer,
            ticks: 100,
        };
        assert_eq!(run.wrong_states, [wrong]);
        let right = run.classified_ticks - 100;
        assert!((80..100).contains(&right), "{run:?}");
        let accuracy = right as f64 / run.classified_ticks as f64;
        assert!((run.state_classification_accuracy - accuracy).abs() < 1e-12);
    }
}
