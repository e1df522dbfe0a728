//! Windowed statistics for the fast loop, allocation-free after construction.
//!
//! * [`SlidingWindow`]: mean and variance over the last N samples (the thesis's 250 ms
//!   "traveling" window for the standard deviation, §4.5.2).
//! * [`PeriodWindow`]: statistics over the last K whole dither periods: mean and standard
//!   deviation of the tangential force, the mean tip velocity (the ẋ_o the contact actually
//!   saw) and the dither velocity amplitude by lock-in demodulation against the dither phase
//!   (the Aω the contact actually saw).

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

wire_struct! {
    /// A [`SlidingWindow`] in brief, for a snapshot: how many samples it holds, their mean and
    /// their variance. Restoring refills the window with samples of that mean and (nearly) that
    /// variance, so both carry on and the samples themselves are forgotten: they are replaced as
    /// new ones come, one window later.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::SlidingSummary")]
    pub struct SlidingSummary {
        /// Samples held.
        pub len: u64,
        /// Their mean.
        pub mean: f64,
        /// Their variance.
        pub variance: f64,
    }
}

/// The sums of one dither period of a [`PeriodWindow`], in the order of its fields (samples,
/// force, force², velocity, velocity·cos φ, velocity·sin φ, normal force, commanded Aω).
pub type PeriodSumsState = [f64; 8];

wire_struct! {
    /// A [`PeriodWindow`]'s whole state, for a snapshot.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::PeriodWindowState")]
    pub struct PeriodWindowState {
        /// The period in progress.
        pub current: PeriodSumsState,
        /// The finished periods (ring).
        pub ring: [PeriodSumsState; MAX_PERIODS],
        /// Finished periods held.
        pub filled: u32,
        /// Next ring slot.
        pub head: u32,
    }
}

/// Mean and variance over the last `capacity` samples.
#[derive(Debug, Clone)]
pub struct SlidingWindow {
    buf: Vec<f64>,
    head: usize,
    len: usize,
    sum: f64,
    sum2: f64,
    since_recompute: usize,
}

impl SlidingWindow {
    /// A window of `capacity ≥ 1` samples.
    pub fn new(capacity: usize) -> Self {
        Self {
            buf: vec![0.0; capacity.max(1)],
            head: 0,
            len: 0,
            sum: 0.0,
            sum2: 0.0,
            since_recompute: 0,
        }
    }

    /// Adds a sample, dropping the oldest when full.
    pub fn push(&mut self, x: f64) {
        let cap = self.buf.len();
        if self.len == cap {
            let old = self.buf[self.head];
            self.sum -= old;
            self.sum2 -= old * old;
        } else {
            self.len += 1;
        }
        self.buf[self.head] = x;
        self.sum += x;
        self.sum2 += x * x;
        self.head = (self.head + 1) % cap;
        self.since_recompute += 1;
        if self.since_recompute >= cap {
            // Re-sum now and then so rounding errors of the running sums do not accumulate.
            self.since_recompute = 0;
            let (mut s, mut s2) = (0.0, 0.0);
            for &v in &self.buf[..] {
                s += v;
                s2 += v * v;
            }
            if self.len == cap {
                self.sum = s;
                self.sum2 = s2;
            }
        }
    }

    /// Number of samples held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Capacity (samples).
    pub fn capacity(&self) -> usize {
        self.buf.len()
    }

    /// True when no sample is held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// True when the window is full.
    pub fn is_full(&self) -> bool {
        self.len == self.buf.len()
    }

    /// Mean (0 when empty).
    pub fn mean(&self) -> f64 {
        if self.len == 0 {
            0.0
        } else {
            self.sum / self.len as f64
        }
    }

    /// Its count, mean and variance ([`SlidingSummary`]).
    pub fn summary(&self) -> SlidingSummary {
        SlidingSummary {
            len: self.len as u64,
            mean: self.mean(),
            variance: self.variance(),
        }
    }

    /// Refills the window from a summary: `len` samples (at most its capacity) alternating
    /// `mean ± σ`, and `mean` itself for an odd count, so the mean is exact and the variance
    /// is `σ²` (`σ²·(len−1)/len` for an odd count). Non-finite values empty it.
    pub fn refill(&mut self, s: &SlidingSummary) {
        let cap = self.buf.len();
        let len = usize::try_from(s.len).unwrap_or(cap).min(cap);
        self.buf.iter_mut().for_each(|v| *v = 0.0);
        self.len = 0;
        self.head = 0;
        self.sum = 0.0;
        self.sum2 = 0.0;
        self.since_recompute = 0;
        if !(s.mean.is_finite() && s.variance.is_finite()) {
            return;
        }
        let sd = s.variance.max(0.0).sqrt();
        for i in 0..len {
            let x = if len % 2 == 1 && i == len - 1 {
                s.mean
            } else if i % 2 == 0 {
                s.mean + sd
            } else {
                s.mean - sd
            };
            self.push(x);
        }
    }

    /// Population variance (0 when empty).
    pub fn variance(&self) -> f64 {
        if self.len == 0 {
            return 0.0;
        }
        let m = self.mean();
        (self.sum2 / self.len as f64 - m * m).max(0.0)
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct PeriodSums {
    n: f64,
    f: f64,
    f2: f64,
    v: f64,
    v_cos: f64,
    v_sin: f64,
    normal: f64,
    a_cmd: f64,
}

impl PeriodSums {
    fn to_array(self) -> PeriodSumsState {
        [
            self.n,
            self.f,
            self.f2,
            self.v,
            self.v_cos,
            self.v_sin,
            self.normal,
            self.a_cmd,
        ]
    }

    fn from_array(a: &PeriodSumsState) -> Self {
        let [n, f, f2, v, v_cos, v_sin, normal, a_cmd] = *a;
        Self {
            n,
            f,
            f2,
            v,
            v_cos,
            v_sin,
            normal,
            a_cmd,
        }
    }

    fn add(&mut self, o: &PeriodSums) {
        self.n += o.n;
        self.f += o.f;
        self.f2 += o.f2;
        self.v += o.v;
        self.v_cos += o.v_cos;
        self.v_sin += o.v_sin;
        self.normal += o.normal;
        self.a_cmd += o.a_cmd;
    }
}

/// Statistics over whole dither periods.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct PeriodStats {
    /// Mean tangential (friction) force (N).
    pub mean_force_n: f64,
    /// Standard deviation of the tangential force (N).
    pub std_force_n: f64,
    /// Mean tip velocity along the tangent (m/s): the ẋ_o the contact saw.
    pub mean_velocity_m_per_s: f64,
    /// Amplitude of the tip velocity at the dither frequency (m/s): the Aω the contact saw.
    pub dither_velocity_m_per_s: f64,
    /// Mean normal force (N).
    pub mean_normal_n: f64,
    /// Mean commanded Aω over the window (m/s).
    pub commanded_a_omega_m_per_s: f64,
    /// Number of samples.
    pub samples: usize,
}

/// Maximum periods a [`PeriodWindow`] can span.
pub const MAX_PERIODS: usize = 16;

/// Statistics over the last `periods` whole dither periods.
#[derive(Debug, Clone)]
pub struct PeriodWindow {
    current: PeriodSums,
    ring: [PeriodSums; MAX_PERIODS],
    periods: usize,
    filled: usize,
    head: usize,
}

impl PeriodWindow {
    /// A window over `periods` (1..=16) periods.
    pub fn new(periods: usize) -> Self {
        Self {
            current: PeriodSums::default(),
            ring: [PeriodSums::default(); MAX_PERIODS],
            periods: periods.clamp(1, MAX_PERIODS),
            filled: 0,
            head: 0,
        }
    }

    /// Adds one tick: tangential force `force`, tip velocity `velocity`, dither `phase` (rad),
    /// normal force `normal` and commanded Aω `a_cmd`.
    pub fn push(&mut self, force: f64, velocity: f64, phase: f64, normal: f64, a_cmd: f64) {
        let (s, c) = phase.sin_cos();
        let p = &mut self.current;
        p.n += 1.0;
        p.f += force;
        p.f2 += force * force;
        p.v += velocity;
        p.v_cos += velocity * c;
        p.v_sin += velocity * s;
        p.normal += normal;
        p.a_cmd += a_cmd;
    }

    /// Closes the current period; returns the window's statistics once `periods` are held.
    pub fn end_period(&mut self) -> Option<PeriodStats> {
        if self.current.n == 0.0 {
            return None;
        }
        self.ring[self.head] = self.current;
        self.current = PeriodSums::default();
        self.head = (self.head + 1) % self.periods;
        self.filled = (self.filled + 1).min(self.periods);
        if self.filled < self.periods {
            return None;
        }
        let mut t = PeriodSums::default();
        for p in &self.ring[..self.periods] {
            t.add(p);
        }
        let n = t.n;
        let mean = t.f / n;
        let i = 2.0 * t.v_cos / n;
        let q = 2.0 * t.v_sin / n;
        Some(PeriodStats {
            mean_force_n: mean,
            std_force_n: (t.f2 / n - mean * mean).max(0.0).sqrt(),
            mean_velocity_m_per_s: t.v / n,
            dither_velocity_m_per_s: (i * i + q * q).sqrt(),
            mean_normal_n: t.normal / n,
            commanded_a_omega_m_per_s: t.a_cmd / n,
            samples: n as usize,
        })
    }

    /// Forgets everything (e.g. after the dither frequency changed).
    pub fn reset(&mut self) {
        *self = Self::new(self.periods);
    }

    /// Its whole state.
    pub fn state(&self) -> PeriodWindowState {
        PeriodWindowState {
            current: self.current.to_array(),
            ring: self.ring.map(|p| p.to_array()),
            filled: self.filled as u32,
            head: self.head as u32,
        }
    }

    /// Restores a state taken by [`PeriodWindow::state`] of a window with as many periods.
    pub fn restore(&mut self, s: &PeriodWindowState) {
        self.current = PeriodSums::from_array(&s.current);
        self.ring = s.ring.map(|p| PeriodSums::from_array(&p));
        self.filled = (s.filled as usize).min(self.periods);
        self.head = (s.head as usize) % self.periods;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sliding_window_matches_direct_statistics() {
        let mut w = SlidingWindow::new(50);
        let xs: Vec<f64> = (0..237)
            .map(|k| ((k * 37) % 101) as f64 * 0.1 - 3.0)
            .collect();
        for &x in &xs {
            w.push(x);
        }
        let last = &xs[xs.len() - 50..];
        let m = last.iter().sum::<f64>() / 50.0;
        let v = last.iter().map(|x| (x - m).powi(2)).sum::<f64>() / 50.0;
        assert!((w.mean() - m).abs() < 1e-12);
        assert!((w.variance() - v).abs() < 1e-10);
        assert!(w.is_full());
    }

    /// Lock-in recovers the amplitude of a phase-shifted sinusoid riding on a mean.
    #[test]
    fn period_window_lock_in() {
        let mut w = PeriodWindow::new(2);
        let n = 1000;
        let mut out = None;
        for period in 0..3 {
            for k in 0..n {
                let ph = std::f64::consts::TAU * k as f64 / n as f64;
                let v = 0.02 + 0.07 * (ph - 0.4).cos();
                w.push(1.0 + (2.0 * ph).sin(), v, ph, 2.5, 0.08);
            }
            out = w.end_period();
            if period == 0 {
                assert!(out.is_none());
            }
        }
        let s = out.unwrap();
        assert!((s.dither_velocity_m_per_s - 0.07).abs() < 1e-12);
        assert!((s.mean_velocity_m_per_s - 0.02).abs() < 1e-12);
        assert!((s.mean_force_n - 1.0).abs() < 1e-12);
        assert!((s.std_force_n - 0.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(s.samples, 2 * n);
    }

    /// A refilled window has the summary's mean exactly and its variance (even count) or
    /// (n−1)/n of it (odd count); it holds at most its capacity; a non-finite summary empties it.
    #[test]
    fn a_refilled_window_keeps_mean_and_variance() {
        let mut w = SlidingWindow::new(40);
        for i in 0..57 {
            w.push((i as f64 * 0.37).sin() * 2.0 + 1.0);
        }
        for n in [40u64, 7, 1, 0] {
            let s = SlidingSummary {
                len: n,
                ..w.summary()
            };
            let mut r = SlidingWindow::new(40);
            r.refill(&s);
            assert_eq!(r.len() as u64, n);
            if n > 0 {
                assert!((r.mean() - s.mean).abs() < 1e-12, "{n}");
                let expected = if n % 2 == 0 {
                    s.variance
                } else {
                    s.variance * (n - 1) as f64 / n as f64
                };
                assert!((r.variance() - expected).abs() < 1e-12, "{n}");
            }
        }
        let mut r = SlidingWindow::new(10);
        r.refill(&SlidingSummary {
            len: 1000,
            mean: 3.0,
            variance: 4.0,
        });
        assert_eq!(r.len(), 10);
        assert!((r.variance() - 4.0).abs() < 1e-12);
        r.refill(&SlidingSummary {
            len: 5,
            mean: f64::NAN,
            variance: 1.0,
        });
        assert!(r.is_empty());
    }

    /// A period window restored from its state gives the same statistics from then on.
    #[test]
    fn a_period_window_round_trips() {
        let mut a = PeriodWindow::new(3);
        let feed = |w: &mut PeriodWindow, k: usize| {
            let phase = (k % 100) as f64 * std::f64::consts::TAU / 100.0;
            w.push(
                (k as f64).sin(),
                0.01 + 0.02 * phase.cos(),
                phase,
                2.5,
                0.02,
            );
            (k % 100 == 99).then(|| w.end_period()).flatten()
        };
        for k in 0..450 {
            feed(&mut a, k);
        }
        let mut b = PeriodWindow::new(3);
        b.restore(&a.state());
        assert_eq!(a.state(), b.state());
        for k in 450..1000 {
            assert_eq!(feed(&mut a, k), feed(&mut b, k), "{k}");
        }
    }
}
