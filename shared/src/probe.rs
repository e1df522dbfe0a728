//! The servo's side of tangent estimation (thesis §5.3.2): executes the probe strokes of a
//! [`ProbePlan`] and records the samples the estimator needs, inside the fast loop.
//!
//! A run is: a hold (`settle_s`, normal force loop frozen, samples marked [`HOLD`] for the noise
//! level), then for each probe a stroke `s(τ) = e(τ)·A·sin φ` along `unit(θ̂ + δα_i)` with
//! `φ = ω(τ − ramp)`, where the envelope e rises and falls by raised cosines over `ramp_s`
//! so the set-point, its velocity and acceleration stay continuous. Samples in the whole
//! periods between the ramps are marked `measured`. The record buffer is allocated once;
//! a plan longer than it is recorded up to its end and flagged incomplete.

use crate::math::{Vec2, unit};
use crate::tangent::{HOLD, ProbePlan, ProbeSample};
use std::f64::consts::{PI, TAU};

/// The stroke to add to the set-point this tick (world frame).
pub use crate::hybrid::SetpointOffset as StrokeCommand;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Stage {
    Idle,
    Hold { t: f64 },
    Stroke { probe: usize, tau: f64 },
    Done,
}

/// Executes and records a probe plan.
#[derive(Debug)]
pub struct ProbeRunner {
    plan: ProbePlan,
    base_angle: f64,
    stage: Stage,
    samples: Vec<ProbeSample>,
    decimation: usize,
    tick: usize,
    time: f64,
    truncated: bool,
}

impl Clone for ProbeRunner {
    /// A copy with the same record capacity (a derived clone would keep only the length, and
    /// the copy could then not record without allocating).
    fn clone(&self) -> Self {
        let mut samples = Vec::with_capacity(self.samples.capacity());
        samples.extend_from_slice(&self.samples);
        Self {
            plan: self.plan,
            base_angle: self.base_angle,
            stage: self.stage,
            samples,
            decimation: self.decimation,
            tick: self.tick,
            time: self.time,
            truncated: self.truncated,
        }
    }
}

impl ProbeRunner {
    /// A runner recording every `decimation`-th tick into a buffer of `capacity` samples.
    pub fn new(capacity: usize, decimation: usize) -> Self {
        Self {
            plan: ProbePlan::new(&[], &Default::default()),
            base_angle: 0.0,
            stage: Stage::Idle,
            samples: Vec::with_capacity(capacity),
            decimation: decimation.max(1),
            tick: 0,
            time: 0.0,
            truncated: false,
        }
    }

    /// Starts a plan about the estimated tangent `base_angle` (rad). Allocation-free.
    pub fn start(&mut self, plan: ProbePlan, base_angle: f64) {
        self.plan = plan;
        self.base_angle = base_angle;
        self.samples.clear();
        self.stage = Stage::Hold { t: 0.0 };
        self.tick = 0;
        self.time = 0.0;
        self.truncated = false;
    }

    /// True while a plan runs.
    pub fn active(&self) -> bool {
        matches!(self.stage, Stage::Hold { .. } | Stage::Stroke { .. })
    }

    /// True when the last plan finished.
    pub fn finished(&self) -> bool {
        self.stage == Stage::Done
    }

    /// The plan of the last run.
    pub fn plan(&self) -> &ProbePlan {
        &self.plan
    }

    /// The estimated tangent the offsets refer to (rad).
    pub fn base_angle(&self) -> f64 {
        self.base_angle
    }

    /// The recorded samples.
    pub fn samples(&self) -> &[ProbeSample] {
        &self.samples
    }

    /// True if the buffer was too small for the plan.
    pub fn truncated(&self) -> bool {
        self.truncated
    }

    /// Forgets the run.
    pub fn reset(&mut self) {
        self.stage = Stage::Idle;
        self.samples.clear();
    }

    /// Samples a plan needs at `rate_hz`.
    pub fn samples_needed(plan: &ProbePlan, rate_hz: f64, decimation: usize) -> usize {
        (plan.duration() * rate_hz / decimation.max(1) as f64).ceil() as usize + 2
    }

    /// Advances by `dt`; `force` (world, N) and `tip` (m) are this tick's measurements.
    pub fn step(&mut self, dt: f64, force: Vec2, tip: Vec2) -> StrokeCommand {
        let p = self.plan;
        let mut cmd = StrokeCommand::default();
        self.time += dt;
        let (probe, phase, measured) = match self.stage {
            Stage::Idle | Stage::Done => return cmd,
            Stage::Hold { t } => {
                let t = t + dt;
                self.stage = if t >= p.settle_s {
                    if p.count == 0 {
                        Stage::Done
                    } else {
                        Stage::Stroke { probe: 0, tau: 0.0 }
                    }
                } else {
                    Stage::Hold { t }
                };
                (HOLD, 0.0, false)
            }
            Stage::Stroke { probe, tau } => {
                let omega = TAU * p.frequency_hz;
                let measured_len = p.periods as f64 / p.frequency_hz;
                let total = 2.0 * p.ramp_s + measured_len;
                let phase = omega * (tau - p.ramp_s);
                let (e, de, dde) = envelope(tau, p.ramp_s, total);
                let (s, c) = phase.sin_cos();
                let a = p.amplitude_m;
                let disp = a * e * s;
                let vel = a * (de * s + e * omega * c);
                let acc = a * (dde * s + 2.0 * de * omega * c - e * omega * omega * s);
                let dir = unit(self.base_angle + p.offsets[probe]);
                cmd = StrokeCommand {
                    displacement: dir * disp,
                    velocity: dir * vel,
                    acceleration: dir * acc,
                };
                let measured = tau >= p.ramp_s && tau < p.ramp_s + measured_len;
                let tau = tau + dt;
                self.stage = if tau >= total {
                    if probe + 1 < p.count {
                        Stage::Stroke {
                            probe: probe + 1,
                            tau: 0.0,
                        }
                    } else {
                        Stage::Done
                    }
                } else {
                    Stage::Stroke { probe, tau }
                };
                (probe as u8, phase, measured)
            }
        };
        if self.tick.is_multiple_of(self.decimation) {
            if self.samples.len() < self.samples.capacity() {
                self.samples.push(ProbeSample {
                    t: self.time,
                    force: [force.x, force.y],
                    tip: [tip.x, tip.y],
                    phase,
                    probe,
                    measured,
                });
            } else {
                self.truncated = true;
            }
        }
        self.tick += 1;
        cmd
    }
}

/// Raised-cosine envelope over [0, total] with ramps of `ramp` at both ends: value and its
/// first two time derivatives.
pub(crate) fn envelope(tau: f64, ramp: f64, total: f64) -> (f64, f64, f64) {
    if ramp <= 0.0 {
        return (1.0, 0.0, 0.0);
    }
    let k = PI / ramp;
    if tau < ramp {
        let x = k * tau;
        (
            0.5 * (1.0 - x.cos()),
            0.5 * k * x.sin(),
            0.5 * k * k * x.cos(),
        )
    } else if tau > total - ramp {
        let x = k * (total - tau);
        (
            0.5 * (1.0 - x.cos()),
            -0.5 * k * x.sin(),
            0.5 * k * k * x.cos(),
        )
    } else {
        (1.0, 0.0, 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tangent::TangentParams;

    /// The stroke is continuous, starts and ends at rest, measures whole periods, and its
    /// velocity is the derivative of its displacement.
    #[test]
    fn strokes_are_smooth_and_measure_whole_periods() {
        let params = TangentParams::default();
        let plan = params.first_plan();
        let dt = 1e-4;
        let cap = ProbeRunner::samples_needed(&plan, 1e4, 10);
        let mut r = ProbeRunner::new(cap, 10);
        r.start(plan, 0.2);
        let mut last = StrokeCommand::default();
        let mut max_jump: f64 = 0.0;
        let mut n = 0;
        while r.active() {
            let c = r.step(dt, Vec2::new(0.0, 2.5), Vec2::zeros());
            let numeric = (c.displacement - last.displacement) / dt;
            if n > 0 {
                max_jump = max_jump.max((numeric - 0.5 * (c.velocity + last.velocity)).norm());
            }
            last = c;
            n += 1;
        }
        assert!(r.finished() && !r.truncated());
        // One tick before rest: displacement O(dt²), velocity O(dt).
        assert!(last.displacement.norm() < 1e-9 && last.velocity.norm() < 1e-4);
        assert!(
            max_jump < 1e-5,
            "velocity does not match displacement: {max_jump}"
        );
        assert!((n as f64 * dt - plan.duration()).abs() < 2.0 * dt);
        for k in 0..2u8 {
            let m: Vec<&ProbeSample> = r
                .samples()
                .iter()
                .filter(|s| s.probe == k && s.measured)
                .collect();
            assert_eq!(m.len(), 2000, "probe {k}: {}", m.len());
            let mean_sin = m.iter().map(|s| s.phase.sin()).sum::<f64>() / m.len() as f64;
            assert!(mean_sin.abs() < 1e-9, "not whole periods: {mean_sin}");
        }
        assert!(r.samples().iter().any(|s| s.probe == HOLD));
    }

    #[test]
    fn a_small_buffer_truncates_without_allocating() {
        let plan = TangentParams::default().first_plan();
        let mut r = ProbeRunner::new(100, 10);
        r.start(plan, 0.0);
        while r.active() {
            r.step(1e-4, Vec2::zeros(), Vec2::zeros());
        }
        assert!(r.truncated());
        assert_eq!(r.samples().len(), 100);
        assert_eq!(r.samples.capacity(), 100);
    }
}
