//! One probe's statistics: the stroke's in-phase (lock-in) response of the normal force, with
//! the friction-suppression dither removed by a comb and a slow trend fitted out, the
//! thesis's broadband RMS beside it, the noise, the contact (thesis §5.3, eq. 5.6).

use super::*;
use crate::math::{Vec2, perp, unit};
use serde::Serialize;

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
pub(super) const NOISE_BINS: usize = 8;

/// Averages the force over one period of the friction-suppression dither (centred moving
/// average): notches the dither and all its harmonics, scales the stroke frequency's response
/// by the same factor for every probe. Samples without a full window at the ends are dropped.
pub(super) fn comb(raw: &[(f64, f64, f64)], dither_hz: f64) -> Vec<(f64, f64, f64)> {
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
pub(super) fn fit_with_trend(samples: &[(f64, f64, f64)]) -> Option<([f64; 5], f64)> {
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
