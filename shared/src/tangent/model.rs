//! A probe run without a plant: the normal force a stroke along a direction produces on a
//! flat surface of known stiffness, with noise ([`ProbeModel`]), for tests and experiments.

use super::*;
use crate::math::{Vec2, perp, unit};

/// A synthetic probe run of the contact model, at 1 kHz: a 200-sample hold at the preload,
/// then each probe's whole periods. Normal force `preload − k·A·sin(α0 + δα)·sin φ` along the
/// true normal, friction `μ F_N sgn(ṡ)` along the true tangent, Gaussian noise on both axes; the
/// recorded tip travels `travel` of the stroke and follows `share` of its normal part.
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
    /// Fraction of the stroke the tip travels (1: it follows the command; near 0: friction
    /// holds it while the servo's spring still loads the contact).
    pub travel: f64,
    /// Fraction of the stroke's part along the true normal that the tip follows into the
    /// contact (1: all of it; near 0: a contact much stiffer than the servo holds the tip on
    /// the surface, and the force response shrinks with it).
    pub share: f64,
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
                let fnn = self.preload - self.k * disp * self.share * beta.sin();
                let fric = -self.friction * fnn * vel.signum();
                let f = n_true * fnn + t_true * (fric * dir.dot(&t_true).signum()) + nz();
                let tip = (t_true * beta.cos() + n_true * (self.share * beta.sin()))
                    * (disp * self.travel);
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
