//! Windowed statistics for the fast loop, allocation-free after construction.
//!
//! * [`SlidingWindow`]: mean and variance over the last N samples (the thesis's 250 ms
//!   "traveling" window for the standard deviation, §4.5.2).
//! * [`PeriodWindow`]: statistics over the last K whole dither periods: mean and standard
//!   deviation of the tangential force, the mean tip velocity (the ẋ_o the contact actually
//!   saw) and the dither velocity amplitude by lock-in demodulation against the dither phase
//!   (the Aω the contact actually saw).

use serde::Serialize;

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
}
