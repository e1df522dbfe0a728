//! On-line dither tuning (thesis §4.4, §4.5.2), the fast-loop part.
//!
//! Two tuners adjust the characteristic velocity `a = Aω` from the measured tangential force:
//!
//! * [`ThesisTuner`] runs the thesis's law as the thesis runs it: eq. 4.22,
//!   `Δ(Aω) = −η F_f (F_v/2 − F_s Aω/(2ẋ_s²))`, on the instantaneous friction force, with the
//!   Stribeck velocity re-estimated every tick from the force variance over a 250 ms traveling
//!   window through eq. 4.24 (in its corrected form, [`power_series_variance`]).
//!   Its stationary point (eq. 4.18) is the *maximum* of the approximated friction 4.21, so the
//!   law drives Aω away from it: upward whenever it starts above it, and on until the amplitude
//!   bound, because the friction it multiplies never changes sign on average.
//! * [`CostTuner`] minimises a well-posed cost, the thesis's own aim in §4.4 (mean *and*
//!   standard deviation of the tangential force): `J(a) = F̄(a)² + λ·σ(a)²`, where σ includes the
//!   oscillation the dither itself causes (friction reversal and the tool's inertial force the
//!   sensor sees, `m_tool ω a/√2`). F̄ and σ come from the exact cycle statistics of eq. 4.5
//!   ([`FrictionLaw::cycle`]). Because any such cost rises for `a < ẋ_o` (dither below the
//!   nominal velocity adds oscillation but removes no mean friction), `J` has a local minimum
//!   at `a = 0`; a gradient method started at 0.2·ẋ_o would switch the dither off. The tuner
//!   therefore minimises the model cost globally over the admissible range, corrects the model
//!   from measurements (the ẋ_o and Aω the contact actually saw, the friction level) once per
//!   dither period, and moves Aω towards the minimiser at a bounded rate.
//!
//! Derivations in `docs/friction-suppression.md`.

use crate::error::ConfigError;
use crate::friction::FrictionLaw;
use crate::math::grid_then_golden;
use crate::window::{PeriodStats, PeriodWindow, PeriodWindowState, SlidingSummary, SlidingWindow};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::{Deserialize, Serialize};

wire_struct! {
    /// A [`Tuner`]'s state, for a snapshot (the fields of the configured tuner; the others 0).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::TunerState")]
    pub struct TunerState {
        /// Aω (m/s).
        pub a_omega_m_per_s: f64,
        /// Thesis tuner: the Stribeck velocity estimate (m/s).
        pub stribeck_velocity_estimate_m_per_s: f64,
        /// Cost tuner: the measured dither transmission.
        pub transmission: f64,
        /// Cost tuner: the friction-level correction.
        pub friction_scale: f64,
        /// Thesis tuner: its friction window, in brief.
        pub window: SlidingSummary,
        /// Cost tuner: its period window.
        pub periods: PeriodWindowState,
    }
}

/// Settings of the thesis tuner (a).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ThesisTunerParams {
    /// Learning rate η of eq. 4.22, per second of servo time ((m/s) per N²·s/m per s).
    pub learning_rate: f64,
    /// Length of the traveling window for the force variance (s); thesis: 0.25.
    pub window_s: f64,
}

impl Default for ThesisTunerParams {
    fn default() -> Self {
        Self {
            learning_rate: 2e-3,
            window_s: 0.25,
        }
    }
}

/// Settings of the cost tuner (b).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CostTunerParams {
    /// Weight λ of the oscillation (σ²) against the mean friction (F̄²), in (0, 1].
    pub oscillation_weight: f64,
    /// Whole dither periods per statistics window.
    pub periods: usize,
    /// Largest change of ln(Aω) per update (one dither period).
    pub max_log_step: f64,
    /// Gain (0–1) of the per-update model corrections.
    pub adapt_gain: f64,
}

impl Default for CostTunerParams {
    fn default() -> Self {
        Self {
            oscillation_weight: 0.5,
            periods: 3,
            max_log_step: 0.2,
            adapt_gain: 0.5,
        }
    }
}

/// Which tuner runs in the fast loop.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum TunerConfig {
    /// No tuning: Aω stays where it is set.
    Fixed,
    /// The thesis's law (eq. 4.22 with eq. 4.24).
    Thesis(ThesisTunerParams),
    /// The well-posed cost tuner.
    Cost(CostTunerParams),
}

impl Default for TunerConfig {
    fn default() -> Self {
        TunerConfig::Cost(CostTunerParams::default())
    }
}

impl TunerConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ConfigError> {
        match self {
            TunerConfig::Fixed => Ok(()),
            TunerConfig::Thesis(p) => {
                if !(p.learning_rate.is_finite() && p.learning_rate >= 0.0) {
                    return Err(ConfigError::setting(
                        "tuner.learning_rate",
                        p.learning_rate,
                        "must be ≥ 0",
                    ));
                }
                if !(p.window_s.is_finite() && p.window_s > 0.0 && p.window_s <= 10.0) {
                    return Err(ConfigError::setting(
                        "tuner.window_s",
                        p.window_s,
                        "must lie in (0, 10]",
                    ));
                }
                Ok(())
            }
            TunerConfig::Cost(p) => {
                if !(p.oscillation_weight.is_finite()
                    && p.oscillation_weight > 0.0
                    && p.oscillation_weight <= 1.0)
                {
                    return Err(ConfigError::setting(
                        "tuner.oscillation_weight",
                        p.oscillation_weight,
                        "must lie in (0, 1]",
                    ));
                }
                if p.periods == 0 || p.periods > crate::window::MAX_PERIODS {
                    return Err(ConfigError::setting(
                        "tuner.periods",
                        p.periods as f64,
                        format!("must lie in 1..={}", crate::window::MAX_PERIODS),
                    ));
                }
                if !(p.max_log_step.is_finite() && p.max_log_step > 0.0) {
                    return Err(ConfigError::setting(
                        "tuner.max_log_step",
                        p.max_log_step,
                        "must be > 0",
                    ));
                }
                if !(p.adapt_gain.is_finite() && p.adapt_gain > 0.0 && p.adapt_gain <= 1.0) {
                    return Err(ConfigError::setting(
                        "tuner.adapt_gain",
                        p.adapt_gain,
                        "must lie in (0, 1]",
                    ));
                }
                Ok(())
            }
        }
    }
}

/// What every tuner knows about the task.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TunerContext {
    /// Friction model (previously identified, eq. 4.23) at the reference normal force.
    pub law: FrictionLaw,
    /// Dither angular frequency ω (rad/s).
    pub omega: f64,
    /// Servo period (s).
    pub dt: f64,
    /// Smallest Aω the tuner commands (m/s).
    pub a_min: f64,
    /// Largest Aω the tuner commands (m/s): the amplitude bound times ω.
    pub a_max: f64,
    /// Mass of the tool beyond the sensor (kg).
    pub tool_mass_kg: f64,
}

/// One tick's measurements for a tuner.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TunerInput {
    /// Friction force resisting the nominal motion, normalised to the reference normal force (N).
    pub friction_n: f64,
    /// Tip velocity along the tangent, positive in the nominal direction (m/s).
    pub velocity_m_per_s: f64,
    /// Commanded nominal velocity magnitude ẋ_o (m/s).
    pub nominal_m_per_s: f64,
    /// Dither phase (rad).
    pub phase: f64,
    /// True on the tick that completes a dither period.
    pub period_end: bool,
    /// Measured normal force (N).
    pub normal_n: f64,
}

/// What a tuner reports (JSON).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct TunerReport {
    /// Commanded Aω (m/s).
    pub a_omega_m_per_s: f64,
    /// Thesis tuner: the current Stribeck-velocity estimate ẋ̂_s (m/s).
    pub stribeck_velocity_estimate_m_per_s: f64,
    /// Thesis tuner: the stationary point of eq. 4.22, F_v ẋ̂_s²/F_s (m/s) (eq. 4.18, corrected
    /// units); the law moves away from it.
    pub thesis_stationary_point_m_per_s: f64,
    /// Cost tuner: the model's minimiser a* of J, in contact velocity (m/s).
    pub cost_minimiser_m_per_s: f64,
    /// Cost tuner: J at a* (N²).
    pub cost_at_minimiser: f64,
    /// Cost tuner: dJ/da at a* (N²·s/m); ≈ 0 at an interior minimum.
    pub cost_gradient_at_minimiser: f64,
    /// Cost tuner: measured transmission (contact Aω / commanded Aω).
    pub transmission: f64,
    /// Cost tuner: friction-level correction of the model.
    pub friction_scale: f64,
    /// Last whole-period statistics (cost tuner).
    pub window: PeriodStats,
    /// True when Aω sits at its upper bound.
    pub at_upper_bound: bool,
}

/// Eq. 4.24, corrected: the variance of eq. 4.5 with the power-series Stribeck term (eq. 4.6)
/// over a dither cycle with `x0 > a` (no reversal):
/// `σ² = ½ (F_v − 2F_s ẋ_o/ẋ_s²)² a² + F_s² a⁴ / (8 ẋ_s⁴)`.
pub fn power_series_variance(law: &FrictionLaw, x0: f64, a: f64) -> f64 {
    let u = 1.0 / law.stribeck_velocity_m_per_s.powi(2);
    let lin = law.viscous_n_s_per_m - 2.0 * law.stribeck_n * x0 * u;
    0.5 * lin * lin * a * a + law.stribeck_n.powi(2) * u * u * a.powi(4) / 8.0
}

/// Inverts [`power_series_variance`] for ẋ_s given a measured variance: the positive root
/// `u = 1/ẋ_s²` of `F_s² a²(2ẋ_o² + a²/8) u² − 2F_vF_s ẋ_o a² u + ½F_v²a² − σ² = 0` (the larger
/// one). `None` when there is no positive root.
pub fn stribeck_velocity_from_variance(
    variance: f64,
    x0: f64,
    a: f64,
    fv: f64,
    fs: f64,
) -> Option<f64> {
    let a2 = fs * fs * a * a * (2.0 * x0 * x0 + a * a / 8.0);
    let a1 = -2.0 * fv * fs * x0 * a * a;
    let a0 = 0.5 * fv * fv * a * a - variance;
    if a2.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let disc = a1 * a1 - 4.0 * a2 * a0;
    if disc < 0.0 {
        return None;
    }
    let u = (-a1 + disc.sqrt()) / (2.0 * a2);
    if u > 0.0 && u.is_finite() {
        Some(1.0 / u.sqrt())
    } else {
        None
    }
}

/// ∂J/∂(Aω) of the thesis's approximated cost `J = ½F_f²` with eq. 4.21,
/// `F_f = λ + F_v a/2 − F_s a²/(4ẋ_s²)`: `F_f (F_v/2 − F_s a/(2ẋ_s²))` (eq. 4.22 without −η).
pub fn thesis_gradient(friction: f64, fv: f64, fs: f64, xs: f64, a: f64) -> f64 {
    friction * (0.5 * fv - fs * a / (2.0 * xs * xs))
}

/// The cost tuner's model cost `J(a) = (1−λ)F̄² + λ(E[F²] + (m ω a)²/2)`, which is
/// `F̄² + λσ²` with `σ² = E[F²] − F̄² + (m ω a)²/2`, and its derivative dJ/da.
pub fn cost_and_gradient(
    law: &FrictionLaw,
    x0: f64,
    a: f64,
    weight: f64,
    tool_mass: f64,
    omega: f64,
) -> (f64, f64) {
    let st = law.cycle(x0, a);
    let k = tool_mass * omega;
    let j = (1.0 - weight) * st.mean * st.mean + weight * (st.mean_square + 0.5 * k * k * a * a);
    let dj =
        2.0 * (1.0 - weight) * st.mean * st.d_mean_da + weight * (st.d_mean_square_da + k * k * a);
    (j, dj)
}

/// The thesis's tuner (a).
#[derive(Debug, Clone)]
pub struct ThesisTuner {
    params: ThesisTunerParams,
    window: SlidingWindow,
    a: f64,
    xs_hat: f64,
}

impl ThesisTuner {
    /// Starts at `a0` (m/s).
    pub fn new(params: ThesisTunerParams, ctx: &TunerContext, a0: f64) -> Self {
        let n = (params.window_s / ctx.dt).round().max(1.0) as usize;
        Self {
            params,
            window: SlidingWindow::new(n),
            a: a0,
            xs_hat: ctx.law.stribeck_velocity_m_per_s,
        }
    }

    fn update(&mut self, ctx: &TunerContext, inp: &TunerInput) -> f64 {
        let law = &ctx.law;
        self.window.push(inp.friction_n);
        if self.window.len() * 2 >= self.window.capacity()
            && let Some(xs) = stribeck_velocity_from_variance(
                self.window.variance(),
                inp.nominal_m_per_s,
                self.a,
                law.viscous_n_s_per_m,
                law.stribeck_n,
            )
        {
            let x_id = law.stribeck_velocity_m_per_s;
            self.xs_hat = xs.clamp(0.1 * x_id, 10.0 * x_id);
        }
        let grad = thesis_gradient(
            inp.friction_n,
            law.viscous_n_s_per_m,
            law.stribeck_n,
            self.xs_hat,
            self.a,
        );
        let next = self.a - self.params.learning_rate * ctx.dt * grad;
        if next.is_finite() {
            self.a = next.clamp(ctx.a_min, ctx.a_max);
        }
        self.a
    }

    fn report(&self, ctx: &TunerContext) -> TunerReport {
        let law = &ctx.law;
        TunerReport {
            a_omega_m_per_s: self.a,
            stribeck_velocity_estimate_m_per_s: self.xs_hat,
            thesis_stationary_point_m_per_s: law.viscous_n_s_per_m * self.xs_hat * self.xs_hat
                / law.stribeck_n.max(1e-12),
            at_upper_bound: self.a >= ctx.a_max * (1.0 - 1e-9),
            ..Default::default()
        }
    }
}

/// The cost tuner (b).
#[derive(Debug, Clone)]
pub struct CostTuner {
    params: CostTunerParams,
    window: PeriodWindow,
    a: f64,
    transmission: f64,
    scale: f64,
    report: TunerReport,
}

impl CostTuner {
    /// Starts at `a0` (m/s).
    pub fn new(params: CostTunerParams, a0: f64) -> Self {
        Self {
            params,
            window: PeriodWindow::new(params.periods),
            a: a0,
            transmission: 1.0,
            scale: 1.0,
            report: TunerReport {
                transmission: 1.0,
                friction_scale: 1.0,
                ..Default::default()
            },
        }
    }

    fn update(&mut self, ctx: &TunerContext, inp: &TunerInput) -> f64 {
        self.window.push(
            inp.friction_n,
            inp.velocity_m_per_s,
            inp.phase,
            inp.normal_n,
            self.a,
        );
        if !inp.period_end {
            return self.a;
        }
        let Some(stats) = self.window.end_period() else {
            return self.a;
        };
        let p = self.params;
        let g = p.adapt_gain;
        let x0 = if stats.mean_velocity_m_per_s > 0.0 {
            stats.mean_velocity_m_per_s
        } else {
            inp.nominal_m_per_s
        };
        // Measured transmission of the dither to the contact.
        let a_cmd = stats.commanded_a_omega_m_per_s;
        if a_cmd > 0.05 * x0.max(1e-6) {
            let ratio = (stats.dither_velocity_m_per_s / a_cmd).clamp(0.2, 1.5);
            self.transmission += g * (ratio - self.transmission);
        }
        // Friction-level correction (rough patches, normal-force changes).
        let model_mean = ctx.law.cycle(x0, stats.dither_velocity_m_per_s).mean;
        if model_mean > 0.05 * ctx.law.kinetic_n && stats.mean_force_n.is_finite() {
            let ratio = (stats.mean_force_n / model_mean).clamp(0.3, 3.0);
            self.scale += g * (ratio - self.scale);
        }
        let law = ctx.law.scaled(self.scale);
        let cost = |a: f64| {
            cost_and_gradient(
                &law,
                x0,
                a,
                p.oscillation_weight,
                ctx.tool_mass_kg,
                ctx.omega,
            )
            .0
        };
        let a_hi = (self.transmission * ctx.a_max).max(1e-9);
        let (mut a_star, mut j_star) = grid_then_golden(a_hi * 1e-3, a_hi, 48, 40, cost);
        let j0 = cost(0.0);
        if j0 < j_star {
            a_star = 0.0;
            j_star = j0;
        }
        let target = (a_star / self.transmission).clamp(ctx.a_min, ctx.a_max);
        let current = self.a.max(ctx.a_min).max(1e-9);
        let step = (target.max(1e-9) / current)
            .ln()
            .clamp(-p.max_log_step, p.max_log_step);
        self.a = (current * step.exp()).clamp(ctx.a_min, ctx.a_max);
        let (_, grad) = cost_and_gradient(
            &law,
            x0,
            a_star,
            p.oscillation_weight,
            ctx.tool_mass_kg,
            ctx.omega,
        );
        self.report = TunerReport {
            a_omega_m_per_s: self.a,
            cost_minimiser_m_per_s: a_star,
            cost_at_minimiser: j_star,
            cost_gradient_at_minimiser: grad,
            transmission: self.transmission,
            friction_scale: self.scale,
            window: stats,
            at_upper_bound: self.a >= ctx.a_max * (1.0 - 1e-9),
            ..Default::default()
        };
        self.a
    }
}

/// A running tuner. The thesis tuner owns its 250 ms sample window on the heap (allocated once
/// at construction), so the variants differ in inline size only by a few words.
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)]
pub enum Tuner {
    /// Aω held.
    Fixed(f64),
    /// Thesis law.
    Thesis(ThesisTuner),
    /// Cost tuner.
    Cost(CostTuner),
}

impl Tuner {
    /// Builds the configured tuner starting at `a0` (m/s).
    pub fn new(config: &TunerConfig, ctx: &TunerContext, a0: f64) -> Self {
        match config {
            TunerConfig::Fixed => Tuner::Fixed(a0),
            TunerConfig::Thesis(p) => Tuner::Thesis(ThesisTuner::new(*p, ctx, a0)),
            TunerConfig::Cost(p) => Tuner::Cost(CostTuner::new(*p, a0)),
        }
    }

    /// One fast-loop tick; returns the Aω to command (m/s).
    pub fn update(&mut self, ctx: &TunerContext, inp: &TunerInput) -> f64 {
        match self {
            Tuner::Fixed(a) => *a,
            Tuner::Thesis(t) => t.update(ctx, inp),
            Tuner::Cost(t) => t.update(ctx, inp),
        }
    }

    /// Overrides the current Aω (m/s), e.g. to restart tuning.
    pub fn set(&mut self, a: f64) {
        match self {
            Tuner::Fixed(x) => *x = a,
            Tuner::Thesis(t) => t.a = a,
            Tuner::Cost(t) => t.a = a,
        }
    }

    /// Its state.
    pub fn state(&self) -> TunerState {
        match self {
            Tuner::Fixed(a) => TunerState {
                a_omega_m_per_s: *a,
                ..Default::default()
            },
            Tuner::Thesis(t) => TunerState {
                a_omega_m_per_s: t.a,
                stribeck_velocity_estimate_m_per_s: t.xs_hat,
                window: t.window.summary(),
                ..Default::default()
            },
            Tuner::Cost(t) => TunerState {
                a_omega_m_per_s: t.a,
                transmission: t.transmission,
                friction_scale: t.scale,
                periods: t.window.state(),
                ..Default::default()
            },
        }
    }

    /// Restores a state taken by [`Tuner::state`] of a tuner of the same kind (the thesis
    /// tuner's window comes back in brief, [`SlidingWindow::refill`]).
    pub fn restore(&mut self, s: &TunerState) {
        match self {
            Tuner::Fixed(a) => *a = s.a_omega_m_per_s,
            Tuner::Thesis(t) => {
                t.a = s.a_omega_m_per_s;
                t.xs_hat = s.stribeck_velocity_estimate_m_per_s;
                t.window.refill(&s.window);
            }
            Tuner::Cost(t) => {
                t.a = s.a_omega_m_per_s;
                t.transmission = s.transmission;
                t.scale = s.friction_scale;
                t.window.restore(&s.periods);
            }
        }
    }

    /// The tuner's state for reports.
    pub fn report(&self, ctx: &TunerContext) -> TunerReport {
        match self {
            Tuner::Fixed(a) => TunerReport {
                a_omega_m_per_s: *a,
                ..Default::default()
            },
            Tuner::Thesis(t) => t.report(ctx),
            Tuner::Cost(t) => TunerReport {
                a_omega_m_per_s: t.a,
                ..t.report
            },
        }
    }

    /// Short name.
    pub fn name(&self) -> &'static str {
        match self {
            Tuner::Fixed(_) => "fixed",
            Tuner::Thesis(_) => "thesis",
            Tuner::Cost(_) => "cost",
        }
    }
}

#[cfg(test)]
#[path = "tuner_tests.rs"]
mod tests;
