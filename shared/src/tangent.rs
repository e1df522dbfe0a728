//! Surface tangent estimation by dither (thesis §5.3, §6.2): the estimator's side.
//!
//! The servo stops, holds the normal set-point and strokes the tool `s(t) = A sin φ` along
//! directions at δα_i from the estimated tangent (defaults 5° and 10°, ≤ 1 Hz), recording the
//! force and the tip position ([`ProbeSample`]). With α0 = θ̂ − θ (estimated minus true tangent
//! angle), a stroke along δα moves the tool out of the surface by `s sin(α0 + δα)`, so the
//! normal force varies as `F_N − F̄_N = −K sin(α0 + δα) sin φ` (K = contact stiffness × A).
//!
//! * The thesis measures the RMS of F_N − F̄_N (eq. 5.6), which loses the sign: eq. 5.8 holds
//!   only while (α0 + δα1)(α0 + δα2) > 0 and folds otherwise. afs demodulates F_N *in phase*
//!   with the stroke (lock-in), giving the signed `R = K sin(α0 + δα)/√2`: the in-phase part
//!   rejects friction (it follows the velocity, a quadrature term), the friction-suppression
//!   dither (another frequency) and averages the noise. The thesis's broadband RMS is computed
//!   too (with the noise variance subtracted) and reported beside it.
//! * Two probes on the same side → the exact form of eq. 5.8 / 6.1 (strokes normalised by the
//!   stroke actually measured). Opposite signs → the fold: the estimator asks for a re-probe on
//!   both sides with wider angles instead of answering. R1 ≈ R2 (both probes far from the
//!   tangent) → re-probe wider, as the thesis says. Three or more probes → the signed linear
//!   least squares `R_i = K cos α0 · sin δα_i + K sin α0 · cos δα_i`.
//! * The projection on the estimated normal mixes in the tangential force when the normal is
//!   off by α0; the statistics are recomputed on the corrected normal until α0 settles.
//! * A stroke that loses contact, or data too noisy to trust, is an error, never an angle.
//!
//! [`TangentRls`] is the recursive form (eq. 5.10) as recursive least squares with
//! forgetting, on absolute probe directions, for slowly varying slopes.
//!
//! Derivations in `docs/surface-tracking.md`.

use crate::error::ConfigError;
use crate::math::{Vec2, perp, unit};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// Most probes one estimate can use.
pub const MAX_PROBES: usize = 6;

/// Settings of the tangent estimator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TangentParams {
    /// First probe angles δα1, δα2 off the estimated tangent (deg); thesis 5° and 10°.
    pub probe_angles_deg: [f64; 2],
    /// Re-probe angles, used on both sides (deg).
    pub reprobe_angles_deg: [f64; 2],
    /// Stroke amplitude A (m).
    pub amplitude_m: f64,
    /// Stroke frequency (Hz), ≤ 1 Hz (thesis §4.5.1).
    pub frequency_hz: f64,
    /// Whole stroke periods measured per probe.
    pub periods: usize,
    /// Ramp in and out of each probe (s).
    pub ramp_s: f64,
    /// Hold before probing, to settle and measure the noise (s).
    pub settle_s: f64,
    /// A sign is trusted when |in-phase amplitude| exceeds this many standard errors.
    pub sign_threshold: f64,
    /// R1 ≈ R2: re-probe when |R1/A1 − R2/A2| is below this many standard errors.
    pub equal_threshold: f64,
    /// Largest standard error of α0 accepted (deg).
    pub max_std_error_deg: f64,
    /// Contact counts as lost when the normal force falls below this fraction of the hold mean.
    pub contact_loss_fraction: f64,
    /// Configured sensor noise standard deviation (N), used when the hold gives no estimate.
    pub noise_std_n: f64,
}

impl Default for TangentParams {
    fn default() -> Self {
        Self {
            probe_angles_deg: [5.0, 10.0],
            reprobe_angles_deg: [8.0, 16.0],
            amplitude_m: 1e-3,
            frequency_hz: 1.0,
            periods: 2,
            ramp_s: 1.0,
            settle_s: 0.3,
            sign_threshold: 4.0,
            equal_threshold: 3.0,
            max_std_error_deg: 0.5,
            contact_loss_fraction: 0.1,
            noise_std_n: 0.02,
        }
    }
}

impl TangentParams {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (n, v) in [
            ("probe_angles_deg[0]", self.probe_angles_deg[0]),
            ("probe_angles_deg[1]", self.probe_angles_deg[1]),
            ("reprobe_angles_deg[0]", self.reprobe_angles_deg[0]),
            ("reprobe_angles_deg[1]", self.reprobe_angles_deg[1]),
        ] {
            if !(v.is_finite() && v.abs() < 60.0) {
                return Err(ConfigError::setting(
                    format!("tangent.{n}"),
                    v,
                    "must lie in (−60, 60) degrees",
                ));
            }
        }
        if self.probe_angles_deg[0] == self.probe_angles_deg[1] {
            return Err(ConfigError::rule(
                "tangent.probe_angles_deg",
                "must be two different angles",
            ));
        }
        if !(self.amplitude_m.is_finite() && self.amplitude_m > 0.0 && self.amplitude_m < 0.02) {
            return Err(ConfigError::setting(
                "tangent.amplitude_m",
                self.amplitude_m,
                "must lie in (0, 0.02)",
            ));
        }
        if !(self.frequency_hz.is_finite() && self.frequency_hz > 0.0 && self.frequency_hz <= 5.0) {
            return Err(ConfigError::setting(
                "tangent.frequency_hz",
                self.frequency_hz,
                "must lie in (0, 5]",
            ));
        }
        if self.periods == 0 || self.periods > 20 {
            return Err(ConfigError::setting(
                "tangent.periods",
                self.periods as f64,
                "must lie in 1..=20",
            ));
        }
        for (n, v) in [
            ("ramp_s", self.ramp_s),
            ("settle_s", self.settle_s),
            ("sign_threshold", self.sign_threshold),
            ("equal_threshold", self.equal_threshold),
            ("max_std_error_deg", self.max_std_error_deg),
            ("noise_std_n", self.noise_std_n),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ConfigError::setting(
                    format!("tangent.{n}"),
                    v,
                    "must be ≥ 0",
                ));
            }
        }
        if !(0.0..1.0).contains(&self.contact_loss_fraction) {
            return Err(ConfigError::setting(
                "tangent.contact_loss_fraction",
                self.contact_loss_fraction,
                "must lie in [0, 1)",
            ));
        }
        Ok(())
    }

    /// The first probe set (rad).
    pub fn first_plan(&self) -> ProbePlan {
        ProbePlan::new(
            &[
                self.probe_angles_deg[0].to_radians(),
                self.probe_angles_deg[1].to_radians(),
            ],
            self,
        )
    }

    /// The re-probe set: both sides, wider angles (rad).
    pub fn reprobe_plan(&self) -> ProbePlan {
        let [a, b] = self.reprobe_angles_deg.map(f64::to_radians);
        ProbePlan::new(&[-b, -a, a, b], self)
    }

    /// Largest stroke amplitude that keeps contact (m): the normal-force swing
    /// `k · A · sin(largest angle + uncertainty)` must stay below `margin` × preload, with k the
    /// stiffness the force controller uses (contact in series with the servo).
    pub fn amplitude_bound(
        &self,
        preload_n: f64,
        stiffness_n_per_m: f64,
        uncertainty_rad: f64,
        margin: f64,
    ) -> f64 {
        let widest = self
            .probe_angles_deg
            .iter()
            .chain(&self.reprobe_angles_deg)
            .fold(0.0f64, |m, a| m.max(a.abs()));
        let s = (widest.to_radians() + uncertainty_rad).sin().max(1e-6);
        margin * preload_n / (stiffness_n_per_m * s)
    }
}

/// The probes the servo is to run: offsets from the estimated tangent and stroke settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ProbePlan {
    /// Offsets δα_i (rad); only the first `count` are used.
    pub offsets: [f64; MAX_PROBES],
    /// Number of probes.
    pub count: usize,
    /// Stroke amplitude (m).
    pub amplitude_m: f64,
    /// Stroke frequency (Hz).
    pub frequency_hz: f64,
    /// Measured periods per probe.
    pub periods: usize,
    /// Ramp in/out (s).
    pub ramp_s: f64,
    /// Hold before the first probe (s).
    pub settle_s: f64,
    /// Frequency of the friction-suppression dither running during the strokes (Hz), 0 if
    /// none: the estimator averages the force over one of its periods to remove it.
    pub dither_hz: f64,
}

impl ProbePlan {
    /// A plan for the given offsets (rad), at most [`MAX_PROBES`].
    pub fn new(offsets: &[f64], p: &TangentParams) -> Self {
        let mut o = [0.0; MAX_PROBES];
        let count = offsets.len().min(MAX_PROBES);
        o[..count].copy_from_slice(&offsets[..count]);
        Self {
            offsets: o,
            count,
            amplitude_m: p.amplitude_m,
            frequency_hz: p.frequency_hz,
            periods: p.periods,
            ramp_s: p.ramp_s,
            settle_s: p.settle_s,
            dither_hz: 0.0,
        }
    }

    /// Duration of one probe (s).
    pub fn probe_duration(&self) -> f64 {
        2.0 * self.ramp_s + self.periods as f64 / self.frequency_hz
    }

    /// Duration of the whole plan (s).
    pub fn duration(&self) -> f64 {
        self.settle_s + self.count as f64 * self.probe_duration()
    }
}

/// Marks a hold sample (before the first probe) in [`ProbeSample::probe`].
pub const HOLD: u8 = u8::MAX;

wire_message! {
    version = 1;
    /// One recorded sample of a probe run (also the payload element of a tangent request).
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, ZeroCopySend)]
    #[type_name("afs::ProbeSample")]
    pub struct ProbeSample {
        /// Time (s).
        pub t: f64,
        /// Measured force on the tool, world frame (N).
        pub force: [f64; 2],
        /// Tip position from the encoders, world frame (m).
        pub tip: [f64; 2],
        /// Stroke phase φ (rad): the commanded displacement is A sin φ.
        pub phase: f64,
        /// Probe index, or [`HOLD`].
        pub probe: u8,
        /// True during the measured whole periods (false in ramps).
        pub measured: bool,
    }
}

/// Statistics of one probe on a given normal direction.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct ProbeStats {
    /// Offset δα (rad).
    pub offset_rad: f64,
    /// Signed in-phase RMS `R = −I/√2` of the normal force at the stroke frequency (N): positive
    /// when stroking along +d pulls the tool out of the surface.
    pub r_signed_n: f64,
    /// Standard error of `r_signed_n` (N).
    pub r_std_n: f64,
    /// Quadrature RMS (N): friction and lag.
    pub quadrature_n: f64,
    /// Thesis eq. 5.6: the RMS of F_N − F̄_N over whole periods at the stroke frequency,
    /// in-phase and quadrature together and unsigned, with noise, drift and harmonics removed:
    /// `√((a² + b²)/2 − 2σ_R²)` for the fitted `a sin φ + b cos φ`, σ_R the measured standard
    /// error of `r_signed_n` (N).
    pub rms_n: f64,
    /// Stroke amplitude actually travelled along the probe direction (m, fundamental).
    pub stroke_m: f64,
    /// Largest excursion on the + side and on the − side of the mean (m): the asymmetric
    /// stroke of eq. 6.1.
    pub stroke_sides_m: [f64; 2],
    /// In-phase amplitude of the measured tip displacement along the estimated tangent t̂ and
    /// outward normal n̂ the probes refer to (m), processed like the force.
    pub displacement_m: [f64; 2],
    /// In-phase amplitude of the normal force, unscaled: `−√2 · r_signed_n` (N).
    pub force_in_phase_n: f64,
    /// Mean and minimum normal force (N).
    pub normal_mean_n: f64,
    /// Minimum normal force (N).
    pub normal_min_n: f64,
    /// Samples used.
    pub samples: usize,
}

/// Off-harmonic frequencies (multiples of f/P that are not multiples of f) used to measure the
/// lock-in's noise: over a window of P whole periods they are orthogonal to the stroke, its
/// harmonics and the friction-suppression dither (an integer multiple of f), so what they pick
/// up in the residual is noise near the probe frequency.
const NOISE_BINS: usize = 8;

/// Averages the force over one period of the friction-suppression dither (centred moving
/// average): notches the dither and all its harmonics, scales the stroke frequency's response
/// by the same factor for every probe. Samples without a full window at the ends are dropped.
fn comb(raw: &[(f64, f64, f64)], dither_hz: f64) -> Vec<(f64, f64, f64)> {
    if dither_hz <= 0.0 || raw.len() < 3 {
        return raw.to_vec();
    }
    let dt = (raw[raw.len() - 1].0 - raw[0].0) / (raw.len() - 1) as f64;
    let w = ((1.0 / dither_hz) / dt).round() as usize;
    if w < 2 || w >= raw.len() {
        return raw.to_vec();
    }
    let mut out = Vec::with_capacity(raw.len() - w);
    let mut acc: f64 = raw[..w].iter().map(|r| r.2).sum();
    for k in 0..raw.len() - w {
        let mid = raw[k + w / 2];
        out.push((mid.0, mid.1, acc / w as f64));
        acc += raw[k + w].2 - raw[k].2;
    }
    out
}

/// The in-phase amplitude `a` of `f ≈ trend + a sin φ + b cos φ` over whole periods of φ, after
/// removing a dither at `dither_hz` (0: none) — the lock-in the probes use, for other callers.
pub(crate) fn in_phase_amplitude(samples: &[(f64, f64, f64)], dither_hz: f64) -> Option<f64> {
    fit_with_trend(&comb(samples, dither_hz)).map(|(c, _)| c[3])
}

/// Joint least squares of `f(τ) = c0 + c1 τ + c2 τ² + a sin φ + b cos φ` over the samples:
/// the stroke's in-phase and quadrature amplitudes (a, b) free of a slow drift of the
/// force (the joint integrators settle for about a second after each ramp-in).
fn fit_with_trend(samples: &[(f64, f64, f64)]) -> Option<([f64; 5], f64)> {
    use nalgebra::{SMatrix, SVector};
    let (t0, t1) = samples
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), s| {
            (a.min(s.0), b.max(s.0))
        });
    let span = (t1 - t0).max(1e-12);
    let mut ata = SMatrix::<f64, 5, 5>::zeros();
    let mut atb = SVector::<f64, 5>::zeros();
    let basis = |t: f64, ph: f64| -> SVector<f64, 5> {
        let x = 2.0 * (t - t0) / span - 1.0;
        let (sn, cs) = ph.sin_cos();
        SVector::<f64, 5>::new(1.0, x, x * x, sn, cs)
    };
    for &(t, ph, f) in samples {
        let b = basis(t, ph);
        ata += b * b.transpose();
        atb += b * f;
    }
    let c = ata.cholesky()?.solve(&atb);
    let sse: f64 = samples
        .iter()
        .map(|&(t, ph, f)| (f - basis(t, ph).dot(&c)).powi(2))
        .sum();
    Some(([c[0], c[1], c[2], c[3], c[4]], sse / samples.len() as f64))
}

/// Computes a probe's statistics with the force projected on `normal` (outward unit).
/// `periods` is the number of whole stroke periods in the measured window.
#[allow(clippy::too_many_arguments)]
pub fn probe_stats(
    samples: &[ProbeSample],
    probe: u8,
    offset: f64,
    base_angle: f64,
    normal: Vec2,
    periods: usize,
    dither_hz: f64,
) -> ProbeStats {
    let dir = unit(base_angle + offset);
    let p = periods.max(1) as f64;
    let chosen = || samples.iter().filter(|s| s.probe == probe && s.measured);
    let raw: Vec<(f64, f64, f64)> = chosen()
        .map(|s| (s.t, s.phase, Vec2::new(s.force[0], s.force[1]).dot(&normal)))
        .collect();
    let data = comb(&raw, dither_hz);
    let n = data.len() as f64;
    if data.len() < 8 {
        return ProbeStats {
            offset_rad: offset,
            samples: data.len(),
            ..Default::default()
        };
    }
    let Some((c, _)) = fit_with_trend(&data) else {
        return ProbeStats {
            offset_rad: offset,
            samples: data.len(),
            ..Default::default()
        };
    };
    // Noise: off-harmonic lock-ins of the residual.
    let (t0, t1) = data
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), s| {
            (a.min(s.0), b.max(s.0))
        });
    let span = (t1 - t0).max(1e-12);
    let mut bins = [0.0f64; NOISE_BINS];
    let mut j = periods.max(1) + 1;
    for b in bins.iter_mut() {
        if j.is_multiple_of(periods.max(1)) {
            j += 1;
        }
        *b = j as f64 / p;
        j += 1;
    }
    let mut noise_acc = [[0.0f64; 2]; NOISE_BINS];
    let (mut sf, mut fmin) = (0.0, f64::INFINITY);
    for &(t, ph, f) in &data {
        let x = 2.0 * (t - t0) / span - 1.0;
        let (sn, cs) = ph.sin_cos();
        let resid = f - (c[0] + c[1] * x + c[2] * x * x + c[3] * sn + c[4] * cs);
        for (acc, k) in noise_acc.iter_mut().zip(bins) {
            let (bs, bc) = (ph * k).sin_cos();
            acc[0] += resid * bs;
            acc[1] += resid * bc;
        }
        sf += f;
        fmin = fmin.min(f);
    }
    // Each bin gives two estimates of the variance of a lock-in amplitude.
    let var_i = noise_acc
        .iter()
        .map(|a| (2.0 * a[0] / n).powi(2) + (2.0 * a[1] / n).powi(2))
        .sum::<f64>()
        / (2.0 * NOISE_BINS as f64);
    let mean = sf / n;
    // Stroke actually travelled along the probe direction: fundamental of the tip displacement.
    let (mut ds, mut dss, mut dsc) = (0.0, 0.0, 0.0);
    for s in chosen() {
        let d = Vec2::new(s.tip[0], s.tip[1]).dot(&dir);
        let (sn, cs) = s.phase.sin_cos();
        ds += d;
        dss += d * sn;
        dsc += d * cs;
    }
    let mean_d = ds / n;
    let stroke = 2.0 * ((dss / n).powi(2) + (dsc / n).powi(2)).sqrt();
    // In-phase displacement along t̂ and n̂ with the same comb and trend fit as the force, so
    // the regression compares like with like.
    let (t_hat, n_hat) = (unit(base_angle), perp(unit(base_angle)));
    let along = |axis: Vec2| -> f64 {
        let raw: Vec<(f64, f64, f64)> = chosen()
            .map(|s| (s.t, s.phase, Vec2::new(s.tip[0], s.tip[1]).dot(&axis)))
            .collect();
        fit_with_trend(&comb(&raw, dither_hz)).map_or(0.0, |(c, _)| c[3])
    };
    let displacement = [along(t_hat), along(n_hat)];
    let (mut hi, mut lo) = (f64::NEG_INFINITY, f64::INFINITY);
    for s in chosen() {
        let d = Vec2::new(s.tip[0], s.tip[1]).dot(&dir) - mean_d;
        hi = hi.max(d);
        lo = lo.min(d);
    }
    ProbeStats {
        offset_rad: offset,
        r_signed_n: -c[3] / 2f64.sqrt(),
        r_std_n: (var_i / 2.0).sqrt(),
        quadrature_n: c[4].abs() / 2f64.sqrt(),
        // E[(a² + b²)/2] = true + (var a + var b)/2 = true + 2 var R: remove the noise.
        rms_n: ((c[3] * c[3] + c[4] * c[4]) / 2.0 - var_i).max(0.0).sqrt(),
        stroke_m: stroke,
        stroke_sides_m: [hi, -lo],
        displacement_m: displacement,
        force_in_phase_n: c[3],
        normal_mean_n: mean,
        normal_min_n: fmin,
        samples: data.len(),
    }
}

/// Eq. 5.8 as printed (small angles): `α0 = (R1 δα2 − R2 δα1)/(R2 − R1)`, valid while
/// (α0 + δα1)(α0 + δα2) > 0. `None` when R1 = R2.
pub fn eq_5_8(r1: f64, r2: f64, d1: f64, d2: f64) -> Option<f64> {
    let den = r2 - r1;
    (den != 0.0).then(|| (r1 * d2 - r2 * d1) / den)
}

/// Eq. 5.9 (small angles, δα1 = −δα2 = δα, |α0| < δα): `α0 = δα (R1 − R2)/(R1 + R2)`.
pub fn eq_5_9(r1: f64, r2: f64, d: f64) -> Option<f64> {
    let den = r1 + r2;
    (den != 0.0).then(|| d * (r1 - r2) / den)
}

/// Eq. 6.1 (asymmetric strokes A1 ≠ A2): `α0 = (R1 A2 δα2 − R2 A1 δα1)/(R2 A1 − R1 A2)`.
pub fn eq_6_1(r1: f64, r2: f64, a1: f64, a2: f64, d1: f64, d2: f64) -> Option<f64> {
    let den = r2 * a1 - r1 * a2;
    (den != 0.0).then(|| (r1 * a2 * d2 - r2 * a1 * d1) / den)
}

/// Exact same-side form of eq. 5.8/6.1: from `ρ_i = R_i/A_i = K' sin(α0 + δα_i)` (same sign),
/// `tan α0 = (ρ2 sin δα1 − ρ1 sin δα2)/(ρ1 cos δα2 − ρ2 cos δα1)`.
pub fn alpha0_exact(rho1: f64, rho2: f64, d1: f64, d2: f64) -> Option<f64> {
    let num = rho2 * d1.sin() - rho1 * d2.sin();
    let den = rho1 * d2.cos() - rho2 * d1.cos();
    if den == 0.0 && num == 0.0 {
        return None;
    }
    // α0 within ±90°: the branch with K' of the same sign as ρ.
    let a = (num / den).atan();
    Some(a)
}

/// Signed least squares over any number of probes: `ρ_i = u sin δα_i + w cos δα_i` with
/// `u = K' cos α0`, `w = K' sin α0`. Returns (α0, K', residual RMS, standard error of α0).
pub fn alpha0_least_squares(
    rho: &[f64],
    offsets: &[f64],
    rho_std: &[f64],
) -> Option<(f64, f64, f64, f64)> {
    let n = rho.len().min(offsets.len());
    if n < 2 {
        return None;
    }
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for k in 0..n {
        let (s, c) = offsets[k].sin_cos();
        a11 += s * s;
        a12 += s * c;
        a22 += c * c;
        b1 += s * rho[k];
        b2 += c * rho[k];
    }
    let det = a11 * a22 - a12 * a12;
    if det.abs() < 1e-12 {
        return None;
    }
    let u = (a22 * b1 - a12 * b2) / det;
    let w = (a11 * b2 - a12 * b1) / det;
    let k = (u * u + w * w).sqrt();
    let alpha = if u >= 0.0 {
        (w / u).atan()
    } else {
        (w / u).atan() + std::f64::consts::PI.copysign(w)
    };
    let sse: f64 = (0..n)
        .map(|j| {
            let (s, c) = offsets[j].sin_cos();
            (rho[j] - u * s - w * c).powi(2)
        })
        .sum();
    let resid = (sse / n as f64).sqrt();
    // Standard error of α0: propagate the measurement errors through (u, w) → atan(w/u).
    let sigma = rho_std.iter().take(n).map(|s| s * s).sum::<f64>() / n as f64;
    let (ci11, ci12, ci22) = (a22 / det, -a12 / det, a11 / det);
    let (gu, gw) = (-w / (k * k), u / (k * k));
    let var_a = sigma * (gu * gu * ci11 + 2.0 * gu * gw * ci12 + gw * gw * ci22);
    Some((alpha, k, resid, var_a.max(0.0).sqrt()))
}

/// Which rule produced an estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TangentMethod {
    /// Regression of the in-phase normal force on the measured tip motion (see [`estimate`]).
    MotionRegression,
    /// Ratio of the responses to the commanded strokes (exact eq. 5.8, or least squares over
    /// more probes); used when the tip motion is not recorded.
    CommandedRatio,
}

/// Why the estimator wants another probe set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ReprobeReason {
    /// The true tangent lies between the probes: the RMS form (eq. 5.8) would fold.
    Fold,
    /// R1 ≈ R2: both probes far from the tangent, α0 ill-conditioned.
    EqualResponses,
    /// No probe's sign is significant and the hypotheses disagree.
    Ambiguous,
}

/// Why an estimate cannot be trusted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, thiserror::Error)]
#[serde(rename_all = "snake_case", tag = "error")]
pub enum TangentError {
    /// The normal force dropped below the contact-loss limit during a stroke.
    #[error(
        "contact lost during probe {probe}: normal force fell to {min_n:.3} N; reduce the stroke amplitude or raise the preload"
    )]
    ContactLost {
        /// Probe index.
        probe: usize,
        /// Smallest normal force (N).
        min_n: f64,
    },
    /// Too few samples for a probe.
    #[error("probe {probe} has {samples} samples; the record is incomplete")]
    MissingData {
        /// Probe index.
        probe: usize,
        /// Samples found.
        samples: usize,
    },
    /// The response is buried in noise.
    #[error(
        "the force response ({signal_n:.4} N) is below the noise ({noise_n:.4} N); use a larger stroke or more periods"
    )]
    TooNoisy {
        /// Largest |R| (N).
        signal_n: f64,
        /// Its standard error (N).
        noise_n: f64,
    },
    /// The estimate's uncertainty exceeds the limit.
    #[error("the estimate's standard error {std_error_deg:.3}° exceeds {limit_deg:.3}°")]
    Uncertain {
        /// Standard error (deg).
        std_error_deg: f64,
        /// Limit (deg).
        limit_deg: f64,
    },
    /// Re-probing did not resolve the ambiguity.
    #[error("re-probing did not resolve the tangent ({0:?})")]
    Unresolved(ReprobeReason),
}

/// An accepted estimate with its quality.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TangentEstimate {
    /// α0 = estimated − true tangent angle (rad).
    pub alpha0_rad: f64,
    /// Corrected tangent angle θ̂ − α0 (rad, world).
    pub tangent_angle_rad: f64,
    /// Rule used.
    pub method: TangentMethod,
    /// Standard error of α0 (rad).
    pub std_error_rad: f64,
    /// Residual RMS of the probe model (N).
    pub residual_n: f64,
    /// Noise level of the in-phase responses (N).
    pub noise_n: f64,
    /// Signal-to-noise ratio: largest |R| over its standard error.
    pub snr: f64,
    /// The thesis's eq. 5.8 on broadband RMS (first two probes), for comparison (rad).
    pub thesis_alpha0_rad: Option<f64>,
    /// Eq. 6.1 on broadband RMS with the measured strokes (first two probes) (rad).
    pub thesis_6_1_alpha0_rad: Option<f64>,
    /// The signed commanded-stroke ratio (exact eq. 5.8 / least squares) (rad).
    pub ratio_alpha0_rad: Option<f64>,
    /// Effective contact stiffness the regression found (N/m).
    pub stiffness_n_per_m: f64,
    /// Probes used.
    pub probes: usize,
    /// Re-projection iterations for the friction leakage.
    pub iterations: usize,
}

/// What the estimator answers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "outcome")]
pub enum TangentOutcome {
    /// A trusted estimate.
    Estimate(TangentEstimate),
    /// Run this plan and call again with all probes.
    Reprobe {
        /// Why.
        reason: ReprobeReason,
        /// The plan to run.
        plan: ProbePlan,
    },
    /// No trustworthy estimate.
    Failed(TangentError),
}

/// Estimates α0 from a probe record. `base_angle` is the estimated tangent angle θ̂ (rad) the
/// offsets are relative to; `plan` lists the probes in `samples`; `reprobed` is true when this
/// record already contains a re-probe set.
///
/// The answer is the regression of each probe's in-phase normal force on its in-phase measured
/// tip displacement (x along t̂, y along n̂): the force follows the penetration,
/// `f = −k (x sin α0 + y cos α0)`, linear in (k sin α0, k cos α0). Using the measured motion
/// (thesis §6.2.2: "relies only on the measured force values and the motion of the robot")
/// removes the servo's compliance from the problem, and the tangential travel times the contact
/// stiffness makes α0 far better determined than the ratio of two small force responses.
/// Before answering, the signed responses decide whether the thesis's form would fold (probes
/// on both sides of the tangent) or be ill-conditioned (R1 ≈ R2): then the estimator asks for
/// a re-probe on both sides with wider angles.
pub fn estimate(
    samples: &[ProbeSample],
    plan: &ProbePlan,
    base_angle: f64,
    params: &TangentParams,
    reprobed: bool,
) -> TangentOutcome {
    let count = plan.count.min(MAX_PROBES);
    if count < 2 {
        return TangentOutcome::Failed(TangentError::MissingData {
            probe: count,
            samples: 0,
        });
    }
    let n_hat = perp(unit(base_angle));
    // The preload during the hold before probing: the reference for contact loss.
    let (hold_sum, hold_count) = samples
        .iter()
        .filter(|s| s.probe == HOLD)
        .fold((0.0, 0usize), |(a, n), s| {
            (a + Vec2::new(s.force[0], s.force[1]).dot(&n_hat), n + 1)
        });
    let hold_mean = if hold_count == 0 {
        f64::NAN
    } else {
        hold_sum / hold_count as f64
    };
    let offsets = &plan.offsets[..count];
    let mut alpha = 0.0;
    let mut stats = [ProbeStats::default(); MAX_PROBES];
    let mut iterations = 0;
    let mut fit = None;
    // The force is projected on the current normal estimate; re-project until α0 settles
    // (removes the tangential force leaking into the projection when n̂ is off by α0).
    for it in 0..4 {
        iterations = it + 1;
        let normal = perp(unit(base_angle - alpha));
        for k in 0..count {
            stats[k] = probe_stats(
                samples,
                k as u8,
                offsets[k],
                base_angle,
                normal,
                plan.periods,
                plan.dither_hz,
            );
        }
        if it == 0 {
            for (k, s) in stats.iter().enumerate().take(count) {
                if s.samples < 8 {
                    return TangentOutcome::Failed(TangentError::MissingData {
                        probe: k,
                        samples: s.samples,
                    });
                }
                let reference = if hold_mean.is_finite() {
                    hold_mean
                } else {
                    s.normal_mean_n
                };
                if s.normal_min_n < params.contact_loss_fraction * reference {
                    return TangentOutcome::Failed(TangentError::ContactLost {
                        probe: k,
                        min_n: s.normal_min_n,
                    });
                }
            }
            let (sig, noise) = stats
                .iter()
                .take(count)
                .fold((0.0f64, 0.0f64), |(a, b), s| {
                    (a.max(s.r_signed_n.abs()), b.max(s.r_std_n))
                });
            if sig < 3.0 * noise {
                return TangentOutcome::Failed(TangentError::TooNoisy {
                    signal_n: sig,
                    noise_n: noise,
                });
            }
        }
        let Some(step) = regress(&stats[..count]) else {
            return TangentOutcome::Failed(TangentError::Unresolved(ReprobeReason::Ambiguous));
        };
        let converged = (step.0 - alpha).abs() < 1e-7;
        alpha = step.0;
        fit = Some(step);
        if converged {
            break;
        }
    }
    let Some((alpha, stiffness, resid, se)) = fit else {
        return TangentOutcome::Failed(TangentError::Unresolved(ReprobeReason::Ambiguous));
    };
    // The thesis's two-probe form: would it fold, or is it ill-conditioned? Judged on the
    // corrected normal: on the uncorrected one the tangential (friction) force leaking into
    // the projection can flip a small response's sign.
    if count == 2 {
        let sig_k = |k: usize| stats[k].r_signed_n.abs() > params.sign_threshold * stats[k].r_std_n;
        let (r1, r2) = (stats[0].r_signed_n, stats[1].r_signed_n);
        if sig_k(0) && sig_k(1) && r1.signum() != r2.signum() {
            return reprobe_or_fail(ReprobeReason::Fold, params, reprobed);
        }
        let diff_std = (stats[0].r_std_n.powi(2) + stats[1].r_std_n.powi(2)).sqrt();
        if sig_k(0) && sig_k(1) && (r1 - r2).abs() < params.equal_threshold * diff_std {
            return reprobe_or_fail(ReprobeReason::EqualResponses, params, reprobed);
        }
    }
    let limit = params.max_std_error_deg.to_radians();
    if se > limit || !alpha.is_finite() {
        return TangentOutcome::Failed(TangentError::Uncertain {
            std_error_deg: se.to_degrees(),
            limit_deg: params.max_std_error_deg,
        });
    }
    let (sig, noise) = stats
        .iter()
        .take(count)
        .fold((0.0f64, 0.0f64), |(a, b), s| {
            (a.max(s.r_signed_n.abs()), b.max(s.r_std_n))
        });
    // Cross-checks: the thesis's forms and the commanded-stroke ratio.
    let thesis = eq_5_8(stats[0].rms_n, stats[1].rms_n, offsets[0], offsets[1]);
    let sides = |s: &ProbeStats| 0.5 * (s.stroke_sides_m[0] + s.stroke_sides_m[1]);
    let thesis_61 = eq_6_1(
        stats[0].rms_n,
        stats[1].rms_n,
        sides(&stats[0]),
        sides(&stats[1]),
        offsets[0],
        offsets[1],
    );
    let rho: Vec<f64> = stats.iter().take(count).map(|s| s.r_signed_n).collect();
    let rho_std: Vec<f64> = stats.iter().take(count).map(|s| s.r_std_n).collect();
    let ratio = if count == 2 {
        alpha0_exact(rho[0], rho[1], offsets[0], offsets[1])
    } else {
        alpha0_least_squares(&rho, offsets, &rho_std).map(|r| r.0)
    };
    TangentOutcome::Estimate(TangentEstimate {
        alpha0_rad: alpha,
        tangent_angle_rad: base_angle - alpha,
        method: TangentMethod::MotionRegression,
        std_error_rad: se,
        residual_n: resid,
        noise_n: noise,
        snr: if noise > 0.0 {
            sig / noise
        } else {
            f64::INFINITY
        },
        thesis_alpha0_rad: thesis,
        thesis_6_1_alpha0_rad: thesis_61,
        ratio_alpha0_rad: ratio,
        stiffness_n_per_m: stiffness,
        probes: count,
        iterations,
    })
}

/// Least squares of `f_i = −(u x_i + w y_i)` over the probes (in-phase force on in-phase
/// displacement along t̂, n̂): α0 = atan2(u, w), k = |(u, w)|. Returns (α0, k, residual RMS,
/// standard error of α0).
fn regress(stats: &[ProbeStats]) -> Option<(f64, f64, f64, f64)> {
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for s in stats {
        let (x, y, f) = (
            s.displacement_m[0],
            s.displacement_m[1],
            -s.force_in_phase_n,
        );
        a11 += x * x;
        a12 += x * y;
        a22 += y * y;
        b1 += x * f;
        b2 += y * f;
    }
    let det = a11 * a22 - a12 * a12;
    if det.is_nan() || det.abs() <= 1e-30 {
        return None;
    }
    let u = (a22 * b1 - a12 * b2) / det;
    let w = (a11 * b2 - a12 * b1) / det;
    if w.is_nan() || w <= 0.0 {
        return None;
    }
    let k = (u * u + w * w).sqrt();
    let alpha = u.atan2(w);
    let n = stats.len() as f64;
    let sse: f64 = stats
        .iter()
        .map(|s| (-s.force_in_phase_n - u * s.displacement_m[0] - w * s.displacement_m[1]).powi(2))
        .sum();
    // Error of an in-phase amplitude: √2 × the standard error of R.
    let sigma2 = stats
        .iter()
        .map(|s| 2.0 * s.r_std_n * s.r_std_n)
        .sum::<f64>()
        / n;
    let (ci11, ci12, ci22) = (a22 / det, -a12 / det, a11 / det);
    let (gu, gw) = (w / (k * k), -u / (k * k));
    let var_a = sigma2 * (gu * gu * ci11 + 2.0 * gu * gw * ci12 + gw * gw * ci22);
    Some((alpha, k, (sse / n).sqrt(), var_a.max(0.0).sqrt()))
}

fn reprobe_or_fail(
    reason: ReprobeReason,
    params: &TangentParams,
    reprobed: bool,
) -> TangentOutcome {
    if reprobed {
        TangentOutcome::Failed(TangentError::Unresolved(reason))
    } else {
        TangentOutcome::Reprobe {
            reason,
            plan: params.reprobe_plan(),
        }
    }
}

/// Eq. 5.10's recursive form, as recursive least squares with forgetting on the same model as
/// [`estimate`]: each probe's in-phase normal force f and in-phase tip displacement Δp (world)
/// satisfy `f = −k n·Δp`, linear in the vector `k n` (world frame). The filter tracks `k n`,
/// the tangent is perpendicular to it, and old probes fade with factor λ, so a slowly turning
/// surface is followed without knowing k (stiffness) or any fixed frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TangentRls {
    theta: [f64; 2],
    p: [[f64; 2]; 2],
    p_max: f64,
    forgetting: f64,
    /// Random walk of the tangent angle per update (rad) over the force noise (N), for the
    /// drift form; 0 for exponential forgetting only.
    drift: f64,
    updates: usize,
}

impl TangentRls {
    /// A filter with forgetting factor `forgetting` ∈ [0.5, 1] and initial covariance `p0`,
    /// starting from the normal of `tangent_angle` with stiffness guess `k0` (N/m).
    pub fn new(forgetting: f64, p0: f64, tangent_angle: f64, k0: f64) -> Self {
        let n = perp(unit(tangent_angle)) * k0;
        Self {
            theta: [n.x, n.y],
            p: [[p0, 0.0], [0.0, p0]],
            p_max: 2.0 * p0,
            forgetting: forgetting.clamp(0.5, 1.0),
            drift: 0.0,
            updates: 0,
        }
    }

    /// The drift form: no exponential forgetting; instead, before each update the angle of
    /// `k n` may have moved by a random walk of `angle_drift_rad` (standard deviation per
    /// update), against force noise `force_noise_n` (standard deviation of an in-phase force).
    /// This is a Kalman filter whose process noise lies only along the angle (`q = (k σ_a/σ_f)²`
    /// on the direction perpendicular to `k n`), so the stiffness k keeps its whole history while
    /// the angle follows a turning surface. Exponential forgetting fades k as well, and because
    /// the probes excite the normal direction only weakly (the measured normal motion is a few
    /// percent of the stroke), a forgotten k drags the angle (docs/surface-tracking.md §5).
    pub fn with_drift(
        p0: f64,
        tangent_angle: f64,
        k0: f64,
        angle_drift_rad: f64,
        force_noise_n: f64,
    ) -> Self {
        let mut f = Self::new(1.0, p0, tangent_angle, k0);
        if angle_drift_rad.is_finite() && force_noise_n.is_finite() && force_noise_n > 0.0 {
            f.drift = angle_drift_rad.abs() / force_noise_n;
        }
        f
    }

    /// Adds one probe: in-phase tip displacement (world, m) and in-phase normal force (N).
    pub fn update(&mut self, displacement: Vec2, force_in_phase: f64) {
        if !(displacement.x.is_finite() && displacement.y.is_finite() && force_in_phase.is_finite())
        {
            return;
        }
        if self.drift > 0.0 {
            // Process noise along the angle: the direction perpendicular to k n.
            let k = self.theta[0].hypot(self.theta[1]);
            if k > 0.0 {
                let u = [-self.theta[1] / k, self.theta[0] / k];
                let q = (k * self.drift).powi(2);
                for i in 0..2 {
                    for j in 0..2 {
                        self.p[i][j] += q * u[i] * u[j];
                    }
                }
            }
        }
        let phi = [-displacement.x, -displacement.y];
        let p = self.p;
        let pphi = [
            p[0][0] * phi[0] + p[0][1] * phi[1],
            p[1][0] * phi[0] + p[1][1] * phi[1],
        ];
        let denom = self.forgetting + phi[0] * pphi[0] + phi[1] * pphi[1];
        let gain = [pphi[0] / denom, pphi[1] / denom];
        let err = force_in_phase - (self.theta[0] * phi[0] + self.theta[1] * phi[1]);
        self.theta[0] += gain[0] * err;
        self.theta[1] += gain[1] * err;
        for i in 0..2 {
            for j in 0..2 {
                self.p[i][j] = (p[i][j] - gain[i] * pphi[j]) / self.forgetting;
            }
        }
        // Keep P symmetric (rounding otherwise breaks it and the filter diverges) and bounded
        // (with forgetting, directions the probes do not excite would grow without limit).
        let off = 0.5 * (self.p[0][1] + self.p[1][0]);
        self.p[0][1] = off;
        self.p[1][0] = off;
        let trace = self.p[0][0] + self.p[1][1];
        if trace > self.p_max {
            let k = self.p_max / trace;
            self.p.iter_mut().flatten().for_each(|x| *x *= k);
        }
        self.updates += 1;
    }

    /// Feeds every probe of a record (stats on the estimate's final normal) into the filter.
    pub fn update_from(&mut self, stats: &[ProbeStats], base_angle: f64) {
        let (t, n) = (unit(base_angle), perp(unit(base_angle)));
        for s in stats {
            self.update(
                t * s.displacement_m[0] + n * s.displacement_m[1],
                s.force_in_phase_n,
            );
        }
    }

    /// The tangent angle (rad, world).
    pub fn tangent_angle(&self) -> f64 {
        self.theta[1].atan2(self.theta[0]) - std::f64::consts::FRAC_PI_2
    }

    /// The contact stiffness the filter sees, |k n| (N/m).
    pub fn stiffness(&self) -> f64 {
        self.theta[0].hypot(self.theta[1])
    }

    /// Number of updates.
    pub fn updates(&self) -> usize {
        self.updates
    }
}

/// A synthetic probe run of the contact model, at 1 kHz: a 200-sample hold at the preload,
/// then each probe's whole periods. Normal force `preload − k·A·sin(α0 + δα)·sin φ` along the
/// true normal, friction `μ F_N sgn(ṡ)` along the true tangent, Gaussian noise on both axes.
/// For tests and benchmarks of the estimator (and for a client exercising the estimator board).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeModel {
    /// True tangent error α0 (rad).
    pub alpha0: f64,
    /// Estimated tangent angle θ̂ the probes are relative to (rad).
    pub base: f64,
    /// Contact stiffness k (N/m).
    pub k: f64,
    /// Force noise standard deviation per axis (N).
    pub noise: f64,
    /// Friction coefficient μ.
    pub friction: f64,
    /// Preload (N).
    pub preload: f64,
}

impl ProbeModel {
    /// The record of `plan` (noise drawn from `seed`).
    pub fn record(&self, plan: &ProbePlan, seed: u64) -> Vec<ProbeSample> {
        use rand_chacha::ChaCha8Rng;
        use rand_chacha::rand_core::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut nz = || -> Vec2 {
            Vec2::new(
                StandardNormal.sample(&mut rng),
                StandardNormal.sample(&mut rng),
            ) * self.noise
        };
        let theta = self.base - self.alpha0;
        let (t_true, n_true) = (unit(theta), perp(unit(theta)));
        let mut out = Vec::new();
        let rate = 1000.0;
        for k in 0..200 {
            let f = n_true * self.preload + nz();
            out.push(ProbeSample {
                t: k as f64 / rate,
                force: [f.x, f.y],
                tip: [0.0, 0.0],
                phase: 0.0,
                probe: HOLD,
                measured: false,
            });
        }
        for p in 0..plan.count.min(MAX_PROBES) {
            let dir = unit(self.base + plan.offsets[p]);
            let n = (plan.periods as f64 * rate / plan.frequency_hz) as usize;
            for k in 0..n {
                let phase = std::f64::consts::TAU * k as f64 / (rate / plan.frequency_hz);
                let disp = plan.amplitude_m * phase.sin();
                let vel = phase.cos();
                let beta = self.alpha0 + plan.offsets[p];
                let fnn = self.preload - self.k * disp * beta.sin();
                let fric = -self.friction * fnn * vel.signum();
                let f = n_true * fnn + t_true * (fric * dir.dot(&t_true).signum()) + nz();
                let tip = dir * disp;
                out.push(ProbeSample {
                    t: k as f64 / rate,
                    force: [f.x, f.y],
                    tip: [tip.x, tip.y],
                    phase,
                    probe: p as u8,
                    measured: true,
                });
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn synth(alpha0_deg: f64) -> ProbeModel {
        ProbeModel {
            alpha0: alpha0_deg.to_radians(),
            base: 0.3,
            k: 1400.0,
            noise: 0.02,
            friction: 0.0,
            preload: 2.5,
        }
    }

    fn run(s: &ProbeModel, params: &TangentParams) -> (TangentOutcome, Option<TangentOutcome>) {
        let plan = params.first_plan();
        let out = estimate(&s.record(&plan, 1), &plan, s.base, params, false);
        if let TangentOutcome::Reprobe { plan, .. } = out {
            let second = estimate(&s.record(&plan, 2), &plan, s.base, params, true);
            (out, Some(second))
        } else {
            (out, None)
        }
    }

    /// Small-angle thesis forms agree with the exact ones for small angles.
    #[test]
    fn thesis_forms_match_exact_for_small_angles() {
        let (d1, d2) = (5f64.to_radians(), 10f64.to_radians());
        for a0 in [-3.0f64, 0.0, 2.0, 4.0] {
            let a = a0.to_radians();
            let (r1, r2) = ((a + d1).sin(), (a + d2).sin());
            let exact = alpha0_exact(r1, r2, d1, d2).unwrap();
            assert!((exact - a).abs() < 1e-12);
            let small = eq_5_8(r1, r2, d1, d2).unwrap();
            // The small-angle form is off by its sin ≈ angle approximation (0.04° at α0 = 0).
            assert!(
                (small - a).abs() < 0.15f64.to_radians(),
                "5.8 at {a0}°: {}",
                small.to_degrees()
            );
            // 6.1 with equal strokes is 5.8; with unequal strokes it normalises them.
            assert_eq!(eq_6_1(r1, r2, 1.0, 1.0, d1, d2), eq_5_8(r1, r2, d1, d2));
            let e61 = eq_6_1(r1 * 0.8, r2 * 1.1, 0.8, 1.1, d1, d2).unwrap();
            assert!((e61 - small).abs() < 1e-12);
            let e59 = eq_5_9((a + d1).sin(), (a - d1).sin().abs(), d1).unwrap();
            assert!((e59 - a).abs() < 0.05f64.to_radians() || a.abs() >= d1);
        }
    }

    /// Eq. 5.9 is the form for probes that straddle the tangent (δα1 = −δα2 = δα, |α0| < δα),
    /// not a special case of eq. 5.8: on the small-angle model R_i = |α0 + δα_i| it is exact,
    /// while eq. 5.8 with the same probes answers δα²/α0.
    #[test]
    fn eq_5_9_is_the_straddle_form() {
        let d = 5f64.to_radians();
        for a0 in [-4.0f64, -1.5, 0.5, 3.0] {
            let a = a0.to_radians();
            let (r1, r2) = ((a + d).abs(), (a - d).abs());
            let e59 = eq_5_9(r1, r2, d).unwrap();
            assert!((e59 - a).abs() < 1e-15, "5.9 at {a0}°");
            let e58 = eq_5_8(r1, r2, d, -d).unwrap();
            assert!((e58 - d * d / a).abs() < 1e-12, "5.8 at {a0}°");
        }
    }

    /// The stroke bound keeps the normal-force swing below the margin × preload.
    #[test]
    fn stroke_amplitude_is_bounded_by_the_preload() {
        let p = TangentParams::default();
        let (preload, k, unc) = (2.5, 1322.0, 3f64.to_radians());
        let a = p.amplitude_bound(preload, k, unc, 0.8);
        let widest = 16f64.to_radians() + unc;
        assert!((k * a * widest.sin() - 0.8 * preload).abs() < 1e-12);
        // A stiffer contact or a smaller preload shrinks it.
        assert!(p.amplitude_bound(preload, 10.0 * k, unc, 0.8) < a);
        assert!(p.amplitude_bound(0.5 * preload, k, unc, 0.8) < a);
    }

    /// Eq. 5.8 on unsigned RMS folds when the true tangent lies between the probes: at
    /// α0 = −7° it answers +5°.
    #[test]
    fn rms_form_folds_between_the_probes() {
        let (d1, d2) = (5f64.to_radians(), 10f64.to_radians());
        let a = (-7f64).to_radians();
        let (r1, r2) = ((a + d1).sin().abs(), (a + d2).sin().abs());
        let folded = eq_5_8(r1, r2, d1, d2).unwrap().to_degrees();
        assert!((folded - 5.0).abs() < 0.1, "{folded}");
    }

    /// On synthetic records (a rigid stroke against a 1.4 kN/m contact, σ = 0.02 N) the estimate
    /// is within 0.25° for |α0| ≤ 10° and 0.5° up to 15°, or the estimator asks to re-probe and
    /// then answers; never a folded angle. (Accuracy in the closed loop: `afs experiment tangent`.)
    #[test]
    fn estimates_within_tolerance_or_reprobe_never_folded() {
        let params = TangentParams::default();
        for a0 in (-15..=15).map(|d| d as f64) {
            let s = synth(a0);
            let (first, second) = run(&s, &params);
            let final_out = second.unwrap_or(first);
            match final_out {
                TangentOutcome::Estimate(e) => {
                    let err = (e.alpha0_rad - s.alpha0).to_degrees().abs();
                    let tol = if a0.abs() <= 10.0 { 0.25 } else { 0.5 };
                    assert!(err < tol, "α0 = {a0}°: error {err:.3}° via {:?}", e.method);
                }
                other => panic!("α0 = {a0}°: no estimate: {other:?}"),
            }
            if (-10.0..-5.0).contains(&a0) {
                // Between the probes the RMS form folds: either the fold is detected and a
                // re-probe asked for, or one probe runs so close to the tangent that its sign
                // is not significant and the regression answers directly.
                if let TangentOutcome::Estimate(e) = first {
                    assert!(
                        (e.alpha0_rad - s.alpha0).to_degrees().abs() < 0.25,
                        "α0 = {a0}°: {e:?}"
                    );
                } else {
                    assert!(
                        matches!(
                            first,
                            TangentOutcome::Reprobe {
                                reason: ReprobeReason::Fold,
                                ..
                            }
                        ),
                        "α0 = {a0}°: fold not detected: {first:?}"
                    );
                }
            }
        }
    }

    /// Friction along the true tangent leaks into the estimated normal; the in-phase statistics
    /// and the re-projection keep the error small.
    #[test]
    fn friction_leakage_is_rejected() {
        let params = TangentParams::default();
        for a0 in [-4.0, 2.0, 6.0] {
            let s = ProbeModel {
                friction: 0.7,
                ..synth(a0)
            };
            let (first, second) = run(&s, &params);
            let TangentOutcome::Estimate(e) = second.unwrap_or(first) else {
                panic!("no estimate at {a0}")
            };
            assert!(
                (e.alpha0_rad - s.alpha0).to_degrees().abs() < 0.25,
                "{a0}: {}",
                e.alpha0_rad.to_degrees()
            );
        }
    }

    /// R1 ≈ R2 (both probes far from the tangent, symmetric about it) asks for a re-probe.
    #[test]
    fn equal_responses_ask_for_a_reprobe() {
        // R1 = R2 with equal signs: α0 = 90° − (δα1 + δα2)/2, the estimated normal lies nearly
        // along the true tangent.
        let params = TangentParams::default();
        let s = synth(82.5);
        let plan = params.first_plan();
        let out = estimate(&s.record(&plan, 3), &plan, s.base, &params, false);
        assert!(
            matches!(
                out,
                TangentOutcome::Reprobe {
                    reason: ReprobeReason::EqualResponses,
                    ..
                }
            ),
            "{out:?}"
        );
    }

    /// Eq. 5.6's RMS, taken at the stroke frequency, is not biased by noise: with noise ten
    /// times the response's RMS per sample its mean over 16 records stays within 4 % of the
    /// closed form `k A |sin(α0 + δα)| / √2`, where the plain RMS of the samples is several
    /// times larger.
    #[test]
    fn the_rms_is_not_biased_by_noise() {
        let params = TangentParams::default();
        let s = ProbeModel {
            noise: 0.2,
            ..synth(2.0)
        };
        let plan = params.first_plan();
        let n = perp(unit(s.base));
        let truth = s.k * plan.amplitude_m * (s.alpha0 + plan.offsets[0]).sin().abs() / 2f64.sqrt();
        let seeds = 16;
        let mut mean_rms = 0.0;
        for seed in 0..seeds {
            let rec = s.record(&plan, seed);
            let stats = probe_stats(&rec, 0, plan.offsets[0], s.base, n, plan.periods, 0.0);
            mean_rms += stats.rms_n / seeds as f64;
        }
        assert!(
            (mean_rms - truth).abs() < 0.04 * truth,
            "{mean_rms} vs {truth}"
        );
        let rec = s.record(&plan, 0);
        let f: Vec<f64> = rec
            .iter()
            .filter(|r| r.probe == 0 && r.measured)
            .map(|r| Vec2::new(r.force[0], r.force[1]).dot(&n))
            .collect();
        let m = f.iter().sum::<f64>() / f.len() as f64;
        let plain = (f.iter().map(|x| (x - m).powi(2)).sum::<f64>() / f.len() as f64).sqrt();
        assert!(plain > 1.5 * truth, "plain RMS {plain} vs {truth}");
    }

    /// A stroke that unloads the contact is an error, not an angle.
    #[test]
    fn contact_loss_is_an_error() {
        let params = TangentParams::default();
        let s = ProbeModel {
            k: 40_000.0,
            ..synth(3.0)
        };
        let plan = params.first_plan();
        let out = estimate(&s.record(&plan, 5), &plan, s.base, &params, false);
        assert!(
            matches!(
                out,
                TangentOutcome::Failed(TangentError::ContactLost { .. })
            ),
            "{out:?}"
        );
        let quiet = ProbeModel {
            k: 10.0,
            noise: 0.05,
            ..synth(3.0)
        };
        let out = estimate(&quiet.record(&plan, 6), &plan, quiet.base, &params, false);
        assert!(
            matches!(
                out,
                TangentOutcome::Failed(TangentError::TooNoisy { .. })
                    | TangentOutcome::Failed(TangentError::Uncertain { .. })
            ),
            "{out:?}"
        );
    }

    /// Probes as the servo makes them: strokes 5° and 10° off the estimate, the measured
    /// normal motion a tenth of the commanded one (the servo gives way to the stiff contact),
    /// the stiffness varying ±3 % from record to record, the surface turning 0.2° per record
    /// and the estimate following the filter. The drift form lags by less than one record's
    /// turn; exponential forgetting, which also forgets k, lags several times more.
    #[test]
    fn drift_form_follows_a_turning_surface_that_forgetting_lags() {
        let run = |mut f: TangentRls| -> f64 {
            let mut theta = 0.0f64;
            let mut worst = 0.0f64;
            for record in 0..40 {
                theta += 0.2f64.to_radians();
                let k = 8800.0 * (1.0 + 0.03 * ((record * 7 % 5) as f64 - 2.0) / 2.0);
                let base = f.tangent_angle();
                let (t, n) = (unit(theta), perp(unit(theta)));
                for off in [5.0f64, 10.0] {
                    let across = (base + off.to_radians() - theta).sin();
                    let d = t * 7.7e-4 + n * (7.7e-4 * across * 0.1);
                    f.update(d, -k * n.dot(&d));
                }
                if record >= 10 {
                    worst = worst.max((f.tangent_angle() - theta).abs());
                }
            }
            worst.to_degrees()
        };
        let drift = run(TangentRls::with_drift(
            1e12,
            0.0,
            8800.0,
            0.1f64.to_radians(),
            0.003,
        ));
        let forgetting = run(TangentRls::new(0.7, 1e12, 0.0, 8800.0));
        // Measured: 0.16° (lag under one record's turn) against 1.09°.
        assert!(drift < 0.25, "drift form {drift}°");
        assert!(
            forgetting > 4.0 * drift,
            "forgetting {forgetting}° vs drift {drift}°"
        );
    }

    /// The recursive form converges to a fixed slope and follows a slowly turning one.
    #[test]
    fn rls_tracks_a_slowly_varying_slope() {
        let k = 1e4;
        let probe = |theta: f64, dir: f64| -> (Vec2, f64) {
            let d = unit(dir) * 1e-3;
            (d, -k * perp(unit(theta)).dot(&d))
        };
        let mut rls = TangentRls::new(0.9, 1e9, 0.0, 5e3);
        let mut theta = 0.1f64;
        for step in 0..300 {
            theta += 0.001;
            for off in [-0.1, 0.1] {
                let (d, f) = probe(theta, theta + 0.02 + off);
                rls.update(d, f);
            }
            // Lag of a forgetting filter: about (rate per update) × λ/(1 − λ) = 0.0005 × 9.
            if step > 30 {
                assert!(
                    (rls.tangent_angle() - theta).abs() < 0.006,
                    "step {step}: {} vs {theta}",
                    rls.tangent_angle()
                );
            }
        }
        let mut fixed = TangentRls::new(1.0, 1e12, 0.0, 1.0);
        for off in [-0.2, -0.1, 0.1, 0.2] {
            let (d, f) = probe(0.45, 0.5 + off);
            fixed.update(d, f);
        }
        assert!(
            (fixed.tangent_angle() - 0.45).abs() < 1e-4,
            "{}",
            fixed.tangent_angle()
        );
        assert!((fixed.stiffness() - k).abs() < 0.01 * k);
    }
}
