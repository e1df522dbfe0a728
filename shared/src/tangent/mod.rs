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

mod angle;
mod estimate;
mod model;
mod path;
mod plan;
mod rls;
mod stats;
#[cfg(test)]
mod tests;

pub use angle::*;
pub use estimate::*;
pub use model::*;
pub use path::*;
pub use plan::*;
pub use rls::*;
pub use stats::*;
