//! Friction at the contact (thesis §4.2–4.4).
//!
//! * [`FrictionLaw`] is the steady sliding law of eq. 4.5: kinetic (Coulomb) + viscous + Stribeck,
//!   `F_f(ẋ) = sgn(ẋ)·(F_t + F_s / (1 + (ẋ/ẋ_s)²)) + F_v·ẋ`, stated at a reference normal force
//!   and scaled linearly with the normal force (Coulomb: `F_t = μ F_N`).
//! * [`FrictionLaw::cycle`] gives the exact statistics of that law over one dither cycle,
//!   `ẋ = ẋ_o + Aω cos ωt` (eq. 4.10): mean, mean square, and their derivatives with respect to
//!   `Aω`, in closed form (complex arithmetic; derivation in `docs/friction-suppression.md`).
//!   It replaces the thesis's power-series approximations (eqs. 4.6, 4.11–4.14, 4.21, 4.24).
//! * [`Presliding`] adds static friction and stick-slip through the elasto-plastic single-state
//!   model of Dupont et al. (2002): the bristle spring of eq. 4.1 deforms purely elastically below
//!   a break-away deflection, so an oscillating sub-break-away load does not make it drift
//!   (LuGre's flaw), and relaxes to the eq. 4.5 level while sliding.
//! * [`RoughnessMap`] lets the coefficients vary along the surface (burrs and rough patches).

use nalgebra::Complex;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Coefficients of eq. 4.5 at a reference normal force.
///
/// Forces in N, velocities in m/s. All coefficients are magnitudes (the thesis prints
/// `F_t = −1.6771` with its sign convention; the kinetic term enters here by magnitude).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FrictionLaw {
    /// Kinetic (Coulomb) level F_t (N).
    pub kinetic_n: f64,
    /// Viscous coefficient F_v (N·s/m).
    pub viscous_n_s_per_m: f64,
    /// Stribeck excess F_s at zero velocity (N).
    pub stribeck_n: f64,
    /// Stribeck characteristic velocity ẋ_s (m/s).
    pub stribeck_velocity_m_per_s: f64,
}

/// Why a friction law or presliding parameter set is rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrictionError {
    /// A coefficient is NaN, infinite or negative.
    #[error("friction coefficient '{name}' = {value} must be finite and non-negative")]
    BadCoefficient {
        /// Field name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// The Stribeck velocity must be strictly positive.
    #[error("stribeck_velocity_m_per_s = {0} must be > 0 (the thesis uses 0.010 m/s)")]
    BadStribeckVelocity(f64),
    /// The break-away ratio must lie in (0, 1).
    #[error("presliding breakaway_ratio = {0} must lie strictly between 0 and 1")]
    BadBreakawayRatio(f64),
}

/// Statistics of the friction force over one dither cycle `ẋ = ẋ_o + a cos θ`, θ uniform.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct CycleStats {
    /// Cycle mean of F_f (N), the thesis's F̄_f.
    pub mean: f64,
    /// Cycle mean of F_f² (N²).
    pub mean_square: f64,
    /// ∂ mean / ∂a (N·s/m).
    pub d_mean_da: f64,
    /// ∂ mean_square / ∂a (N²·s/m).
    pub d_mean_square_da: f64,
}

impl CycleStats {
    /// Standard deviation of F_f over the cycle (N).
    pub fn std(&self) -> f64 {
        (self.mean_square - self.mean * self.mean).max(0.0).sqrt()
    }
}

impl Default for FrictionLaw {
    /// The thesis's coefficients, [`FrictionLaw::THESIS`].
    fn default() -> Self {
        Self::THESIS
    }
}

impl FrictionLaw {
    /// The coefficients the thesis identified (eq. 4.23), read in SI units: F_t = 1.6771 N (by
    /// magnitude), F_v = 0.0976 N·s/m, F_s = 0.54 N, ẋ_s = 10 mm/s. See `docs/friction.md` for why
    /// F_v is read in N·s/m.
    pub const THESIS: FrictionLaw = FrictionLaw {
        kinetic_n: 1.6771,
        viscous_n_s_per_m: 0.0976,
        stribeck_n: 0.54,
        stribeck_velocity_m_per_s: 0.010,
    };

    /// Checks that every coefficient is usable.
    pub fn validate(&self) -> Result<(), FrictionError> {
        for (name, value) in [
            ("kinetic_n", self.kinetic_n),
            ("viscous_n_s_per_m", self.viscous_n_s_per_m),
            ("stribeck_n", self.stribeck_n),
        ] {
            if !value.is_finite() || value < 0.0 {
                return Err(FrictionError::BadCoefficient { name, value });
            }
        }
        let vs = self.stribeck_velocity_m_per_s;
        if !(vs.is_finite() && vs > 0.0) {
            return Err(FrictionError::BadStribeckVelocity(vs));
        }
        Ok(())
    }

    /// The law with every force coefficient multiplied by `scale` (normal-force ratio times the
    /// local roughness factor). The Stribeck velocity is unchanged.
    pub fn scaled(&self, scale: f64) -> FrictionLaw {
        FrictionLaw {
            kinetic_n: self.kinetic_n * scale,
            viscous_n_s_per_m: self.viscous_n_s_per_m * scale,
            stribeck_n: self.stribeck_n * scale,
            stribeck_velocity_m_per_s: self.stribeck_velocity_m_per_s,
        }
    }

    /// The rate-independent part of the sliding level, `F_t + F_s / (1 + (v/ẋ_s)²)` (N), for a
    /// speed `v ≥ 0`. The presliding state relaxes to this deflection force.
    pub fn sliding_level(&self, speed: f64) -> f64 {
        let u = speed / self.stribeck_velocity_m_per_s;
        self.kinetic_n + self.stribeck_n / (1.0 + u * u)
    }

    /// Force needed to start sliding from rest, `F_t + F_s` (N).
    pub fn breakaway(&self) -> f64 {
        self.kinetic_n + self.stribeck_n
    }

    /// Eq. 4.5: the friction resisting a relative velocity `v` (m/s), signed like `v` (N).
    /// The force on the moving body is the negative of this.
    pub fn resistance(&self, v: f64) -> f64 {
        let s = if v > 0.0 {
            1.0
        } else if v < 0.0 {
            -1.0
        } else {
            0.0
        };
        s * self.sliding_level(v.abs()) + self.viscous_n_s_per_m * v
    }

    /// Exact cycle statistics of eq. 4.5 for `ẋ = nominal + a cos θ` (m/s), see [`CycleStats`].
    ///
    /// With `b = ẋ_o/ẋ_s`, `c = a/ẋ_s`, `P = b − i` and `D = √(P−c)·√(P+c)` (principal roots):
    /// the full-cycle mean of `g = 1/(1+(v/ẋ_s)²)` is `Im(1/D)`; with reversal (`a > |ẋ_o|`) the
    /// signed mean of g is `Im Z`, `Z = (4W − π)/(πD)`, `W = atan(R τ)`, `R = √(P−c)/√(P+c)`,
    /// `τ = tan(θ*/2) = √((c+b)/(c−b))`. Full derivation in `docs/friction-suppression.md`.
    pub fn cycle(&self, nominal: f64, a: f64) -> CycleStats {
        let sign = if nominal < 0.0 { -1.0 } else { 1.0 };
        let x = nominal.abs();
        let a = a.abs();
        let (ft, fv, fs) = (self.kinetic_n, self.viscous_n_s_per_m, self.stribeck_n);
        let vs = self.stribeck_velocity_m_per_s;
        if x == 0.0 && a == 0.0 {
            return CycleStats::default();
        }
        let b = x / vs;
        let c = a / vs;
        let p = Complex::new(b, -1.0);
        let sm = (p - c).sqrt();
        let sp = (p + c).sqrt();
        let d = sm * sp;
        let inv_d = d.inv();
        let inv_d3 = inv_d * inv_d * inv_d;
        // Full-cycle means of g and g², and their c-derivatives.
        let e_g = inv_d.im;
        let de_g = (inv_d3 * c).im;
        let e_g2 = 0.5 * inv_d.im - 0.5 * (p * inv_d3).re;
        let de_g2 = 0.5 * (inv_d3 * c).im - 1.5 * (p * c * inv_d3 * inv_d * inv_d).re;
        // Signed quantities: fraction m = E[sgn v], S = E[sgn(v) g], E[|v| g]/ẋ_s, E|v|/ẋ_s.
        let (m, dm, s, ds, evg, devg, eav, deav);
        if c <= b {
            m = 1.0;
            dm = 0.0;
            s = inv_d.im;
            ds = (inv_d3 * c).im;
            evg = inv_d.re;
            devg = (inv_d3 * c).re;
            eav = b;
            deav = 0.0;
        } else {
            let root = (c * c - b * b).sqrt();
            m = 2.0 / PI * (b / c).asin();
            dm = -2.0 / PI * b / (c * root);
            let theta_star = (-b / c).acos();
            let tau = ((c + b) / (c - b)).sqrt();
            let dtau = -b / (tau * (c - b) * (c - b));
            let r = sm / sp;
            let dr = -p / (r * (p + c) * (p + c));
            let rt = r * tau;
            let w = rt.atan();
            let dw = (dr * tau + r * dtau) / (Complex::new(1.0, 0.0) + rt * rt);
            let z = (w * 4.0 - PI) * inv_d / PI;
            let dz = dw * 4.0 * inv_d / PI + (w * 4.0 - PI) * c * inv_d3 / PI;
            s = z.im;
            ds = dz.im;
            evg = z.re;
            devg = dz.re;
            eav = (b * (2.0 * theta_star - PI) + 2.0 * root) / PI;
            deav = 2.0 / PI * root / c;
        }
        let mean = ft * m + fs * s + fv * x;
        // d/da = (1/ẋ_s) d/dc.
        let d_mean_da = (ft * dm + fs * ds) / vs;
        let mean_square = ft * ft
            + 2.0 * ft * fs * e_g
            + fs * fs * e_g2
            + 2.0 * fv * vs * (ft * eav + fs * evg)
            + fv * fv * (x * x + 0.5 * a * a);
        let d_mean_square_da = (2.0 * ft * fs * de_g + fs * fs * de_g2) / vs
            + 2.0 * fv * (ft * deav + fs * devg)
            + fv * fv * a;
        CycleStats {
            mean: sign * mean,
            mean_square,
            d_mean_da: sign * d_mean_da,
            d_mean_square_da,
        }
    }

    /// Cycle mean and mean square of eq. 4.5 by numerical quadrature (composite Gauss–Legendre
    /// in θ on [0, π], split at the velocity reversal θ* = acos(−ẋ_o/a) and graded towards it so
    /// every piece is smooth). An independent check of [`FrictionLaw::cycle`]; slow.
    pub fn cycle_by_quadrature(&self, nominal: f64, a: f64) -> (f64, f64) {
        let gl = crate::math::GaussLegendre::<20>::new();
        let x0 = nominal;
        let f = |th: f64| self.resistance(x0 + a * th.cos());
        let mut mean = 0.0;
        let mut mean_square = 0.0;
        let mut piece = |lo: f64, hi: f64| {
            mean += gl.integrate_composite(lo, hi, 8, f);
            mean_square += gl.integrate_composite(lo, hi, 8, |t| f(t) * f(t));
        };
        if a > x0.abs() {
            let ts = (-x0 / a).acos();
            // Geometric grading towards ts from both sides.
            let mut lo = 0.0;
            let mut h = ts;
            while h > 1e-9 {
                h *= 0.5;
                piece(lo, ts - h);
                lo = ts - h;
            }
            piece(lo, ts);
            let mut hi = PI;
            let mut h = PI - ts;
            while h > 1e-9 {
                h *= 0.5;
                piece(ts + h, hi);
                hi = ts + h;
            }
            piece(ts, hi);
        } else {
            piece(0.0, PI);
        }
        (mean / PI, mean_square / PI)
    }
}

/// Parameters of the presliding (bristle) state: eq. 4.1's spring `F_static = k_fric Δx`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PreslidingParams {
    /// Bristle stiffness k_fric = σ0 (N/m). Presliding deflection at break-away is
    /// `(F_t + F_s)/σ0`, a few µm for metal on metal.
    pub stiffness_n_per_m: f64,
    /// Bristle damping σ1 (N·s/m), acts on the bristle deflection rate only.
    pub damping_n_s_per_m: f64,
    /// Deflection below which the bristle is purely elastic, as a fraction of the sliding
    /// deflection `F_ss(v)/σ0` (Dupont's z_ba / z_ss), in (0, 1).
    pub breakaway_ratio: f64,
}

impl Default for PreslidingParams {
    fn default() -> Self {
        Self {
            stiffness_n_per_m: 4.0e5,
            damping_n_s_per_m: 100.0,
            breakaway_ratio: 0.7,
        }
    }
}

impl PreslidingParams {
    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), FrictionError> {
        for (name, value) in [
            ("presliding.stiffness_n_per_m", self.stiffness_n_per_m),
            ("presliding.damping_n_s_per_m", self.damping_n_s_per_m),
        ] {
            if !value.is_finite() || value < 0.0 {
                return Err(FrictionError::BadCoefficient { name, value });
            }
        }
        if self.stiffness_n_per_m <= 0.0 {
            return Err(FrictionError::BadCoefficient {
                name: "presliding.stiffness_n_per_m",
                value: self.stiffness_n_per_m,
            });
        }
        let r = self.breakaway_ratio;
        if !(r.is_finite() && r > 0.0 && r < 1.0) {
            return Err(FrictionError::BadBreakawayRatio(r));
        }
        Ok(())
    }
}

/// The elasto-plastic presliding state `z` (bristle deflection, m) of one contact.
///
/// `ż = v·(1 − α(z, v)·z/z_ss(v))`, `z_ss = sgn(v)·F_ss(|v|)/σ0`, with α = 0 for
/// `|z| ≤ z_ba` or when z and v have opposite signs (pure elastic: no drift), α = 1 for
/// `|z| ≥ |z_ss|` and a smooth sine blend between. Friction resistance
/// `F = σ0 z + σ1 ż + F_v v`. In steady sliding `F = F_ss(v) + F_v v`, i.e. eq. 4.5.
///
/// One step freezes α and v over `dt` and integrates the linear ODE in z exactly (an
/// exponential), which is stable for any step: the state is stable at the servo rate.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Presliding {
    /// Bristle deflection z (m).
    pub deflection_m: f64,
}

impl Presliding {
    /// Advances the state by `dt` (s) at relative sliding velocity `v` (m/s) under the (already
    /// normal-force-scaled) `law`; returns the friction resistance (N, signed like the
    /// deflection; the force on the moving body is its negative).
    pub fn step(&mut self, law: &FrictionLaw, params: &PreslidingParams, v: f64, dt: f64) -> f64 {
        let sigma0 = params.stiffness_n_per_m;
        let z = self.deflection_m;
        let z_ss = law.sliding_level(v.abs()) / sigma0;
        let z_static = law.breakaway() / sigma0;
        let z_ba = params.breakaway_ratio * z_ss;
        let same_sign = v * z > 0.0;
        let alpha = if !same_sign || z.abs() <= z_ba {
            0.0
        } else if z.abs() >= z_ss {
            1.0
        } else {
            0.5 * (PI * (z.abs() - 0.5 * (z_ss + z_ba)) / (z_ss - z_ba)).sin() + 0.5
        };
        let kappa = if z_ss > 0.0 {
            alpha * v.abs() / z_ss
        } else {
            0.0
        };
        let mut z_new = if kappa * dt > 1e-12 {
            let target = v / kappa;
            target + (z - target) * (-kappa * dt).exp()
        } else {
            z + v * dt
        };
        // A bristle cannot hold more than the break-away force: after a drop of the normal
        // force it slips back to the new limit.
        z_new = z_new.clamp(-z_static, z_static);
        let z_dot = if dt > 0.0 { (z_new - z) / dt } else { 0.0 };
        self.deflection_m = z_new;
        sigma0 * z_new + params.damping_n_s_per_m * z_dot + law.viscous_n_s_per_m * v
    }

    /// Releases the bristle (contact lost).
    pub fn reset(&mut self) {
        self.deflection_m = 0.0;
    }
}

/// One rough patch or burr on the surface: the friction coefficients are multiplied by
/// `1 + gain·cos²(π(u − centre)/(2·half_width))` within `|u − centre| < half_width`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoughnessPatch {
    /// Patch centre along the surface (m, surface coordinate u).
    pub centre_m: f64,
    /// Half width (m).
    pub half_width_m: f64,
    /// Peak relative change of the coefficients (e.g. 0.3 = +30 %, −0.2 = a smoother spot).
    pub gain: f64,
}

/// The friction coefficient multiplier along the surface.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoughnessMap {
    /// The patches; empty means uniform friction.
    pub patches: Vec<RoughnessPatch>,
}

impl RoughnessMap {
    /// A reproducible random set of `count` patches over `[start, start+length]` with widths in
    /// `[0.5, 2]·mean_half_width` and gains uniform in `[−max_gain/2, max_gain]` (mostly burrs).
    pub fn random(
        seed: u64,
        start: f64,
        length: f64,
        count: usize,
        mean_half_width: f64,
        max_gain: f64,
    ) -> Self {
        use rand_chacha::ChaCha8Rng;
        use rand_chacha::rand_core::SeedableRng;
        use rand_distr::{Distribution, Uniform};
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let unit = Uniform::new(0.0f64, 1.0).expect("valid range");
        let patches = (0..count)
            .map(|_| RoughnessPatch {
                centre_m: start + length * unit.sample(&mut rng),
                half_width_m: mean_half_width * (0.5 + 1.5 * unit.sample(&mut rng)),
                gain: max_gain * (1.5 * unit.sample(&mut rng) - 0.5),
            })
            .collect();
        Self { patches }
    }

    /// Coefficient multiplier at surface coordinate `u` (m); never below 0.05.
    pub fn factor(&self, u: f64) -> f64 {
        let mut f = 1.0;
        for p in &self.patches {
            if p.half_width_m <= 0.0 {
                continue;
            }
            let x = (u - p.centre_m) / p.half_width_m;
            if x.abs() < 1.0 {
                let c = (0.5 * PI * x).cos();
                f += p.gain * c * c;
            }
        }
        f.max(0.05)
    }

    /// Mean multiplier over `[u0, u1]` by the midpoint rule on 2000 points.
    pub fn mean_factor(&self, u0: f64, u1: f64) -> f64 {
        if (u1 - u0).abs() < 1e-12 {
            return self.factor(u0);
        }
        let n = 2000;
        (0..n)
            .map(|k| self.factor(u0 + (u1 - u0) * (k as f64 + 0.5) / n as f64))
            .sum::<f64>()
            / n as f64
    }
}

#[cfg(test)]
#[path = "friction_tests.rs"]
mod tests;
