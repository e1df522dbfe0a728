//! The tracking monitor: the figures of a surface-tracking run (tangent error, normal force,
//! contact, travel), tick by tick, from the world and controller samples. The scenarios (for
//! the stack and its lockstep reference) and the tracking experiments measure with it.

use crate::msg::{PlantSample, ServoFlags, ServoSample};
use crate::servo::{EstimationCounters, ServoMode};
use crate::window::SlidingWindow;
use serde::{Deserialize, Serialize};

/// What the monitor needs of one tick, from the two samples of that tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MonitorTick {
    /// Simulated time (s).
    pub t: f64,
    /// True normal force (N).
    pub normal_true: f64,
    /// In contact.
    pub contact: bool,
    /// True tangent angle (rad).
    pub tangent_true: f64,
    /// Contact position along the surface (m).
    pub u: f64,
    /// Tracking (not stopped for an estimate, not safe).
    pub moving: bool,
    /// Estimated tangent angle (rad).
    pub tangent_estimated: f64,
    /// Measured friction resisting the nominal motion (N).
    pub friction: f64,
    /// Measured normal force (N).
    pub normal: f64,
    /// Tip velocity along the estimated tangent in the nominal direction (m/s).
    pub velocity: f64,
    /// Dither phase (rad).
    pub phase: f64,
    /// Commanded Aω (m/s).
    pub a_cmd: f64,
}

impl MonitorTick {
    /// From the world and controller samples of one tick.
    pub fn from_samples(p: &PlantSample, s: &ServoSample) -> Self {
        let dir = if s.velocity_target_m_per_s < 0.0 {
            -1.0
        } else {
            1.0
        };
        Self {
            t: p.time_s,
            normal_true: p.normal_force_n,
            contact: p.contact_count > 0 && p.normal_force_n > 0.0,
            tangent_true: p.tangent_angle_rad,
            u: p.surface_u_m,
            moving: ServoMode::try_from(s.mode) == Ok(ServoMode::Track)
                && !s.flags.contains(ServoFlags::SAFE),
            tangent_estimated: s.tangent_angle_rad,
            friction: -s.tangential_force_n * dir,
            normal: s.normal_force_n,
            velocity: s.tangent_velocity_m_per_s * dir,
            phase: s.dither_phase_rad,
            a_cmd: s.a_omega_m_per_s,
        }
    }
}

/// One recorded instant of a tracking run (every 10 ms).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct TrackSample {
    /// Time (s).
    pub t: f64,
    /// Surface coordinate of the contact (m).
    pub u_m: f64,
    /// True tangent angle at the contact (rad).
    pub true_angle_rad: f64,
    /// Tangent angle the controller uses (rad).
    pub estimated_angle_rad: f64,
    /// True normal force (N).
    pub normal_n: f64,
    /// True while tracking (not stopped for an estimate).
    pub moving: bool,
}

/// A tracking run's figures.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TrackingRun {
    /// RMS of the tangent error while moving (deg).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub tangent_error_rms_deg: f64,
    /// Largest |tangent error| while moving (deg).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub tangent_error_max_deg: f64,
    /// Worst |F_N − preload| / preload after the first 0.5 s, of the true normal force
    /// averaged over one dither period: the regulated force, without the dither's ripple.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub worst_normal_deviation: f64,
    /// Smallest and largest of that period-averaged force (N).
    #[serde(deserialize_with = "crate::nan::pair_or_null")]
    pub normal_range_n: [f64; 2],
    /// When and where the worst period-averaged deviation happened (s, m).
    #[serde(deserialize_with = "crate::nan::pair_or_null")]
    pub worst_normal_at: [f64; 2],
    /// RMS of the period-averaged |F_N − preload| / preload from 0.5 s after the first touch.
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub normal_deviation_rms: f64,
    /// Smallest and largest instantaneous true normal force after 0.5 s, ripple included (N).
    #[serde(deserialize_with = "crate::nan::pair_or_null")]
    pub instantaneous_normal_range_n: [f64; 2],
    /// Servo ticks without contact, from the first touch on.
    pub ticks_without_contact: usize,
    /// Estimation counters.
    pub estimations: EstimationCounters,
    /// Distance travelled along the surface (m).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub travelled_m: f64,
    /// Run time (s).
    #[serde(deserialize_with = "crate::nan::or_null")]
    pub duration_s: f64,
    /// The estimator's answers (lockstep runs only).
    #[serde(skip)]
    pub estimates: Vec<crate::sim::EstimateLog>,
    /// The record.
    #[serde(skip)]
    pub samples: Vec<TrackSample>,
}

/// Streams [`MonitorTick`]s into a [`TrackingRun`].
#[derive(Debug, Clone)]
pub struct TrackingMonitor {
    preload: f64,
    period: SlidingWindow,
    sq: f64,
    n: f64,
    max_err: f64,
    worst: f64,
    worst_at: [f64; 2],
    fmin: f64,
    fmax: f64,
    imin: f64,
    imax: f64,
    dev_sq: f64,
    dev_n: f64,
    lost: usize,
    /// When the tool first touched (s): 0 when it starts in contact; the normal force is
    /// judged from 0.5 s after it, and ticks without contact counted from it (a run that
    /// starts off the surface approaches first, docs/contact.md *First touch*).
    touched_at: Option<f64>,
    u0: Option<f64>,
    last: MonitorTick,
    ticks: u64,
    samples: Vec<TrackSample>,
}

impl TrackingMonitor {
    /// A monitor for a preload (N), with the dither period in ticks.
    pub fn new(preload: f64, period_ticks: usize) -> Self {
        Self {
            preload,
            period: SlidingWindow::new(period_ticks.max(1)),
            sq: 0.0,
            n: 0.0,
            max_err: 0.0,
            worst: 0.0,
            worst_at: [0.0; 2],
            fmin: f64::INFINITY,
            fmax: f64::NEG_INFINITY,
            imin: f64::INFINITY,
            imax: f64::NEG_INFINITY,
            dev_sq: 0.0,
            dev_n: 0.0,
            lost: 0,
            touched_at: None,
            u0: None,
            last: MonitorTick::default(),
            ticks: 0,
            samples: Vec::new(),
        }
    }

    /// One tick.
    pub fn push(&mut self, m: &MonitorTick) {
        if self.u0.is_none() {
            self.u0 = Some(m.u);
        }
        if self.touched_at.is_none() && m.contact {
            self.touched_at = Some(if self.ticks == 0 { 0.0 } else { m.t });
        }
        let Some(touched_at) = self.touched_at else {
            self.ticks += 1;
            self.last = *m;
            return;
        };
        if !m.contact {
            self.lost += 1;
        }
        let err = crate::math::wrap_angle(m.tangent_estimated - m.tangent_true).to_degrees();
        if m.moving {
            self.sq += err * err;
            self.n += 1.0;
            self.max_err = self.max_err.max(err.abs());
        }
        self.period.push(m.normal_true);
        if m.t >= touched_at + 0.5 {
            let mean = self.period.mean();
            let dev = (mean - self.preload).abs() / self.preload;
            self.dev_sq += dev * dev;
            self.dev_n += 1.0;
            if dev > self.worst {
                self.worst = dev;
                self.worst_at = [m.t, m.u];
            }
            self.fmin = self.fmin.min(mean);
            self.fmax = self.fmax.max(mean);
            self.imin = self.imin.min(m.normal_true);
            self.imax = self.imax.max(m.normal_true);
        }
        if self.ticks.is_multiple_of(100) {
            self.samples.push(TrackSample {
                t: m.t,
                u_m: m.u,
                true_angle_rad: m.tangent_true,
                estimated_angle_rad: m.tangent_estimated,
                normal_n: m.normal_true,
                moving: m.moving,
            });
        }
        self.ticks += 1;
        self.last = *m;
    }

    /// The figures so far.
    pub fn finish(&self, estimations: EstimationCounters) -> TrackingRun {
        TrackingRun {
            tangent_error_rms_deg: (self.sq / self.n.max(1.0)).sqrt(),
            tangent_error_max_deg: self.max_err,
            worst_normal_deviation: self.worst,
            normal_range_n: [self.fmin, self.fmax],
            worst_normal_at: self.worst_at,
            normal_deviation_rms: (self.dev_sq / self.dev_n.max(1.0)).sqrt(),
            instantaneous_normal_range_n: [self.imin, self.imax],
            ticks_without_contact: self.lost,
            estimations,
            travelled_m: self.last.u - self.u0.unwrap_or(self.last.u),
            duration_s: self.last.t,
            estimates: Vec::new(),
            samples: self.samples.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run that starts off the surface is judged from its first touch: the approach's ticks
    /// are not ticks without contact, and the normal force counts from 0.5 s after the touch;
    /// a contact lost after the touch still counts.
    #[test]
    fn a_run_is_judged_from_its_first_touch() {
        let preload = 2.5;
        let mut m = TrackingMonitor::new(preload, 10);
        let dt = 1e-3;
        for k in 0..3000 {
            let t = f64::from(k) * dt;
            let contact = t >= 1.0 && !(2.0..2.005).contains(&t);
            m.push(&MonitorTick {
                t,
                contact,
                // The force builds over 0.3 s after the touch.
                normal_true: if contact {
                    preload * ((t - 1.0) / 0.3).min(1.0)
                } else {
                    0.0
                },
                ..MonitorTick::default()
            });
        }
        let run = m.finish(EstimationCounters::default());
        assert_eq!(run.ticks_without_contact, 5);
        // The only deviation judged is the 5-ms loss at 2 s, not the approach's second nor the
        // force building after the touch.
        assert!(run.worst_normal_at[0] >= 2.0, "{:?}", run.worst_normal_at);
        assert!(
            run.normal_deviation_rms < 0.1,
            "{}",
            run.normal_deviation_rms
        );
    }
}
