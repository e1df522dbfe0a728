//! Friction identification (thesis §4.5.2, eq. 4.23 and fig. 4.6), by least squares with a
//! reported residual.
//!
//! * [`fit_friction_law`]: F_t, F_v, F_s and ẋ_s of eq. 4.5 from (speed, friction) pairs of
//!   constant-velocity runs. The model is linear in (F_t, F_v, F_s) for a fixed ẋ_s, so the fit
//!   is a separable (variable-projection) least squares: for each ẋ_s the linear coefficients
//!   come from a 3×3 solve, and the one-dimensional residual over log ẋ_s is minimised by a grid
//!   and golden-section search. Noise-free data give the coefficients back exactly.
//! * [`fit_friction_coefficient`]: μ from (F_N, F_t) trial means. The thesis's 0.709 (fig. 4.6)
//!   is the mean of the per-trial ratios F_t/F_N, i.e. the least-squares μ for the relative
//!   residuals `F_t/F_N − μ`; the through-origin least squares of `F_t − μF_N` is reported too.

use crate::friction::FrictionLaw;
use crate::math::grid_then_golden;
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

/// Why identification failed; each tells what data is missing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentError {
    /// Too few points for the number of unknowns.
    #[error("need at least {needed} data points, got {got}: run more velocity levels")]
    TooFewPoints {
        /// Required.
        needed: usize,
        /// Given.
        got: usize,
    },
    /// A data point is NaN, infinite, or has a non-positive speed/normal force.
    #[error("data point {0} is not usable (non-finite, or speed / normal force ≤ 0)")]
    BadPoint(usize),
    /// The speeds do not span enough range to separate the terms.
    #[error(
        "speeds span only {ratio:.1}×; the Stribeck and viscous terms need ≥ 20× (e.g. 1 mm/s to 200 mm/s)"
    )]
    NarrowRange {
        /// max/min speed.
        ratio: f64,
    },
    /// The least-squares system is singular.
    #[error("the least-squares system is singular")]
    Singular,
}

/// Result of the eq. 4.5 fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FrictionFit {
    /// Identified coefficients.
    pub law: FrictionLaw,
    /// RMS residual of the fit (N).
    pub rms_residual_n: f64,
    /// Number of points.
    pub points: usize,
}

fn basis(v: f64, xs: f64) -> Vector3<f64> {
    let u = v / xs;
    Vector3::new(1.0, v, 1.0 / (1.0 + u * u))
}

fn linear_fit(data: &[(f64, f64)], xs: f64) -> Option<(Vector3<f64>, f64)> {
    let mut ata = Matrix3::zeros();
    let mut atb = Vector3::zeros();
    // Scale columns for conditioning: F_v's column is ~v, tiny against 1.
    let vmax = data.iter().map(|d| d.0).fold(0.0, f64::max).max(1e-12);
    let scale = Vector3::new(1.0, 1.0 / vmax, 1.0);
    for &(v, f) in data {
        let b = basis(v, xs).component_mul(&scale);
        ata += b * b.transpose();
        atb += b * f;
    }
    let c = ata.cholesky()?.solve(&atb);
    let coef = c.component_mul(&scale);
    let sse: f64 = data
        .iter()
        .map(|&(v, f)| (basis(v, xs).dot(&coef) - f).powi(2))
        .sum();
    Some((coef, sse))
}

/// Fits eq. 4.5 to (speed m/s > 0, friction magnitude N) pairs.
pub fn fit_friction_law(data: &[(f64, f64)]) -> Result<FrictionFit, IdentError> {
    if data.len() < 5 {
        return Err(IdentError::TooFewPoints {
            needed: 5,
            got: data.len(),
        });
    }
    for (i, &(v, f)) in data.iter().enumerate() {
        if !(v.is_finite() && f.is_finite() && v > 0.0) {
            return Err(IdentError::BadPoint(i));
        }
    }
    let vmin = data.iter().map(|d| d.0).fold(f64::INFINITY, f64::min);
    let vmax = data.iter().map(|d| d.0).fold(0.0, f64::max);
    if vmax / vmin < 20.0 {
        return Err(IdentError::NarrowRange { ratio: vmax / vmin });
    }
    let sse_at = |log_xs: f64| {
        linear_fit(data, log_xs.exp())
            .map(|r| r.1)
            .unwrap_or(f64::INFINITY)
    };
    let (log_xs, _) = grid_then_golden((vmin / 10.0).ln(), (vmax * 2.0).ln(), 200, 80, sse_at);
    let xs = log_xs.exp();
    let (c, sse) = linear_fit(data, xs).ok_or(IdentError::Singular)?;
    Ok(FrictionFit {
        law: FrictionLaw {
            kinetic_n: c[0],
            viscous_n_s_per_m: c[1],
            stribeck_n: c[2],
            stribeck_velocity_m_per_s: xs,
        },
        rms_residual_n: (sse / data.len() as f64).sqrt(),
        points: data.len(),
    })
}

/// Result of the μ fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CoefficientFit {
    /// Mean of per-trial ratios F_t/F_N (the thesis's estimator, fig. 4.6).
    pub mu: f64,
    /// RMS of the ratio residuals `F_t/F_N − μ`.
    pub rms_ratio_residual: f64,
    /// Through-origin least squares `Σ F_N F_t / Σ F_N²`.
    pub mu_least_squares: f64,
    /// RMS of `F_t − μ_ls F_N` (N).
    pub rms_force_residual_n: f64,
    /// Number of trials.
    pub trials: usize,
}

/// μ from (F_N, F_t) pairs (N).
pub fn fit_friction_coefficient(pairs: &[(f64, f64)]) -> Result<CoefficientFit, IdentError> {
    if pairs.is_empty() {
        return Err(IdentError::TooFewPoints { needed: 1, got: 0 });
    }
    for (i, &(fnn, ft)) in pairs.iter().enumerate() {
        if !(fnn.is_finite() && ft.is_finite() && fnn > 0.0) {
            return Err(IdentError::BadPoint(i));
        }
    }
    let n = pairs.len() as f64;
    let mu = pairs.iter().map(|&(a, b)| b / a).sum::<f64>() / n;
    let rr = (pairs
        .iter()
        .map(|&(a, b)| (b / a - mu).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let mu_ls = pairs.iter().map(|&(a, b)| a * b).sum::<f64>()
        / pairs.iter().map(|&(a, _)| a * a).sum::<f64>();
    let rf = (pairs
        .iter()
        .map(|&(a, b)| (b - mu_ls * a).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    Ok(CoefficientFit {
        mu,
        rms_ratio_residual: rr,
        mu_least_squares: mu_ls,
        rms_force_residual_n: rf,
        trials: pairs.len(),
    })
}

/// The six trials printed in fig. 4.6: (F_N, F_t) in N.
pub const THESIS_FIG_4_6: [(f64, f64); 6] = [
    (1.750, 1.179),
    (2.015, 1.462),
    (2.156, 1.425),
    (2.645, 1.840),
    (3.886, 2.813),
    (5.263, 4.084),
];

#[cfg(test)]
mod tests {
    use super::*;

    /// Noise-free data from the thesis's law are identified exactly (1e-6 relative).
    #[test]
    fn identification_is_exact_on_noise_free_data() {
        let truth = FrictionLaw::THESIS;
        let speeds = [
            0.001, 0.002, 0.003, 0.005, 0.007, 0.01, 0.015, 0.02, 0.03, 0.05, 0.07, 0.1, 0.15, 0.2,
        ];
        let data: Vec<(f64, f64)> = speeds.iter().map(|&v| (v, truth.resistance(v))).collect();
        let fit = fit_friction_law(&data).unwrap();
        let l = fit.law;
        for (got, want) in [
            (l.kinetic_n, truth.kinetic_n),
            (l.viscous_n_s_per_m, truth.viscous_n_s_per_m),
            (l.stribeck_n, truth.stribeck_n),
            (l.stribeck_velocity_m_per_s, truth.stribeck_velocity_m_per_s),
        ] {
            assert!((got - want).abs() < 1e-6 * want, "{got} vs {want}");
        }
        assert!(fit.rms_residual_n < 1e-9);
    }

    #[test]
    fn bad_identification_input_is_refused() {
        assert!(matches!(
            fit_friction_law(&[(0.01, 1.0); 3]),
            Err(IdentError::TooFewPoints { .. })
        ));
        let narrow: Vec<(f64, f64)> = (1..8).map(|k| (0.01 + 0.001 * k as f64, 1.0)).collect();
        assert!(matches!(
            fit_friction_law(&narrow),
            Err(IdentError::NarrowRange { .. })
        ));
        let mut bad: Vec<(f64, f64)> = (1..8).map(|k| (0.001 * 3f64.powi(k), 1.0)).collect();
        bad[2].1 = f64::NAN;
        assert_eq!(fit_friction_law(&bad), Err(IdentError::BadPoint(2)));
        assert!(fit_friction_coefficient(&[(0.0, 1.0)]).is_err());
    }

    /// Fig. 4.6's table gives the printed 0.709 as the mean of the ratios.
    #[test]
    fn thesis_table_gives_0_709() {
        let fit = fit_friction_coefficient(&THESIS_FIG_4_6).unwrap();
        assert_eq!(format!("{:.3}", fit.mu), "0.709");
        assert!(
            (fit.mu_least_squares - 0.737).abs() < 1e-3,
            "{}",
            fit.mu_least_squares
        );
    }

    #[test]
    fn coefficient_fit_is_exact_on_proportional_data() {
        let pairs: Vec<(f64, f64)> = [1.0, 2.0, 3.5].iter().map(|&n| (n, 0.6 * n)).collect();
        let fit = fit_friction_coefficient(&pairs).unwrap();
        assert!((fit.mu - 0.6).abs() < 1e-15 && (fit.mu_least_squares - 0.6).abs() < 1e-15);
        assert!(fit.rms_force_residual_n < 1e-15);
    }
}

/// On-line friction identification from the servo's stream (the estimator board runs it on
/// every [`ServoSample`](crate::msg::ServoSample)).
///
/// It collects windows of steady, undithered sliding: the servo tracking at its requested
/// velocity with no dither, for at least `settle_s` since the velocity was reached, cut into
/// windows of `window_s`. Each window gives a friction coefficient μ = mean friction / mean
/// normal force (fig. 4.6) and a point (speed, friction at the reference normal force) for
/// eq. 4.5; once the speeds span 20× the law is fitted with [`fit_friction_law`].
#[derive(Debug, Clone)]
pub struct OnlineFrictionId {
    settle_s: f64,
    window_s: f64,
    steady_since: Option<f64>,
    target: f64,
    acc: WindowAcc,
    points: Vec<(f64, f64)>,
    mus: Vec<(f64, f64)>,
    max_points: usize,
    fit: Option<FrictionFit>,
    last_mu: Option<(f64, f64)>,
}

#[derive(Debug, Clone, Copy, Default)]
struct WindowAcc {
    t0: f64,
    n: f64,
    friction: f64,
    normalized: f64,
    normal: f64,
    speed: f64,
}

/// One tick of the servo's stream, as the identification needs it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct IdentTick {
    /// Time (s).
    pub t: f64,
    /// Requested velocity (m/s).
    pub velocity_target: f64,
    /// Nominal velocity (m/s).
    pub nominal_velocity: f64,
    /// Commanded Aω (m/s).
    pub a_omega: f64,
    /// Measured tangential force along t̂ (N).
    pub tangential_force: f64,
    /// Friction normalised to the reference normal force (N).
    pub friction_normalized: f64,
    /// Measured normal force (N).
    pub normal_force: f64,
    /// Measured tip velocity along t̂ (m/s).
    pub tangent_velocity: f64,
    /// Tracking with good force data.
    pub tracking: bool,
}

/// What the identification holds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OnlineIdent {
    /// Windows used.
    pub windows: usize,
    /// Distinct speed levels (1 % apart).
    pub speeds: usize,
    /// μ of the latest speed level: mean and spread over its windows.
    pub mu: Option<(f64, f64)>,
    /// The eq. 4.5 fit, once the speeds span enough.
    pub fit: Option<FrictionFit>,
}

impl OnlineFrictionId {
    /// Windows of `window_s` after `settle_s` of steady motion; keeps at most `max_points`.
    pub fn new(settle_s: f64, window_s: f64, max_points: usize) -> Self {
        Self {
            settle_s,
            window_s,
            steady_since: None,
            target: 0.0,
            acc: WindowAcc::default(),
            points: Vec::with_capacity(max_points),
            mus: Vec::with_capacity(max_points),
            max_points,
            fit: None,
            last_mu: None,
        }
    }

    /// One tick.
    pub fn push(&mut self, k: &IdentTick) {
        let values = [
            k.t,
            k.velocity_target,
            k.nominal_velocity,
            k.a_omega,
            k.tangential_force,
            k.friction_normalized,
            k.normal_force,
            k.tangent_velocity,
        ];
        let steady = k.tracking
            && values.iter().all(|v| v.is_finite())
            && k.velocity_target != 0.0
            && (k.nominal_velocity - k.velocity_target).abs() < 1e-9
            && k.a_omega < 1e-6
            && k.normal_force > 0.0;
        if !steady || k.velocity_target != self.target {
            self.steady_since = steady.then_some(k.t);
            self.target = k.velocity_target;
            self.acc = WindowAcc::default();
            return;
        }
        let since = *self.steady_since.get_or_insert(k.t);
        if k.t - since < self.settle_s {
            return;
        }
        let dir = k.velocity_target.signum();
        if self.acc.n == 0.0 {
            self.acc.t0 = k.t;
        }
        self.acc.n += 1.0;
        self.acc.friction += -k.tangential_force * dir;
        self.acc.normalized += k.friction_normalized;
        self.acc.normal += k.normal_force;
        self.acc.speed += k.tangent_velocity * dir;
        if k.t - self.acc.t0 >= self.window_s {
            let a = self.acc;
            self.acc = WindowAcc::default();
            if self.points.len() < self.max_points && a.normal > 0.0 && a.speed > 0.0 {
                let speed = k.velocity_target.abs();
                self.points.push((speed, a.normalized / a.n));
                self.mus.push((speed, a.friction / a.normal));
                self.update(speed);
            }
        }
    }

    fn update(&mut self, speed: f64) {
        let same: Vec<f64> = self
            .mus
            .iter()
            .filter(|(s, _)| (s - speed).abs() <= 0.01 * speed)
            .map(|m| m.1)
            .collect();
        let n = same.len() as f64;
        let mean = same.iter().sum::<f64>() / n;
        let var = same.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / n;
        self.last_mu = Some((mean, var.sqrt()));
        // A fit is kept only if it is physical: kinetic friction > 0, Stribeck term ≥ 0.
        self.fit = fit_friction_law(&self.points)
            .ok()
            .filter(|f| f.law.kinetic_n > 0.0 && f.law.stribeck_n >= 0.0);
    }

    /// The state of the identification.
    pub fn report(&self) -> OnlineIdent {
        let mut levels: Vec<f64> = Vec::new();
        for (s, _) in &self.points {
            if !levels.iter().any(|l| (l - s).abs() <= 0.01 * s) {
                levels.push(*s);
            }
        }
        OnlineIdent {
            windows: self.points.len(),
            speeds: levels.len(),
            mu: self.last_mu,
            fit: self.fit,
        }
    }
}

#[cfg(test)]
mod online_tests {
    use super::*;

    /// Steady windows of an exact eq. 4.5 law at six speeds identify it; dithered, unsteady or
    /// invalid ticks are ignored.
    #[test]
    fn identifies_the_law_from_steady_windows() {
        let law = FrictionLaw::THESIS;
        let mut id = OnlineFrictionId::new(0.2, 0.25, 1000);
        let dt = 1e-3;
        let mut t = 0.0;
        for v in [0.002, 0.004, 0.008, 0.016, 0.032, 0.048] {
            for dir in [1.0, -1.0] {
                for k in 0..1200 {
                    let f = law.resistance(v);
                    let normal = 2.5;
                    let dithered = k < 100;
                    id.push(&IdentTick {
                        t,
                        velocity_target: dir * v,
                        nominal_velocity: dir * v,
                        a_omega: if dithered { 0.01 } else { 0.0 },
                        tangential_force: -dir * f * normal / 2.5,
                        friction_normalized: f,
                        normal_force: normal,
                        tangent_velocity: dir * v,
                        tracking: true,
                    });
                    t += dt;
                }
            }
        }
        let r = id.report();
        assert_eq!(r.speeds, 6);
        assert!(r.windows >= 36, "{}", r.windows);
        let (mu, spread) = r.mu.unwrap();
        assert!((mu - law.resistance(0.048) / 2.5).abs() < 1e-9 && spread < 1e-9);
        let fit = r.fit.unwrap().law;
        assert!(
            (fit.kinetic_n - law.kinetic_n).abs() < 1e-6 * law.kinetic_n,
            "{fit:?}"
        );
        assert!((fit.stribeck_n - law.stribeck_n).abs() < 1e-5, "{fit:?}");
    }
}
