//! The force/torque sensor model (thesis §4.5.1: a six-axis ATI 130 N / 10 N·m unit; afs
//! models the planar part, fx, fy, mz, in the sensor frame whose x axis runs along link 2).
//!
//! Each sample (at the sensor's own rate, default 7 kHz like an ATI Net F/T) is
//! `quantize(saturate(lowpass(truth + bias + drift + noise)))`:
//! * a fixed per-axis bias drawn once from the seed (uniform in ±`bias`);
//! * a slow thermal drift: its rate wanders as an Ornstein–Uhlenbeck process (standard
//!   deviation `drift_rate_force_n_per_s`, correlation time `drift_correlation_s`), so the offset
//!   changes smoothly (≈ rate × time over seconds), not like a random walk;
//! * white Gaussian gauge noise, scaled so that the *output* (after the filter) has the
//!   configured standard deviation;
//! * a first-order low-pass with selectable cut-off (`y += α (x − y)`, `α = 1 − e^{−2π f_c / f_s}`),
//!   or none;
//! * saturation at the rated range, then quantization to the resolution.
//!
//! Pure and deterministic: the noise comes from a seeded ChaCha8 generator.

use crate::error::ConfigError;
use crate::math::Vec2;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, StandardNormal, Uniform};
use serde::{Deserialize, Serialize};

/// A planar wrench: force (N) and moment about the sensor's z axis (N·m).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Wrench {
    /// Force (N).
    pub force: Vec2,
    /// Moment (N·m).
    pub torque: f64,
}

impl Wrench {
    /// This reading with the zero-load reading `tare` taken off: what the controllers use.
    /// The one place the tare is subtracted.
    pub fn tared(self, tare: Wrench) -> Wrench {
        Wrench {
            force: self.force - tare.force,
            torque: self.torque - tare.torque,
        }
    }
}

/// Sensor parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorParams {
    /// Sample rate (Hz).
    pub rate_hz: f64,
    /// Standard deviation of the force noise at the output (N).
    pub noise_force_n: f64,
    /// Standard deviation of the moment noise at the output (N·m).
    pub noise_torque_nm: f64,
    /// Bias magnitude bound per force axis (N).
    pub bias_force_n: f64,
    /// Bias magnitude bound for the moment (N·m).
    pub bias_torque_nm: f64,
    /// Standard deviation of the force drift rate (N/s).
    pub drift_rate_force_n_per_s: f64,
    /// Correlation time of the drift rate (s).
    pub drift_correlation_s: f64,
    /// Force resolution (N); 0 disables quantization.
    pub quantization_force_n: f64,
    /// Moment resolution (N·m); 0 disables quantization.
    pub quantization_torque_nm: f64,
    /// Low-pass cut-off (Hz); 0 disables the filter.
    pub cutoff_hz: f64,
    /// Rated force range (N): readings saturate there.
    pub range_force_n: f64,
    /// Rated moment range (N·m).
    pub range_torque_nm: f64,
}

impl Default for SensorParams {
    fn default() -> Self {
        Self {
            rate_hz: 7000.0,
            noise_force_n: 0.02,
            noise_torque_nm: 0.0005,
            bias_force_n: 0.05,
            bias_torque_nm: 0.002,
            drift_rate_force_n_per_s: 2e-4,
            drift_correlation_s: 300.0,
            quantization_force_n: 1.0 / 40.0,
            quantization_torque_nm: 1.0 / 800.0,
            cutoff_hz: 326.0,
            range_force_n: 130.0,
            range_torque_nm: 10.0,
        }
    }
}

impl SensorParams {
    /// An ideal sensor: no noise, bias, drift, filter or quantization (same rate).
    pub fn ideal(rate_hz: f64) -> Self {
        Self {
            rate_hz,
            noise_force_n: 0.0,
            noise_torque_nm: 0.0,
            bias_force_n: 0.0,
            bias_torque_nm: 0.0,
            drift_rate_force_n_per_s: 0.0,
            quantization_force_n: 0.0,
            quantization_torque_nm: 0.0,
            cutoff_hz: 0.0,
            ..Self::default()
        }
    }

    /// Checks the parameters; the message names the field and what to do.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.rate_hz.is_finite() && self.rate_hz >= 10.0 && self.rate_hz <= 100_000.0) {
            return Err(ConfigError::setting(
                "sensor.rate_hz",
                self.rate_hz,
                "must lie in [10, 100000]",
            ));
        }
        let nonneg = [
            ("noise_force_n", self.noise_force_n),
            ("noise_torque_nm", self.noise_torque_nm),
            ("bias_force_n", self.bias_force_n),
            ("bias_torque_nm", self.bias_torque_nm),
            ("drift_rate_force_n_per_s", self.drift_rate_force_n_per_s),
            ("quantization_force_n", self.quantization_force_n),
            ("quantization_torque_nm", self.quantization_torque_nm),
            ("cutoff_hz", self.cutoff_hz),
        ];
        for (n, v) in nonneg {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ConfigError::setting(
                    format!("sensor.{n}"),
                    v,
                    "must be a non-negative number",
                ));
            }
        }
        if self.cutoff_hz > 0.0 && self.cutoff_hz >= 0.5 * self.rate_hz {
            return Err(ConfigError::setting(
                "sensor.cutoff_hz",
                self.cutoff_hz,
                format!(
                    "must be below half the sample rate ({} Hz), or 0 for no filter",
                    0.5 * self.rate_hz
                ),
            ));
        }
        for (n, v) in [
            ("range_force_n", self.range_force_n),
            ("range_torque_nm", self.range_torque_nm),
            ("drift_correlation_s", self.drift_correlation_s),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ConfigError::setting(
                    format!("sensor.{n}"),
                    v,
                    "must be > 0",
                ));
            }
        }
        Ok(())
    }

    /// Filter coefficient α of the first-order low-pass (1 when the filter is off).
    pub fn filter_alpha(&self) -> f64 {
        if self.cutoff_hz <= 0.0 {
            1.0
        } else {
            1.0 - (-std::f64::consts::TAU * self.cutoff_hz / self.rate_hz).exp()
        }
    }

    /// Delay of a slow force change through the sensor (s): the filter's low-frequency group
    /// delay `T (1 − α)/α` plus half a sample period for the reading held between samples.
    /// With the filter off, half a sample period.
    pub fn signal_delay_s(&self) -> f64 {
        let period = 1.0 / self.rate_hz;
        let alpha = self.filter_alpha();
        period * (1.0 - alpha) / alpha + 0.5 * period
    }
}

/// One sensor reading.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Reading {
    /// The measured wrench (sensor frame).
    pub wrench: Wrench,
    /// True when any axis hit its rated range.
    pub saturated: bool,
}

/// The sensor's state: generator, bias, drift and filter memory.
#[derive(Debug, Clone)]
pub struct SensorModel {
    params: SensorParams,
    rng: ChaCha8Rng,
    bias: [f64; 3],
    drift: [f64; 3],
    drift_rate: [f64; 2],
    filtered: [f64; 3],
    primed: bool,
    alpha: f64,
    raw_noise: [f64; 3],
}

impl SensorModel {
    /// A sensor whose noise, bias and drift come from `seed`.
    pub fn new(params: SensorParams, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5e05_0f7e);
        let u = Uniform::new_inclusive(-1.0f64, 1.0).expect("valid range");
        let bias = [
            params.bias_force_n * u.sample(&mut rng),
            params.bias_force_n * u.sample(&mut rng),
            params.bias_torque_nm * u.sample(&mut rng),
        ];
        let alpha = params.filter_alpha();
        // Output variance of y += α(x − y) for white x of variance s²: s² α / (2 − α).
        let gain = (alpha / (2.0 - alpha)).sqrt();
        let raw_noise = [
            params.noise_force_n / gain,
            params.noise_force_n / gain,
            params.noise_torque_nm / gain,
        ];
        Self {
            params,
            rng,
            bias,
            drift: [0.0; 3],
            drift_rate: [0.0; 2],
            filtered: [0.0; 3],
            primed: false,
            alpha,
            raw_noise,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &SensorParams {
        &self.params
    }

    /// The fixed bias drawn for this sensor (fx, fy, mz).
    pub fn bias(&self) -> [f64; 3] {
        self.bias
    }

    /// Produces one reading of the true sensor-frame wrench.
    pub fn sample(&mut self, truth: Wrench) -> Reading {
        let p = self.params;
        let dt = 1.0 / p.rate_hz;
        let truth3 = [truth.force.x, truth.force.y, truth.torque];
        let mut raw = [0.0; 3];
        for k in 0..3 {
            if k < 2 && p.drift_rate_force_n_per_s > 0.0 {
                // Exact OU update of the drift rate, then integrate the offset.
                let tau = p.drift_correlation_s;
                let decay = (-dt / tau).exp();
                let n: f64 = StandardNormal.sample(&mut self.rng);
                let r = &mut self.drift_rate[k];
                *r = *r * decay + p.drift_rate_force_n_per_s * (1.0 - decay * decay).sqrt() * n;
                self.drift[k] += *r * dt;
            }
            let noise = if self.raw_noise[k] > 0.0 {
                let n: f64 = StandardNormal.sample(&mut self.rng);
                self.raw_noise[k] * n
            } else {
                0.0
            };
            raw[k] = truth3[k] + self.bias[k] + self.drift[k] + noise;
        }
        if !self.primed {
            // Start the filter at the first value without its noise (no start-up transient).
            for ((f, t), b) in self.filtered.iter_mut().zip(truth3).zip(self.bias) {
                *f = t + b;
            }
            self.primed = true;
        }
        let mut saturated = false;
        let mut out = [0.0; 3];
        for k in 0..3 {
            self.filtered[k] += self.alpha * (raw[k] - self.filtered[k]);
            let (range, q) = if k < 2 {
                (p.range_force_n, p.quantization_force_n)
            } else {
                (p.range_torque_nm, p.quantization_torque_nm)
            };
            let mut y = self.filtered[k];
            if y.abs() > range {
                saturated = true;
                y = y.clamp(-range, range);
            }
            if q > 0.0 {
                y = (y / q).round() * q;
            }
            out[k] = y;
        }
        Reading {
            wrench: Wrench {
                force: Vec2::new(out[0], out[1]),
                torque: out[2],
            },
            saturated,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The output noise has the configured standard deviation after the filter.
    #[test]
    fn output_noise_matches_configuration() {
        let p = SensorParams {
            bias_force_n: 0.0,
            drift_rate_force_n_per_s: 0.0,
            quantization_force_n: 0.0,
            ..SensorParams::default()
        };
        let mut s = SensorModel::new(p, 3);
        let n = 200_000;
        let mut sum = 0.0;
        let mut sum2 = 0.0;
        for _ in 0..n {
            let r = s.sample(Wrench {
                force: Vec2::new(1.0, 0.0),
                torque: 0.0,
            });
            sum += r.wrench.force.x;
            sum2 += r.wrench.force.x.powi(2);
        }
        let mean = sum / n as f64;
        let sd = (sum2 / n as f64 - mean * mean).sqrt();
        assert!((mean - 1.0).abs() < 1e-3, "{mean}");
        assert!((sd - 0.02).abs() < 0.02 * 0.03, "{sd}");
    }

    /// The filter's step response reaches 1 − 1/e after one time constant.
    #[test]
    fn lowpass_time_constant() {
        let p = SensorParams {
            cutoff_hz: 50.0,
            ..SensorParams::ideal(7000.0)
        };
        let mut s = SensorModel::new(p, 0);
        s.sample(Wrench::default());
        let tau_samples = (7000.0 / (std::f64::consts::TAU * 50.0)).round() as usize;
        let mut y = 0.0;
        for _ in 0..tau_samples {
            y = s
                .sample(Wrench {
                    force: Vec2::new(1.0, 0.0),
                    torque: 0.0,
                })
                .wrench
                .force
                .x;
        }
        assert!((y - (1.0 - (-1.0f64).exp())).abs() < 0.01, "{y}");
    }

    #[test]
    fn same_seed_same_readings_and_saturation_flagged() {
        let mut a = SensorModel::new(SensorParams::default(), 9);
        let mut b = SensorModel::new(SensorParams::default(), 9);
        for _ in 0..100 {
            let w = Wrench {
                force: Vec2::new(0.3, -2.0),
                torque: 0.01,
            };
            assert_eq!(a.sample(w), b.sample(w));
        }
        let mut r = Reading::default();
        for _ in 0..50 {
            r = a.sample(Wrench {
                force: Vec2::new(500.0, 0.0),
                torque: 0.0,
            });
        }
        assert!(r.saturated);
        assert!(r.wrench.force.x <= 130.0);
    }

    /// The drift rate is stationary with the configured standard deviation, so over a short
    /// time the offset moves about rate × time.
    #[test]
    fn drift_rate_has_configured_spread() {
        let p = SensorParams {
            noise_force_n: 0.0,
            bias_force_n: 0.0,
            quantization_force_n: 0.0,
            cutoff_hz: 0.0,
            drift_correlation_s: 1.0,
            ..SensorParams::default()
        };
        let mut s = SensorModel::new(p, 5);
        let n = 7000 * 400;
        let mut sum2 = 0.0;
        for _ in 0..n {
            s.sample(Wrench::default());
            sum2 += s.drift_rate[0].powi(2);
        }
        let sd = (sum2 / n as f64).sqrt();
        assert!((sd - 2e-4).abs() < 0.1 * 2e-4, "{sd}");
    }

    #[test]
    fn invalid_parameters_are_rejected() {
        let p = SensorParams {
            cutoff_hz: 4000.0,
            ..SensorParams::default()
        };
        let e = p.validate().unwrap_err();
        assert!(
            matches!(&e, ConfigError::Setting { setting, value, .. }
                if setting == "sensor.cutoff_hz" && *value == 4000.0),
            "{e:?}"
        );
        let p = SensorParams {
            noise_force_n: -1.0,
            ..SensorParams::default()
        };
        assert!(p.validate().is_err());
        assert!(SensorParams::default().validate().is_ok());
    }
}
