//! On-line estimate of the contact's normal stiffness, from what a robot measures: the normal
//! force (the wrist sensor) and the tool's position (the encoders). Nothing is read from the
//! world's contact parameters (docs/contact.md).
//!
//! The contact is a spring whose rest surface may be tilted and curved against the servo's
//! estimated tangent: along the inward normal `x` (into the surface) and the tangent `s`,
//!
//! ```text
//! F_N = k (x − x₀ − ε s − κ s²/2)
//! ```
//!
//! with k the stiffness of everything between the encoders and the surface (the part, the
//! sensor), x₀ the surface's place, ε the tangent error and κ its curvature. It is linear in
//! the parameters `[k, −kε, −kκ/2, −k x₀]` with the regressors `[x, s, s², 1]`, so an
//! exponentially weighted least-squares fit gives k from the measured F_N (noisy) on the
//! measured x and s (encoders, exact): the noise is in the fitted variable, so the fit is
//! unbiased. The tangential regressors take out the surface's own shape under the dither's and
//! the travel's motion, which would otherwise pass for compliance: on fig. 5.6's sinusoid a fit
//! on `[x, s, 1]` alone read half the stiffness. Excitation is whatever moves the penetration:
//! the first touch, the dither's normal ripple, the probe strokes, the force loop. Without it
//! the uncertainty grows and says so; the estimate is only used when it is tight.

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

/// Settings of the estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StiffnessParams {
    /// Memory of the fit (s): samples older than this weigh e⁻¹ as much.
    pub memory_s: f64,
    /// Samples below this normal force (N) are not in contact and are not fitted.
    pub min_force_n: f64,
}

impl Default for StiffnessParams {
    fn default() -> Self {
        Self {
            memory_s: 0.5,
            min_force_n: 0.25,
        }
    }
}

/// The estimate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StiffnessEstimate {
    /// Normal stiffness k̂ (N/m).
    pub stiffness_n_per_m: f64,
    /// Its standard error (N/m).
    pub std_error_n_per_m: f64,
    /// Effective number of samples in the fit.
    pub samples: f64,
}

impl StiffnessEstimate {
    /// Relative standard error σ_k / k̂ (∞ when k̂ is not positive).
    pub fn relative_error(&self) -> f64 {
        if self.stiffness_n_per_m > 0.0 {
            self.std_error_n_per_m / self.stiffness_n_per_m
        } else {
            f64::INFINITY
        }
    }
}

wire_struct! {
    /// A [`StiffnessEstimator`]'s memory, for a snapshot: the exponentially weighted sums.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::StiffnessFitState")]
    pub struct StiffnessFitState {
        /// Total weight of the samples (Σw).
        pub weight: f64,
        /// Σw² (for the effective number of samples).
        pub weight_sq: f64,
        /// Weighted means of x (m), s (m), s² (m²) and F_N (N).
        pub mean: [f64; 4],
        /// Weighted centred second moments of those, in pairs: (x, x), (x, s), (x, s²),
        /// (x, F), (s, s), (s, s²), (s, F), (s², s²), (s², F), (F, F).
        pub m2: [f64; 10],
    }
}

/// Exponentially weighted least squares of F_N on `[x, s, 1]`, kept as weighted means and
/// centred second moments (Welford's form), so that micrometre motions 0.5 m from the base
/// lose no digits.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StiffnessEstimator {
    params: StiffnessParams,
    fit: StiffnessFitState,
}

impl StiffnessEstimator {
    /// An estimator with no samples.
    pub fn new(params: StiffnessParams) -> Self {
        Self {
            params,
            fit: StiffnessFitState::default(),
        }
    }

    /// Its memory, for a snapshot.
    pub fn state(&self) -> StiffnessFitState {
        self.fit
    }

    /// Restores a memory taken by [`StiffnessEstimator::state`].
    pub fn restore(&mut self, fit: &StiffnessFitState) {
        self.fit = *fit;
    }

    /// Forgets everything (a new contact).
    pub fn reset(&mut self) {
        *self = Self::new(self.params);
    }

    /// One sample `dt` after the last: inward normal position `x` (m), tangential position
    /// `s` (m), measured normal force `force` (N). Non-finite samples and samples out of
    /// contact are skipped (the older ones still fade).
    pub fn push(&mut self, dt: f64, x: f64, s: f64, force: f64) {
        let fade = if self.params.memory_s > 0.0 && dt.is_finite() && dt > 0.0 {
            (-dt / self.params.memory_s).exp()
        } else {
            1.0
        };
        self.fit.weight *= fade;
        self.fit.weight_sq *= fade * fade;
        for m in &mut self.fit.m2 {
            *m *= fade;
        }
        if !(x.is_finite() && s.is_finite() && force.is_finite()) || force < self.params.min_force_n
        {
            return;
        }
        // West's weighted incremental update with weight 1 for the new sample.
        self.fit.weight += 1.0;
        self.fit.weight_sq += 1.0;
        let r = 1.0 / self.fit.weight;
        let v = [x, s, s * s, force];
        let mut d = [0.0; VARS];
        for ((dk, m), vk) in d.iter_mut().zip(&mut self.fit.mean).zip(v) {
            *dk = vk - *m;
            *m += *dk * r;
        }
        // After the mean moved: (v − mean_old)(w − mean_new) accumulates the centred product.
        for (m, (i, j)) in self.fit.m2.iter_mut().zip(PAIRS) {
            *m += d[i] * (v[j] - self.fit.mean[j]);
        }
    }

    /// The centred second moment of variables `i` and `j` (0 x, 1 s, 2 s², 3 F).
    fn moment(&self, i: usize, j: usize) -> f64 {
        let (i, j) = if i <= j { (i, j) } else { (j, i) };
        PAIRS
            .iter()
            .position(|&p| p == (i, j))
            .map_or(0.0, |k| self.fit.m2[k])
    }

    /// The fit, or None before it is determined (too few samples, or the penetration not
    /// moved apart from the surface's shape under the tangential motion).
    pub fn estimate(&self) -> Option<StiffnessEstimate> {
        let n_eff = if self.fit.weight_sq > 0.0 {
            self.fit.weight * self.fit.weight / self.fit.weight_sq
        } else {
            0.0
        };
        if n_eff < 8.0 {
            return None;
        }
        // Normal equations of F on the centred regressors [x, s, s²]: M θ = b.
        let m = Matrix3::from_fn(|i, j| self.moment(i, j));
        let b = Vector3::from_fn(|i, _| self.moment(i, 3));
        // Conditioning judged on the correlation form, free of the regressors' units.
        let scale = Vector3::from_fn(|i, _| m[(i, i)].sqrt());
        if scale.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return None;
        }
        let correlation = Matrix3::from_fn(|i, j| m[(i, j)] / (scale[i] * scale[j]));
        let det = correlation.determinant();
        if det.is_nan() || det <= 1e-9 {
            return None;
        }
        let inv = m.try_inverse()?;
        let theta = inv * b;
        // Residual sum of squares and the stiffness's variance σ² (M⁻¹)₀₀.
        let rss = (self.moment(3, 3) - theta.dot(&b)).max(0.0);
        let dof = (n_eff - 4.0).max(1.0);
        // The moments are weighted sums: scale to an equivalent n_eff unweighted samples.
        let to_samples = n_eff / self.fit.weight;
        let sigma2 = rss * to_samples / dof;
        let var_k = sigma2 * inv[(0, 0)] / to_samples;
        Some(StiffnessEstimate {
            stiffness_n_per_m: theta[0],
            std_error_n_per_m: var_k.max(0.0).sqrt(),
            samples: n_eff,
        })
    }
}

/// The fitted variables: x, s, s² and F.
const VARS: usize = 4;
/// The pairs of variables whose centred products the fit keeps, in `m2`'s order.
const PAIRS: [(usize, usize); 10] = [
    (0, 0),
    (0, 1),
    (0, 2),
    (0, 3),
    (1, 1),
    (1, 2),
    (1, 3),
    (2, 2),
    (2, 3),
    (3, 3),
];

#[cfg(test)]
mod tests {
    use super::*;

    /// A spring on a tilted surface, the tool moving along it and into it: the fit recovers
    /// the stiffness exactly (to rounding), whatever the tilt and the surface's place.
    #[test]
    fn exact_data_give_the_stiffness() {
        for k in [1e3, 1e4, 1e5, 1e6] {
            let mut e = StiffnessEstimator::new(StiffnessParams::default());
            let (x0, eps) = (0.4321, 0.03);
            let dt = 1e-3;
            for i in 0..2000 {
                let t = i as f64 * dt;
                // Travel at 20 mm/s with a 10-Hz dither of 1 mm along the tangent; the
                // penetration varies at 3 Hz about the preload's.
                let s = 0.02 * t + 1e-3 * (62.83 * t).sin();
                let pen = 2.5 / k * (1.0 + 0.3 * (18.85 * t).sin());
                let x = x0 + eps * s + pen;
                e.push(dt, x, s, k * pen);
            }
            let est = e.estimate().unwrap();
            assert!(
                (est.stiffness_n_per_m / k - 1.0).abs() < 1e-6,
                "{k}: {est:?}"
            );
            assert!(est.relative_error() < 1e-6, "{k}: {est:?}");
        }
    }

    /// With the sensor's noise on F_N the standard error is the spread of the estimate over
    /// noise draws (within 30 % over 200 draws), and the estimate is unbiased (mean within 3
    /// standard errors of the mean).
    #[test]
    fn the_standard_error_is_the_spread_over_noise_draws() {
        let k = 1e4;
        use rand_chacha::ChaCha8Rng;
        use rand_chacha::rand_core::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut noise = move || -> f64 { StandardNormal.sample(&mut rng) };
        let (mut ks, mut ses) = (Vec::new(), Vec::new());
        for _ in 0..200 {
            let mut e = StiffnessEstimator::new(StiffnessParams {
                memory_s: 0.2,
                ..StiffnessParams::default()
            });
            let dt = 1e-3;
            for i in 0..1000 {
                let t = i as f64 * dt;
                let s = 0.02 * t + 1e-3 * (62.83 * t).sin();
                let pen = 2.5 / k * (1.0 + 0.05 * (18.85 * t).sin());
                e.push(dt, 0.3 + 0.01 * s + pen, s, k * pen + 0.02 * noise());
            }
            let est = e.estimate().unwrap();
            ks.push(est.stiffness_n_per_m);
            ses.push(est.std_error_n_per_m);
        }
        let n = ks.len() as f64;
        let mean = ks.iter().sum::<f64>() / n;
        let spread = (ks.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let se = ses.iter().sum::<f64>() / n;
        assert!(
            (se / spread - 1.0).abs() < 0.3,
            "said {se}, spread {spread}"
        );
        assert!((mean - k).abs() < 3.0 * spread / n.sqrt(), "mean {mean}");
    }

    /// A curved surface under a dithered, travelling tool: the tangential regressors take the
    /// shape out, and the fit still reads the stiffness (a fit on x and s alone reads far less).
    #[test]
    fn a_curved_surface_does_not_pass_for_compliance() {
        let k = 1e4;
        let mut e = StiffnessEstimator::new(StiffnessParams::default());
        let dt = 1e-3;
        for i in 0..2000 {
            let t = i as f64 * dt;
            let s = 0.005 * t + 1e-3 * (62.83 * t).sin();
            // Fig. 5.6's sinusoid near its crest: curvature 8.2 /m, and a small penetration
            // ripple from the force loop.
            let surface = 0.01 * s - 0.5 * 8.2 * s * s;
            let pen = 2.5 / k * (1.0 + 0.02 * (18.85 * t).sin());
            e.push(dt, 0.3 + surface + pen, s, k * pen);
        }
        let est = e.estimate().unwrap();
        assert!((est.stiffness_n_per_m / k - 1.0).abs() < 1e-6, "{est:?}");
    }

    /// No penetration change (x moves only with s): no estimate; out of contact: no sample.
    #[test]
    fn without_excitation_or_contact_there_is_no_estimate() {
        let mut e = StiffnessEstimator::new(StiffnessParams::default());
        for i in 0..1000 {
            let s = i as f64 * 1e-5;
            e.push(1e-3, 0.3 + 0.02 * s, s, 2.5);
        }
        assert_eq!(e.estimate(), None);
        let mut e = StiffnessEstimator::new(StiffnessParams::default());
        for i in 0..1000 {
            let x = i as f64 * 1e-6;
            e.push(1e-3, x, 0.0, 0.1);
        }
        assert_eq!(e.estimate(), None);
    }
}
