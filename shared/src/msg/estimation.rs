//! The estimator's services: tangent and rotation-centre requests and responses, and the
//! conversions to and from the core's types, so that both ends use the same code.

use crate::error::ConfigError;
use crate::tangent::{
    MAX_PROBES, ProbePlan, ReprobeReason, TangentError, TangentEstimate, TangentMethod,
    TangentOutcome, TangentParams,
};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

wire_struct! {
    /// The tangent estimator's settings, as sent with each request (the estimator is stateless).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::TangentParamsMsg")]
    pub struct TangentParamsMsg {
        /// Whole periods per probe.
        pub periods: u32,
        /// Padding (0).
        pub reserved: u32,
        /// [`TangentParams::probe_angles_deg`].
        pub probe_angles_deg: [f64; 2],
        /// [`TangentParams::reprobe_angles_deg`].
        pub reprobe_angles_deg: [f64; 2],
        /// [`TangentParams::amplitude_m`].
        pub amplitude_m: f64,
        /// [`TangentParams::frequency_hz`].
        pub frequency_hz: f64,
        /// [`TangentParams::ramp_s`].
        pub ramp_s: f64,
        /// [`TangentParams::settle_s`].
        pub settle_s: f64,
        /// [`TangentParams::sign_threshold`].
        pub sign_threshold: f64,
        /// [`TangentParams::equal_threshold`].
        pub equal_threshold: f64,
        /// [`TangentParams::max_std_error_deg`].
        pub max_std_error_deg: f64,
        /// [`TangentParams::contact_loss_fraction`].
        pub contact_loss_fraction: f64,
        /// [`TangentParams::noise_std_n`].
        pub noise_std_n: f64,
        /// [`TangentParams::design_stiffness_n_per_m`].
        pub design_stiffness_n_per_m: f64,
    }
}

impl From<&TangentParams> for TangentParamsMsg {
    fn from(p: &TangentParams) -> Self {
        Self {
            periods: u32::try_from(p.periods).unwrap_or(u32::MAX),
            reserved: 0,
            probe_angles_deg: p.probe_angles_deg,
            reprobe_angles_deg: p.reprobe_angles_deg,
            amplitude_m: p.amplitude_m,
            frequency_hz: p.frequency_hz,
            ramp_s: p.ramp_s,
            settle_s: p.settle_s,
            sign_threshold: p.sign_threshold,
            equal_threshold: p.equal_threshold,
            max_std_error_deg: p.max_std_error_deg,
            contact_loss_fraction: p.contact_loss_fraction,
            noise_std_n: p.noise_std_n,
            design_stiffness_n_per_m: p.design_stiffness_n_per_m,
        }
    }
}

impl TangentParamsMsg {
    /// Back to the core's settings, checked.
    pub fn to_params(&self) -> Result<TangentParams, ConfigError> {
        let p = TangentParams {
            probe_angles_deg: self.probe_angles_deg,
            reprobe_angles_deg: self.reprobe_angles_deg,
            amplitude_m: self.amplitude_m,
            frequency_hz: self.frequency_hz,
            periods: self.periods as usize,
            ramp_s: self.ramp_s,
            settle_s: self.settle_s,
            sign_threshold: self.sign_threshold,
            equal_threshold: self.equal_threshold,
            max_std_error_deg: self.max_std_error_deg,
            contact_loss_fraction: self.contact_loss_fraction,
            noise_std_n: self.noise_std_n,
            design_stiffness_n_per_m: self.design_stiffness_n_per_m,
        };
        p.validate()?;
        Ok(p)
    }
}

wire_struct! {
    /// A probe plan on the wire.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::ProbePlanMsg")]
    pub struct ProbePlanMsg {
        /// Number of probes (≤ 6).
        pub count: u32,
        /// Whole periods per probe.
        pub periods: u32,
        /// Offsets δα_i from the estimated tangent (rad).
        pub offsets_rad: [f64; MAX_PROBES],
        /// Stroke amplitude (m).
        pub amplitude_m: f64,
        /// Stroke frequency (Hz).
        pub frequency_hz: f64,
        /// Ramp in and out (s).
        pub ramp_s: f64,
        /// Hold before the first probe (s).
        pub settle_s: f64,
        /// Friction-suppression dither frequency during the strokes (Hz, 0: none).
        pub dither_hz: f64,
    }
}

impl From<&ProbePlan> for ProbePlanMsg {
    fn from(p: &ProbePlan) -> Self {
        Self {
            count: u32::try_from(p.count).unwrap_or(u32::MAX),
            periods: u32::try_from(p.periods).unwrap_or(u32::MAX),
            offsets_rad: p.offsets,
            amplitude_m: p.amplitude_m,
            frequency_hz: p.frequency_hz,
            ramp_s: p.ramp_s,
            settle_s: p.settle_s,
            dither_hz: p.dither_hz,
        }
    }
}

impl ProbePlanMsg {
    /// Back to the core's plan; `None` if the numbers cannot be a plan.
    pub fn to_plan(&self) -> Option<ProbePlan> {
        let count = self.count as usize;
        let finite = self.offsets_rad.iter().all(|o| o.is_finite())
            && [
                self.amplitude_m,
                self.frequency_hz,
                self.ramp_s,
                self.settle_s,
                self.dither_hz,
            ]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0);
        (count <= MAX_PROBES && self.periods > 0 && self.frequency_hz > 0.0 && finite).then_some(
            ProbePlan {
                offsets: self.offsets_rad,
                count,
                amplitude_m: self.amplitude_m,
                frequency_hz: self.frequency_hz,
                periods: self.periods as usize,
                ramp_s: self.ramp_s,
                settle_s: self.settle_s,
                dither_hz: self.dither_hz,
            },
        )
    }
}

wire_message! {
    version = 2;
    /// Header of a tangent-estimation request; the payload is the `[ProbeSample]` record.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::TangentRequestHeader.v2")]
    pub struct TangentRequestHeader {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// 1 when the record is a re-probe set.
        pub reprobe: u32,
        /// Identifies the estimation; the same for its retries.
        pub request_id: u64,
        /// 0 for the first send, then 1, 2, … for retries.
        pub attempt: u32,
        /// Padding (0).
        pub reserved: u32,
        /// Monotonic time of sending (ns).
        pub publish_ns: u64,
        /// The estimated tangent angle the offsets refer to (rad, world).
        pub base_angle_rad: f64,
        /// The probes that ran.
        pub plan: ProbePlanMsg,
        /// The estimator's settings.
        pub params: TangentParamsMsg,
    }
}

wire_code! {
    /// [`TangentResponse::outcome`] and [`RotationResponse::outcome`].
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
    #[serde(rename_all = "snake_case")]
    pub enum Outcome {
        /// An estimate.
        Estimate = 0,
        /// Run [`TangentResponse::plan`] and ask again.
        Reprobe = 1,
        /// No trustworthy estimate ([`TangentResponse::code`] says why).
        Failed = 2,
        /// The request itself was malformed.
        BadRequest = 3,
    }
}

wire_code! {
    /// [`TangentResponse::code`]: why a re-probe is asked for, or why the estimation failed.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
    #[serde(rename_all = "snake_case")]
    pub enum ResponseCode {
        /// The probes straddle the tangent (re-probe or unresolved).
        Fold = 1,
        /// The two responses are equal (re-probe or unresolved).
        EqualResponses = 2,
        /// Ambiguous (re-probe or unresolved).
        Ambiguous = 3,
        /// A soft contact: the re-probe's stroke is longer.
        SoftContact = 4,
        /// Contact lost during a probe.
        ContactLost = 10,
        /// Too few samples in a probe.
        MissingData = 11,
        /// The response is below the noise.
        TooNoisy = 12,
        /// The estimate's standard error is beyond the limit.
        Uncertain = 13,
        /// Friction held the tip during a probe.
        Stuck = 14,
    }
}

wire_code! {
    /// [`TangentResponse::method`].
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
    #[serde(rename_all = "snake_case")]
    pub enum MethodCode {
        /// Regression on the measured tip motion.
        MotionRegression = 0,
        /// Ratio of the responses to the commanded strokes.
        CommandedRatio = 1,
        /// The tip's path over the probes.
        TipPath = 2,
    }
}

wire_message! {
    version = 1;
    /// The estimator's answer.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::TangentResponse")]
    pub struct TangentResponse {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// [`Outcome`] as its code.
        pub outcome: u32,
        /// The request's id.
        pub request_id: u64,
        /// Monotonic time of the answer (ns).
        pub publish_ns: u64,
        /// [`ResponseCode`] of a re-probe or failure (0 otherwise).
        pub code: u32,
        /// [`MethodCode`] of an estimate.
        pub method: u32,
        /// Probes used.
        pub probes: u32,
        /// Re-projection iterations.
        pub iterations: u32,
        /// α0 = estimated − true tangent (rad).
        pub alpha0_rad: f64,
        /// Corrected tangent angle (rad, world).
        pub tangent_angle_rad: f64,
        /// Standard error of α0 (rad).
        pub std_error_rad: f64,
        /// Residual RMS (N).
        pub residual_n: f64,
        /// Noise of the in-phase responses (N).
        pub noise_n: f64,
        /// Signal-to-noise ratio.
        pub snr: f64,
        /// Effective contact stiffness (N/m).
        pub stiffness_n_per_m: f64,
        /// Thesis eq. 5.8 cross-check (rad, NaN if none).
        pub thesis_alpha0_rad: f64,
        /// Eq. 6.1 cross-check (rad, NaN if none).
        pub thesis_6_1_alpha0_rad: f64,
        /// Signed-ratio cross-check (rad, NaN if none).
        pub ratio_alpha0_rad: f64,
        /// The two numbers of an error (e.g. probe and force for contact lost).
        pub error_values: [f64; 2],
        /// The re-probe plan.
        pub plan: ProbePlanMsg,
    }
}

impl From<ReprobeReason> for ResponseCode {
    fn from(r: ReprobeReason) -> Self {
        match r {
            ReprobeReason::Fold => ResponseCode::Fold,
            ReprobeReason::EqualResponses => ResponseCode::EqualResponses,
            ReprobeReason::Ambiguous => ResponseCode::Ambiguous,
            ReprobeReason::SoftContact => ResponseCode::SoftContact,
        }
    }
}

impl ResponseCode {
    /// The re-probe reason of a code, if it is one.
    fn reason(self) -> Option<ReprobeReason> {
        match self {
            ResponseCode::Fold => Some(ReprobeReason::Fold),
            ResponseCode::EqualResponses => Some(ReprobeReason::EqualResponses),
            ResponseCode::Ambiguous => Some(ReprobeReason::Ambiguous),
            ResponseCode::SoftContact => Some(ReprobeReason::SoftContact),
            _ => None,
        }
    }
}

impl From<TangentMethod> for MethodCode {
    fn from(m: TangentMethod) -> Self {
        match m {
            TangentMethod::MotionRegression => MethodCode::MotionRegression,
            TangentMethod::CommandedRatio => MethodCode::CommandedRatio,
            TangentMethod::TipPath => MethodCode::TipPath,
        }
    }
}

impl From<MethodCode> for TangentMethod {
    fn from(m: MethodCode) -> Self {
        match m {
            MethodCode::MotionRegression => TangentMethod::MotionRegression,
            MethodCode::CommandedRatio => TangentMethod::CommandedRatio,
            MethodCode::TipPath => TangentMethod::TipPath,
        }
    }
}

fn opt(v: Option<f64>) -> f64 {
    v.unwrap_or(f64::NAN)
}

fn from_opt(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl TangentResponse {
    /// The wire form of an outcome.
    pub fn from_outcome(request_id: u64, o: &TangentOutcome) -> Self {
        let mut r = Self {
            version: Self::VERSION,
            request_id,
            thesis_alpha0_rad: f64::NAN,
            thesis_6_1_alpha0_rad: f64::NAN,
            ratio_alpha0_rad: f64::NAN,
            ..Default::default()
        };
        match o {
            TangentOutcome::Estimate(e) => {
                r.outcome = Outcome::Estimate.into();
                r.method = MethodCode::from(e.method).into();
                r.probes = u32::try_from(e.probes).unwrap_or(u32::MAX);
                r.iterations = u32::try_from(e.iterations).unwrap_or(u32::MAX);
                r.alpha0_rad = e.alpha0_rad;
                r.tangent_angle_rad = e.tangent_angle_rad;
                r.std_error_rad = e.std_error_rad;
                r.residual_n = e.residual_n;
                r.noise_n = e.noise_n;
                r.snr = e.snr;
                r.stiffness_n_per_m = e.stiffness_n_per_m;
                r.thesis_alpha0_rad = opt(e.thesis_alpha0_rad);
                r.thesis_6_1_alpha0_rad = opt(e.thesis_6_1_alpha0_rad);
                r.ratio_alpha0_rad = opt(e.ratio_alpha0_rad);
            }
            TangentOutcome::Reprobe { reason, plan } => {
                r.outcome = Outcome::Reprobe.into();
                r.code = ResponseCode::from(*reason).into();
                r.plan = plan.into();
            }
            TangentOutcome::Failed(err) => {
                r.outcome = Outcome::Failed.into();
                let (code, a, b) = match *err {
                    TangentError::ContactLost { probe, min_n } => {
                        (ResponseCode::ContactLost, probe as f64, min_n)
                    }
                    TangentError::MissingData { probe, samples } => {
                        (ResponseCode::MissingData, probe as f64, samples as f64)
                    }
                    TangentError::TooNoisy { signal_n, noise_n } => {
                        (ResponseCode::TooNoisy, signal_n, noise_n)
                    }
                    TangentError::Uncertain {
                        std_error_deg,
                        limit_deg,
                    } => (ResponseCode::Uncertain, std_error_deg, limit_deg),
                    TangentError::Stuck {
                        probe,
                        travel_fraction,
                    } => (ResponseCode::Stuck, probe as f64, travel_fraction),
                    TangentError::Unresolved(reason) => (reason.into(), 0.0, 0.0),
                };
                r.code = code.into();
                r.error_values = [a, b];
            }
        }
        r
    }

    /// A refusal of a malformed request.
    pub fn bad_request(request_id: u64) -> Self {
        Self {
            version: Self::VERSION,
            outcome: Outcome::BadRequest.into(),
            request_id,
            ..Default::default()
        }
    }

    /// Back to the core's outcome; `None` for a bad request or a malformed answer.
    pub fn to_outcome(&self) -> Option<TangentOutcome> {
        if self.version != Self::VERSION {
            return None;
        }
        let count = |v: f64| {
            if v.is_finite() && v >= 0.0 {
                v as usize
            } else {
                0
            }
        };
        let code = ResponseCode::try_from(self.code);
        Some(match Outcome::try_from(self.outcome).ok()? {
            Outcome::Estimate => {
                if !(self.alpha0_rad.is_finite() && self.tangent_angle_rad.is_finite()) {
                    return None;
                }
                TangentOutcome::Estimate(TangentEstimate {
                    alpha0_rad: self.alpha0_rad,
                    tangent_angle_rad: self.tangent_angle_rad,
                    method: MethodCode::try_from(self.method).ok()?.into(),
                    std_error_rad: self.std_error_rad,
                    residual_n: self.residual_n,
                    noise_n: self.noise_n,
                    snr: self.snr,
                    thesis_alpha0_rad: from_opt(self.thesis_alpha0_rad),
                    thesis_6_1_alpha0_rad: from_opt(self.thesis_6_1_alpha0_rad),
                    ratio_alpha0_rad: from_opt(self.ratio_alpha0_rad),
                    stiffness_n_per_m: self.stiffness_n_per_m,
                    probes: self.probes as usize,
                    iterations: self.iterations as usize,
                })
            }
            Outcome::Reprobe => TangentOutcome::Reprobe {
                reason: code.ok()?.reason()?,
                plan: self.plan.to_plan()?,
            },
            Outcome::Failed => {
                let [a, b] = self.error_values;
                TangentOutcome::Failed(match code.ok()? {
                    ResponseCode::ContactLost => TangentError::ContactLost {
                        probe: count(a),
                        min_n: b,
                    },
                    ResponseCode::MissingData => TangentError::MissingData {
                        probe: count(a),
                        samples: count(b),
                    },
                    ResponseCode::TooNoisy => TangentError::TooNoisy {
                        signal_n: a,
                        noise_n: b,
                    },
                    ResponseCode::Uncertain => TangentError::Uncertain {
                        std_error_deg: a,
                        limit_deg: b,
                    },
                    ResponseCode::Stuck => TangentError::Stuck {
                        probe: count(a),
                        travel_fraction: b,
                    },
                    c => TangentError::Unresolved(c.reason()?),
                })
            }
            Outcome::BadRequest => return None,
        })
    }
}

wire_message! {
    version = 1;
    /// One wrench sample of a rotational dither (rotation-centre request payload).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::RotationSample")]
    pub struct RotationSample {
        /// Time (s).
        pub t: f64,
        /// Dither phase φ (rad): the commanded rotation is A sin φ.
        pub phase: f64,
        /// Measured force (N, world).
        pub force_n: [f64; 2],
        /// Which dither centre (index into the header's centres).
        pub dither: u32,
        /// Padding (0).
        pub reserved: u32,
    }
}

/// Most dither centres a rotation request can carry.
pub const MAX_CENTRES: usize = 6;

wire_message! {
    version = 1;
    /// Header of a rotation-centre request; the payload is `[RotationSample]`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::RotationRequestHeader")]
    pub struct RotationRequestHeader {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// Number of dither centres (3 to 6).
        pub centres: u32,
        /// Request id.
        pub request_id: u64,
        /// Monotonic time of sending (ns).
        pub publish_ns: u64,
        /// Dither centres (m, world).
        pub centre_m: [[f64; 2]; MAX_CENTRES],
        /// Dither amplitude (rad).
        pub amplitude_rad: f64,
        /// Friction-suppression dither superposed (Hz, 0: none), removed before the lock-in.
        pub suppression_hz: f64,
    }
}

wire_message! {
    version = 1;
    /// The rotation-centre answer.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::RotationResponse")]
    pub struct RotationResponse {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// [`Outcome`] as its code: estimate, failed (singular or too few samples), bad request.
        pub outcome: u32,
        /// The request's id.
        pub request_id: u64,
        /// Monotonic time of the answer (ns).
        pub publish_ns: u64,
        /// Instantaneous centre of rotation P (m, world).
        pub centre_m: [f64; 2],
        /// The thesis's unsigned form (NaN if it found none).
        pub thesis_centre_m: [f64; 2],
        /// Fitted response matrix A = ∂g/∂c, row-major (N per m per rad).
        pub response_matrix: [f64; 4],
        /// |diagonal| / |off-diagonal| of A.
        pub coupling: f64,
    }
}

#[cfg(test)]
#[path = "estimation_tests.rs"]
mod tests;
