//! The dither signal (eqs. 1.1, 4.10): `d = A sin ωt` added to the end-point motion along the
//! estimated tangent, with `ḋ = Aω cos ωt`, so the contact sees `ẋ = ẋ_o + Aω cos ωt`.
//!
//! The frequency is preset (thesis §4.4.1: it only scales the amplitude for a given
//! characteristic velocity `Aω`); the tuners adjust `Aω`. The amplitude is bounded so the
//! contact is never lost: if the estimated tangent is off by up to α, a stroke of A moves the
//! tool A·sin α along the normal, which must stay below the preload's penetration
//! `F_preload / k_e` (thesis §6.2.1).

use crate::error::ConfigError;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

wire_struct! {
    /// A running [`Dither`]'s state, for a snapshot: restored into an oscillator of the same
    /// frequency it continues bit for bit.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::DitherState")]
    pub struct DitherState {
        /// Phase ωt in [0, 2π) (rad).
        pub phase_rad: f64,
        /// Amplitude A (m).
        pub amplitude_m: f64,
        /// (sin φ, cos φ) as the rotation recurrence holds them.
        pub sin_cos: [f64; 2],
        /// 1 if the last step completed a period.
        pub wrapped: u32,
        /// Reserved (0).
        pub reserved: u32,
    }
}

/// Dither settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DitherParams {
    /// Dither frequency (Hz); thesis default 10 Hz for friction suppression.
    pub frequency_hz: f64,
    /// Absolute amplitude limit (m).
    pub max_amplitude_m: f64,
    /// Assumed worst error of the estimated tangent (deg) for the contact-loss bound: 2°, above
    /// the 0.75° at which the tracker's drift trigger re-estimates (docs/contact.md, *The
    /// contact mode and the dither*).
    pub tangent_uncertainty_deg: f64,
    /// Fraction of the preload penetration a stroke may use along the normal (0–1).
    pub contact_margin: f64,
}

impl Default for DitherParams {
    fn default() -> Self {
        Self {
            frequency_hz: 10.0,
            max_amplitude_m: 3e-3,
            tangent_uncertainty_deg: 2.0,
            contact_margin: 0.8,
        }
    }
}

impl DitherParams {
    /// Largest admissible amplitude (m): `min(max_amplitude, margin · (F_preload/k_e) / sin α)`.
    pub fn amplitude_bound(&self, preload_n: f64, stiffness_n_per_m: f64) -> f64 {
        let depth = preload_n / stiffness_n_per_m;
        let s = self.tangent_uncertainty_deg.to_radians().sin();
        let contact = if s > 0.0 {
            self.contact_margin * depth / s
        } else {
            f64::INFINITY
        };
        self.max_amplitude_m.min(contact)
    }

    /// Angular frequency ω (rad/s).
    pub fn omega(&self) -> f64 {
        TAU * self.frequency_hz
    }

    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.frequency_hz.is_finite() && self.frequency_hz > 0.0) {
            return Err(ConfigError::setting(
                "dither.frequency_hz",
                self.frequency_hz,
                "must be > 0",
            ));
        }
        if !(self.max_amplitude_m.is_finite() && self.max_amplitude_m >= 0.0) {
            return Err(ConfigError::setting(
                "dither.max_amplitude_m",
                self.max_amplitude_m,
                "must be ≥ 0",
            ));
        }
        if !(self.tangent_uncertainty_deg.is_finite()
            && (0.0..90.0).contains(&self.tangent_uncertainty_deg))
        {
            return Err(ConfigError::setting(
                "dither.tangent_uncertainty_deg",
                self.tangent_uncertainty_deg,
                "must lie in [0, 90)",
            ));
        }
        if !(self.contact_margin.is_finite()
            && self.contact_margin > 0.0
            && self.contact_margin <= 1.0)
        {
            return Err(ConfigError::setting(
                "dither.contact_margin",
                self.contact_margin,
                "must lie in (0, 1]",
            ));
        }
        Ok(())
    }
}

/// A running dither oscillator. Amplitude changes keep the phase continuous.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dither {
    omega: f64,
    phase: f64,
    amplitude: f64,
    wrapped: bool,
    /// (sin φ, cos φ), advanced by rotation (no trigonometry per tick).
    sc: (f64, f64),
    /// Rotation per step and the step it was computed for.
    rot: (f64, f64, f64),
}

impl Dither {
    /// An oscillator at `frequency_hz`, amplitude zero, phase zero.
    pub fn new(frequency_hz: f64) -> Self {
        Self {
            omega: TAU * frequency_hz,
            phase: 0.0,
            amplitude: 0.0,
            wrapped: false,
            sc: (0.0, 1.0),
            rot: (0.0, 1.0, 0.0),
        }
    }

    /// Angular frequency ω (rad/s).
    pub fn omega(&self) -> f64 {
        self.omega
    }

    /// Phase ωt in [0, 2π).
    pub fn phase(&self) -> f64 {
        self.phase
    }

    /// Amplitude A (m).
    pub fn amplitude(&self) -> f64 {
        self.amplitude
    }

    /// Characteristic velocity Aω (m/s).
    pub fn velocity_amplitude(&self) -> f64 {
        self.amplitude * self.omega
    }

    /// Sets Aω (m/s), clamped to `[0, bound·ω]`.
    pub fn set_velocity_amplitude(&mut self, a_omega: f64, amplitude_bound: f64) {
        let a = if a_omega.is_finite() {
            a_omega.max(0.0) / self.omega
        } else {
            0.0
        };
        self.amplitude = a.min(amplitude_bound);
    }

    /// Advances by `dt`; returns (displacement A sin φ, velocity Aω cos φ, acceleration
    /// −Aω² sin φ) at the new phase.
    pub fn step(&mut self, dt: f64) -> (f64, f64, f64) {
        self.phase += self.omega * dt;
        self.wrapped = self.phase >= TAU;
        if self.wrapped {
            self.phase -= TAU;
            // Re-synchronise the rotation once per period.
            self.sc = self.phase.sin_cos();
        } else {
            if self.rot.2 != dt {
                let (s, c) = (self.omega * dt).sin_cos();
                self.rot = (s, c, dt);
            }
            let (s0, c0) = self.sc;
            let (sr, cr) = (self.rot.0, self.rot.1);
            let (s1, c1) = (s0 * cr + c0 * sr, c0 * cr - s0 * sr);
            // Keep the pair on the unit circle (first-order correction).
            let k = 1.5 - 0.5 * (s1 * s1 + c1 * c1);
            self.sc = (s1 * k, c1 * k);
        }
        let (s, c) = self.sc;
        let a = self.amplitude;
        (a * s, a * self.omega * c, -a * self.omega * self.omega * s)
    }

    /// True if the last step completed a period.
    pub fn completed_period(&self) -> bool {
        self.wrapped
    }

    /// Its state.
    pub fn state(&self) -> DitherState {
        DitherState {
            phase_rad: self.phase,
            amplitude_m: self.amplitude,
            sin_cos: [self.sc.0, self.sc.1],
            wrapped: u32::from(self.wrapped),
            reserved: 0,
        }
    }

    /// Restores a state taken by [`Dither::state`] (of an oscillator at the same frequency).
    pub fn restore(&mut self, s: &DitherState) {
        self.phase = s.phase_rad;
        self.amplitude = s.amplitude_m;
        self.sc = (s.sin_cos[0], s.sin_cos[1]);
        self.wrapped = s.wrapped != 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn amplitude_bound_keeps_contact() {
        let p = DitherParams::default();
        let b = p.amplitude_bound(2.5, 10e3);
        // 0.8 · 0.25 mm / sin 3° = 3.82 mm → the 3 mm absolute limit applies.
        assert!((b - 3e-3).abs() < 1e-12);
        let p = DitherParams {
            tangent_uncertainty_deg: 10.0,
            ..p
        };
        let b = p.amplitude_bound(2.5, 10e3);
        assert!((b * 10f64.to_radians().sin() - 0.8 * 2.5 / 10e3).abs() < 1e-12);
    }

    /// Over a whole number of periods the dither displacement averages to zero and its velocity
    /// has RMS Aω/√2.
    #[test]
    fn dither_cycle_moments() {
        let mut d = Dither::new(10.0);
        d.set_velocity_amplitude(0.05, 1.0);
        let dt = 1e-4;
        let n = 3000;
        let (mut sd, mut sv2) = (0.0, 0.0);
        for _ in 0..n {
            let (x, v, _) = d.step(dt);
            sd += x;
            sv2 += v * v;
        }
        assert!((sd / n as f64).abs() < 1e-12);
        assert!(((sv2 / n as f64).sqrt() - 0.05 / 2f64.sqrt()).abs() < 1e-9);
        // The rotation recurrence stays on the exact phase.
        let (x, _, _) = d.step(dt);
        assert!((x - d.amplitude() * d.phase().sin()).abs() < 1e-12);
        d.set_velocity_amplitude(f64::NAN, 1.0);
        assert_eq!(d.amplitude(), 0.0);
    }
}
