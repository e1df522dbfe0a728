//! The estimator board: a request-response server for tangent estimation and rotation-centre
//! estimation (and the same services as request and response topics, which a link to another
//! host can carry), and the on-line friction identification it publishes at about 1 Hz.
//!
//! Stateless as a server: each request carries the whole probe record, the plan and the
//! settings, so a restarted estimator answers the servo's retry exactly as the first one
//! would have. It runs at normal priority on its own core and polls its ports every
//! millisecond.

use crate::boards::Startup;
use crate::ipc;
use crate::rt;
use afs_shared::ident::IdentTick;
use afs_shared::ident::OnlineFrictionId;
use afs_shared::math::Vec2;
use afs_shared::msg::{
    self, FrictionReport, FrictionStatus, Outcome, RotationRequestHeader, RotationResponse,
    RotationSample, TangentRequestHeader, TangentResponse,
};
use afs_shared::multicontact::estimate_rotation_centre;
use afs_shared::tangent::{self, ProbeSample};
use anyhow::{Context, Result};
use iceoryx2::port::update_connections::UpdateConnections;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// What the board did.
#[derive(Debug, Clone, Copy, Default)]
pub struct EstimatorSummary {
    /// Tangent requests answered.
    pub tangent_requests: u64,
    /// Rotation requests answered.
    pub rotation_requests: u64,
    /// Requests refused as malformed.
    pub bad_requests: u64,
    /// Friction reports published.
    pub friction_reports: u64,
}

/// Runs until `stop` is set; `startup` is the start-up report begun in `main`.
pub fn run(prefix: &str, mut startup: Startup, stop: &AtomicBool) -> Result<EstimatorSummary> {
    let node = ipc::node(prefix, msg::Board::Estimator.name())?;
    startup.report.node_ns = Startup::now();
    let tangent_server = ipc::tangent(&node)?
        .server_builder()
        .create()
        .context("tangent server")?;
    let rotation_server = ipc::rotation(&node)?
        .server_builder()
        .create()
        .context("rotation server")?;
    // The same services as topics, for a servo on another host (docs/link.md): served side by
    // side with the request-response form, the servo's stack file chooses which it uses.
    let tangent_topic = ipc::tangent_requests(&node)?
        .subscriber_builder()
        .create()
        .context("tangent request subscriber")?;
    let tangent_answers = ipc::tangent_responses(&node)?
        .publisher_builder()
        .create()
        .context("tangent response publisher")?;
    let rotation_topic = ipc::rotation_requests(&node)?
        .subscriber_builder()
        .create()
        .context("rotation request subscriber")?;
    let rotation_answers = ipc::rotation_responses(&node)?
        .publisher_builder()
        .create()
        .context("rotation response publisher")?;
    let friction_pub = ipc::friction(&node)?
        .publisher_builder()
        .create()
        .context("friction publisher")?;
    let servo_sub = ipc::servo(&node)?
        .subscriber_builder()
        .buffer_size(ipc::TICK_BUFFER)
        .create()
        .context("servo subscriber")?;
    startup.open(&node)?;
    startup.report.ports_ns = Startup::now();
    // It serves from here on.
    startup.report.data_ns = startup.report.ports_ns;
    startup.send();
    let mut ident = OnlineFrictionId::new(0.2, 0.25, 4096);
    let mut summary = EstimatorSummary::default();
    let mut report = FrictionReport {
        version: msg::FrictionReport::VERSION,
        mu: f64::NAN,
        mu_std: f64::NAN,
        kinetic_n: f64::NAN,
        viscous_n_s_per_m: f64::NAN,
        stribeck_n: f64::NAN,
        stribeck_velocity_m_per_s: f64::NAN,
        rms_residual_n: f64::NAN,
        ..Default::default()
    };
    let mut next_report = rt::monotonic_ns() + 1_000_000_000;
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(1));
        // Drop the connections of clients that died (a killed servo) as soon as iceoryx2 has
        // removed them from the service, and connect new ones; without a change this only
        // compares a counter.
        let _ = tangent_server.update_connections();
        let _ = rotation_server.update_connections();
        let _ = tangent_topic.update_connections();
        let _ = tangent_answers.update_connections();
        let _ = rotation_topic.update_connections();
        let _ = rotation_answers.update_connections();
        startup.update_connections();
        while let Ok(Some(s)) = servo_sub.receive() {
            if s.payload().version == msg::ServoSample::VERSION {
                ident.push(&IdentTick::from(s.payload()));
            }
        }
        while let Ok(Some(req)) = tangent_server.receive() {
            let r = answer_tangent(req.user_header(), req.payload(), &mut summary);
            if req.send_copy(r).is_ok() {
                summary.tangent_requests += 1;
            }
        }
        while let Ok(Some(req)) = tangent_topic.receive() {
            let r = answer_tangent(req.user_header(), req.payload(), &mut summary);
            if tangent_answers.send_copy(r).is_ok() {
                summary.tangent_requests += 1;
            }
        }
        while let Ok(Some(req)) = rotation_server.receive() {
            let r = answer_rotation(req.user_header(), req.payload(), &mut summary);
            if req.send_copy(r).is_ok() {
                summary.rotation_requests += 1;
            }
        }
        while let Ok(Some(req)) = rotation_topic.receive() {
            let r = answer_rotation(req.user_header(), req.payload(), &mut summary);
            if rotation_answers.send_copy(r).is_ok() {
                summary.rotation_requests += 1;
            }
        }
        let now = rt::monotonic_ns();
        if now >= next_report {
            next_report = now + 1_000_000_000;
            let id = ident.report();
            report.seq += 1;
            report.windows = id.windows as u64;
            report.speeds = u32::try_from(id.speeds).unwrap_or(u32::MAX);
            report.status = FrictionStatus::empty();
            if let Some((mu, sd)) = id.mu {
                report.status |= FrictionStatus::MU_VALID;
                report.mu = mu;
                report.mu_std = sd;
            }
            if let Some(f) = id.fit {
                report.status |= FrictionStatus::LAW_VALID;
                report.kinetic_n = f.law.kinetic_n;
                report.viscous_n_s_per_m = f.law.viscous_n_s_per_m;
                report.stribeck_n = f.law.stribeck_n;
                report.stribeck_velocity_m_per_s = f.law.stribeck_velocity_m_per_s;
                report.rms_residual_n = f.rms_residual_n;
            }
            report.publish_ns = now;
            if friction_pub.send_copy(report).is_ok() {
                summary.friction_reports += 1;
            }
        }
    }
    Ok(summary)
}

/// The answer to a tangent request (its header and probe record), stamped; a malformed request
/// gets a refusal and is counted.
fn answer_tangent(
    h: &TangentRequestHeader,
    samples: &[ProbeSample],
    summary: &mut EstimatorSummary,
) -> TangentResponse {
    let answer = if h.version != msg::TangentRequestHeader::VERSION {
        None
    } else {
        match (h.plan.to_plan(), h.params.to_params()) {
            (Some(plan), Ok(params)) if h.base_angle_rad.is_finite() => {
                let outcome =
                    tangent::estimate(samples, &plan, h.base_angle_rad, &params, h.reprobe != 0);
                Some(TangentResponse::from_outcome(h.request_id, &outcome))
            }
            _ => None,
        }
    };
    let mut r = answer.unwrap_or_else(|| {
        summary.bad_requests += 1;
        TangentResponse::bad_request(h.request_id)
    });
    r.publish_ns = rt::monotonic_ns();
    r
}

/// The answer to a rotation request (its header and dither record), stamped; a malformed
/// request gets a refusal and is counted.
fn answer_rotation(
    h: &RotationRequestHeader,
    samples: &[RotationSample],
    summary: &mut EstimatorSummary,
) -> RotationResponse {
    let n = (h.centres as usize).min(msg::MAX_CENTRES);
    let mut r = RotationResponse {
        version: msg::RotationResponse::VERSION,
        request_id: h.request_id,
        outcome: Outcome::BadRequest.into(),
        centre_m: [f64::NAN; 2],
        thesis_centre_m: [f64::NAN; 2],
        response_matrix: [f64::NAN; 4],
        coupling: f64::NAN,
        ..Default::default()
    };
    if h.version == msg::RotationRequestHeader::VERSION && n >= 3 {
        let centres: Vec<Vec2> = h.centre_m[..n]
            .iter()
            .map(|c| Vec2::new(c[0], c[1]))
            .collect();
        let samples: Vec<(usize, f64, f64, Vec2)> = samples
            .iter()
            .map(|s| {
                (
                    s.dither as usize,
                    s.t,
                    s.phase,
                    Vec2::new(s.force_n[0], s.force_n[1]),
                )
            })
            .collect();
        r.outcome = Outcome::Failed.into();
        if let Some(e) =
            estimate_rotation_centre(&centres, &samples, h.amplitude_rad, h.suppression_hz)
        {
            r.outcome = Outcome::Estimate.into();
            r.centre_m = [e.centre.x, e.centre.y];
            if let Some(t) = e.thesis_centre {
                r.thesis_centre_m = [t.x, t.y];
            }
            let a = e.response_matrix;
            r.response_matrix = [a[(0, 0)], a[(0, 1)], a[(1, 0)], a[(1, 1)]];
            r.coupling = e.coupling;
        }
    } else {
        summary.bad_requests += 1;
    }
    r.publish_ns = rt::monotonic_ns();
    r
}
