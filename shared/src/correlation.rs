//! The preliminary surface-tracking method of thesis §5.2 (eqs. 5.1–5.4), as the baseline the
//! dither method is compared with (`afs experiment fig5.3`).
//!
//! The surface is modelled globally as a polynomial `ŷ(x) = Σ W_i x̃^i` (x̃ = x/L) along the
//! initial tangent; the tool is position-controlled along the normal to follow `ŷ − δ_0`
//! (no force loop), with a small dither along the normal. Each tick the weights move down the
//! gradient of `J = ½(f − f_d)²` (eq. 5.1):
//! `ΔW_i = −η (f − f_d) (∂f/∂y) (∂y/∂W_i)` (eq. 5.2–5.3), with `∂y/∂W_i = x̃^i` and `∂f/∂y`
//! from the correlation of the force with the dither over a sliding window (eq. 5.4; the
//! printed 5.4 puts the square of each deviation under the sum without summing it, the
//! regression slope is `Σ(y−ȳ)(f−f̄) / Σ(y−ȳ)²`). η is set from a time constant: `η = dt/(τ k²)`
//! with k a reference contact stiffness, so the model height error decays at about 1/τ.
//!
//! Its failure modes, which the thesis reports: a global polynomial cannot follow corners, and
//! errors in the higher coefficients grow away from where the data are.

use crate::window::SlidingWindow;
use serde::{Deserialize, Serialize};

/// Highest polynomial degree.
pub const MAX_DEGREE: usize = 4;

/// Settings of the correlation tracker.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CorrelationParams {
    /// Polynomial degree (≤ 4).
    pub degree: usize,
    /// Length scale L of x̃ = x/L (m).
    pub length_scale_m: f64,
    /// Adaptation time constant τ (s).
    pub time_constant_s: f64,
    /// Reference contact stiffness for η (N/m).
    pub stiffness_n_per_m: f64,
    /// Normal dither amplitude (m) and frequency (Hz).
    pub dither_amplitude_m: f64,
    /// Normal dither frequency (Hz).
    pub dither_hz: f64,
    /// Correlation window (s).
    pub window_s: f64,
}

impl Default for CorrelationParams {
    fn default() -> Self {
        Self {
            degree: 2,
            length_scale_m: 0.05,
            time_constant_s: 0.3,
            stiffness_n_per_m: 1300.0,
            dither_amplitude_m: 1e-4,
            dither_hz: 5.0,
            window_s: 1.0,
        }
    }
}

/// The preliminary method's state.
#[derive(Debug, Clone)]
pub struct CorrelationTracker {
    params: CorrelationParams,
    weights: [f64; MAX_DEGREE + 1],
    y_window: SlidingWindow,
    f_window: SlidingWindow,
    yf_window: SlidingWindow,
    slope: f64,
    phase: f64,
    last_dither: f64,
}

impl CorrelationTracker {
    /// A tracker with initial weights (model heights in m for x̃^0, x̃^1, …) and servo period dt.
    pub fn new(params: CorrelationParams, initial: &[f64], dt: f64) -> Self {
        let mut weights = [0.0; MAX_DEGREE + 1];
        for (w, v) in weights
            .iter_mut()
            .zip(initial)
            .take(params.degree.min(MAX_DEGREE) + 1)
        {
            *w = *v;
        }
        let n = (params.window_s / dt).round().max(2.0) as usize;
        Self {
            params,
            weights,
            y_window: SlidingWindow::new(n),
            f_window: SlidingWindow::new(n),
            yf_window: SlidingWindow::new(n),
            slope: -params.stiffness_n_per_m,
            phase: 0.0,
            last_dither: 0.0,
        }
    }

    /// Model height ŷ(x) (m) and slope dŷ/dx.
    pub fn model(&self, x: f64) -> (f64, f64) {
        let l = self.params.length_scale_m;
        let xt = x / l;
        let (mut y, mut dy, mut p) = (0.0, 0.0, 1.0);
        for (i, w) in self
            .weights
            .iter()
            .enumerate()
            .take(self.params.degree.min(MAX_DEGREE) + 1)
        {
            y += w * p;
            if i < MAX_DEGREE {
                dy += (i + 1) as f64 * self.weights.get(i + 1).copied().unwrap_or(0.0) * p / l;
            }
            p *= xt;
        }
        (y, dy)
    }

    /// The correlation estimate of ∂f/∂y (N/m), eq. 5.4.
    pub fn slope(&self) -> f64 {
        self.slope
    }

    /// The weights.
    pub fn weights(&self) -> &[f64] {
        &self.weights[..=self.params.degree.min(MAX_DEGREE)]
    }

    /// One tick at position x (m along the initial tangent) with normal force f (N) and desired
    /// force f_d; returns the normal dither offset (m) to add to the commanded height ŷ(x) − δ0.
    /// The force is correlated with the dither applied on the previous tick (eq. 5.4: "a
    /// correlation between the forces and dither motion").
    pub fn step(&mut self, x: f64, f: f64, f_d: f64, dt: f64) -> f64 {
        let p = self.params;
        let y = self.last_dither;
        self.y_window.push(y);
        self.f_window.push(f);
        self.yf_window.push(y * f);
        if self.y_window.is_full() {
            let var_y = self.y_window.variance();
            let cov = self.yf_window.mean() - self.y_window.mean() * self.f_window.mean();
            if var_y > 1e-14 {
                // Pushing into the surface raises the force: a usable slope is negative and
                // of the order of the contact stiffness; otherwise keep the last one.
                let s = cov / var_y;
                let k = p.stiffness_n_per_m;
                if s.is_finite() && s < -0.2 * k && s > -5.0 * k {
                    self.slope = s;
                }
            }
        }
        // Eq. 5.2: ΔW_i = −η (f − f_d)(∂f/∂y) x̃^i.
        let eta = dt / (p.time_constant_s * p.stiffness_n_per_m.powi(2));
        let xt = x / p.length_scale_m;
        let e = f - f_d;
        let mut pow = 1.0;
        for w in self.weights.iter_mut().take(p.degree.min(MAX_DEGREE) + 1) {
            *w -= eta * e * self.slope * pow;
            pow *= xt;
        }
        self.phase =
            (self.phase + std::f64::consts::TAU * p.dither_hz * dt) % std::f64::consts::TAU;
        self.last_dither = p.dither_amplitude_m * self.phase.sin();
        self.last_dither
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against an ideal spring surface f = k (ŷ_true(x) − y_tool) the weights converge to a
    /// quadratic surface from an initial guess within 10 %, and ∂f/∂y comes out as −k.
    #[test]
    fn converges_on_a_quadratic_from_a_close_guess() {
        let k = 1300.0;
        let truth = [0.001, 0.002, 0.0015];
        let params = CorrelationParams::default();
        let dt = 1e-3;
        let mut c = CorrelationTracker::new(params, &[0.0009, 0.0022, 0.00135], dt);
        let depth = 2.5 / k;
        let mut x = -0.05;
        let h = |x: f64| truth[0] + truth[1] * x / 0.05 + truth[2] * (x / 0.05).powi(2);
        let mut dither = 0.0;
        let mut worst_late: f64 = 0.0;
        while x < 0.05 {
            let y_tool = c.model(x).0 - depth + dither;
            let f = (k * (h(x) - y_tool)).max(0.0);
            dither = c.step(x, f, 2.5, dt);
            if x > 0.0 {
                worst_late = worst_late.max((c.model(x).0 - h(x)).abs());
            }
            x += 0.005 * dt;
        }
        // The weights follow the 5 Hz dither a little through the force error (about
        // 1/(2π·5·τ) ≈ 0.1 with τ = 0.3 s), which shrinks the correlation slope by that much.
        assert!((c.slope() + k).abs() < 0.15 * k, "slope {}", c.slope());
        // Where the tool is, the model follows the surface to within a fraction of the 0.1 mm
        // dither (the weights follow the dither's force response by about 1/(2π·5·τ) ≈ 0.1,
        // and the slope estimate lags it).
        assert!(
            worst_late < 4e-5,
            "worst model error over the second half {worst_late}"
        );
    }
}
