//! The servo's side of the estimator's tangent service: the probe record copied into a loaned
//! request over several ticks, sent, waited for, re-sent after a time-out, given up after the
//! last attempt. Nothing here allocates or blocks.

use crate::ipc::{self, Svc};
use crate::rt;
use afs_shared::msg::{self, TangentRequestHeader, TangentResponse};
use afs_shared::servo::{ServoCore, ServoMode};
use afs_shared::tangent::ProbeSample;
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::client::Client;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::request_mut_uninit::RequestMutUninit;
use std::mem::MaybeUninit;

pub(super) type TangentClient =
    Client<Svc, [ProbeSample], TangentRequestHeader, TangentResponse, ()>;
type TangentLoan =
    RequestMutUninit<Svc, [MaybeUninit<ProbeSample>], TangentRequestHeader, TangentResponse, ()>;
type TangentPending =
    PendingResponse<Svc, [ProbeSample], TangentRequestHeader, TangentResponse, ()>;

/// Samples copied into a request per tick: about 57 kB, a few microseconds.
const COPY_PER_TICK: usize = 1024;

enum Link {
    Idle,
    Copying {
        loan: TangentLoan,
        next: usize,
    },
    Waiting {
        pending: TangentPending,
        sent_ns: u64,
    },
}

/// The servo's side of the estimator service: copies the probe record into a loaned request
/// over several ticks, sends it, waits, re-sends after a time-out, gives up after the last
/// attempt.
pub(super) struct EstimatorLink {
    client: TangentClient,
    state: Link,
    request_id: u64,
    attempt: u32,
    timeout_ns: u64,
    attempts: u32,
    /// Requests sent.
    pub(super) requests: u64,
    /// Requests re-sent after a time-out.
    pub(super) retries: u64,
    /// Answers received.
    pub(super) answers: u64,
}

impl EstimatorLink {
    /// A link over `client` that re-sends after `timeout_s` and gives up after `attempts`.
    pub(super) fn new(client: TangentClient, timeout_s: f64, attempts: u32) -> Self {
        Self {
            client,
            state: Link::Idle,
            request_id: 0,
            attempt: 0,
            timeout_ns: (timeout_s * 1e9) as u64,
            attempts: attempts.max(1),
            requests: 0,
            retries: 0,
            answers: 0,
        }
    }

    /// No request in flight.
    pub(super) fn is_idle(&self) -> bool {
        matches!(self.state, Link::Idle)
    }

    /// Drops the connections of an estimator that died and connects a restarted one.
    pub(super) fn update_connections(&self) {
        let _ = self.client.update_connections();
    }

    /// Moves the request along by one tick.
    pub(super) fn tick(&mut self, servo: &mut ServoCore, now_ns: u64) {
        if servo.mode() != ServoMode::AwaitingEstimate {
            self.state = Link::Idle;
            self.attempt = 0;
            return;
        }
        let state = std::mem::replace(&mut self.state, Link::Idle);
        self.state = match state {
            Link::Idle => {
                let Some(req) = servo.pending_probe() else {
                    return;
                };
                if self.attempt == 0 {
                    self.request_id += 1;
                }
                let len = req.samples.len().min(ipc::MAX_PROBE_SAMPLES);
                match self.client.loan_slice_uninit(len) {
                    Ok(mut loan) => {
                        let tangent = servo.params().tangent;
                        *loan.user_header_mut() = TangentRequestHeader {
                            version: msg::VERSION,
                            reprobe: u32::from(req.reprobe),
                            request_id: self.request_id,
                            attempt: self.attempt,
                            reserved: 0,
                            publish_ns: 0,
                            base_angle_rad: req.base_angle,
                            plan: req.plan.into(),
                            params: (&tangent).into(),
                        };
                        Link::Copying { loan, next: 0 }
                    }
                    // No memory to loan (should not happen: static allocation): try next tick.
                    Err(_) => Link::Idle,
                }
            }
            Link::Copying { mut loan, next } => {
                let Some(req) = servo.pending_probe() else {
                    return;
                };
                let dst = loan.payload_mut();
                let end = (next + COPY_PER_TICK).min(dst.len());
                for (d, s) in dst[next..end].iter_mut().zip(&req.samples[next..end]) {
                    d.write(*s);
                }
                if end < dst.len() {
                    Link::Copying { loan, next: end }
                } else {
                    loan.user_header_mut().publish_ns = rt::monotonic_ns();
                    // SAFETY: every element of the slice was written above.
                    let request = unsafe { loan.assume_init() };
                    match request.send() {
                        Ok(pending) => {
                            self.requests += 1;
                            Link::Waiting {
                                pending,
                                sent_ns: now_ns,
                            }
                        }
                        Err(_) => Link::Idle,
                    }
                }
            }
            Link::Waiting { pending, sent_ns } => {
                let mut answer = None;
                while let Ok(Some(r)) = pending.receive() {
                    if r.payload().request_id == self.request_id {
                        answer = Some(*r.payload());
                    }
                }
                if let Some(a) = answer {
                    self.answers += 1;
                    self.attempt = 0;
                    match a.to_outcome() {
                        Some(o) => servo.apply_tangent_outcome(&o),
                        // The estimator refused the request: nothing to learn from it.
                        None => servo.give_up_estimate(),
                    }
                    Link::Idle
                } else if now_ns.saturating_sub(sent_ns) > self.timeout_ns {
                    self.attempt += 1;
                    self.retries += 1;
                    if self.attempt >= self.attempts {
                        self.attempt = 0;
                        servo.give_up_estimate();
                    }
                    Link::Idle
                } else {
                    Link::Waiting { pending, sent_ns }
                }
            }
        };
    }
}
