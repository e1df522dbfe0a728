//! The servo's side of the estimator's tangent service: the probe record copied into a loaned
//! request over several ticks, sent, waited for, re-sent after a time-out, given up after the
//! last attempt. Nothing here allocates or blocks.
//!
//! The service has two forms with the same semantics: iceoryx2 request-response (the
//! default), and a request topic with a response topic matched by request id, which a link to
//! another host can carry (docs/link.md). For the servo a slow or cut link is a slow or dead
//! estimator: the same time-out, retries and give-up.

use crate::ipc::{self, Svc};
use crate::rt;
use afs_shared::msg::{TangentRequestHeader, TangentResponse};
use afs_shared::servo::{ServoCore, ServoMode};
use afs_shared::tangent::ProbeSample;
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::client::Client;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::request_mut_uninit::RequestMutUninit;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use std::mem::MaybeUninit;

pub(super) type TangentClient =
    Client<Svc, [ProbeSample], TangentRequestHeader, TangentResponse, ()>;
type TangentLoan =
    RequestMutUninit<Svc, [MaybeUninit<ProbeSample>], TangentRequestHeader, TangentResponse, ()>;
type TangentPending =
    PendingResponse<Svc, [ProbeSample], TangentRequestHeader, TangentResponse, ()>;
pub(super) type RequestPublisher = Publisher<Svc, [ProbeSample], TangentRequestHeader>;
pub(super) type ResponseSubscriber = Subscriber<Svc, TangentResponse, ()>;
type TopicLoan = SampleMutUninit<Svc, [MaybeUninit<ProbeSample>], TangentRequestHeader>;

/// How the servo reaches the estimator.
pub(super) enum Transport {
    /// iceoryx2 request-response (one host).
    RequestResponse(TangentClient),
    /// A request topic and a response topic (across a link).
    Topics {
        requests: RequestPublisher,
        responses: ResponseSubscriber,
    },
}

/// A request being filled, in either form.
enum Loan {
    Rpc(TangentLoan),
    Topic(TopicLoan),
}

impl Loan {
    fn header_mut(&mut self) -> &mut TangentRequestHeader {
        match self {
            Loan::Rpc(l) => l.user_header_mut(),
            Loan::Topic(l) => l.user_header_mut(),
        }
    }

    fn payload_mut(&mut self) -> &mut [MaybeUninit<ProbeSample>] {
        match self {
            Loan::Rpc(l) => l.payload_mut(),
            Loan::Topic(l) => l.payload_mut(),
        }
    }

    /// Sends it (every element written); the pending response of the request-response form.
    ///
    /// # Safety
    /// Every element of the payload must have been written.
    unsafe fn send(self) -> Result<Option<TangentPending>, ()> {
        match self {
            // SAFETY: the caller wrote every element.
            Loan::Rpc(l) => unsafe { l.assume_init() }.send().map(Some).map_err(|_| ()),
            // SAFETY: the caller wrote every element.
            Loan::Topic(l) => unsafe { l.assume_init() }
                .send()
                .map(|_| None)
                .map_err(|_| ()),
        }
    }
}

/// Samples copied into a request per tick: about 57 kB, a few microseconds.
const COPY_PER_TICK: usize = 1024;

enum Link {
    Idle,
    Copying {
        loan: Loan,
        next: usize,
    },
    Waiting {
        /// None in the topic form: the answer comes on the response topic.
        pending: Option<TangentPending>,
        sent_ns: u64,
    },
}

/// The servo's side of the estimator service: copies the probe record into a loaned request
/// over several ticks, sends it, waits, re-sends after a time-out, gives up after the last
/// attempt.
pub(super) struct EstimatorLink {
    transport: Transport,
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
    /// A link over `transport` that re-sends after `timeout_s` and gives up after `attempts`.
    pub(super) fn new(transport: Transport, timeout_s: f64, attempts: u32) -> Self {
        Self {
            transport,
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
        match &self.transport {
            Transport::RequestResponse(c) => {
                let _ = c.update_connections();
            }
            Transport::Topics {
                requests,
                responses,
            } => {
                let _ = requests.update_connections();
                let _ = responses.update_connections();
            }
        }
    }

    /// Loans a request of `len` samples.
    fn loan(&self, len: usize) -> Option<Loan> {
        match &self.transport {
            Transport::RequestResponse(c) => c.loan_slice_uninit(len).ok().map(Loan::Rpc),
            Transport::Topics { requests, .. } => {
                requests.loan_slice_uninit(len).ok().map(Loan::Topic)
            }
        }
    }

    /// The answer to the request in flight, if it came (older answers are passed over).
    fn answer(&self, pending: Option<&TangentPending>) -> Option<TangentResponse> {
        let mut answer = None;
        match (pending, &self.transport) {
            (Some(p), _) => {
                while let Ok(Some(r)) = p.receive() {
                    if r.payload().request_id == self.request_id {
                        answer = Some(*r.payload());
                    }
                }
            }
            (None, Transport::Topics { responses, .. }) => {
                while let Ok(Some(r)) = responses.receive() {
                    if r.payload().request_id == self.request_id {
                        answer = Some(*r.payload());
                    }
                }
            }
            (None, Transport::RequestResponse(_)) => {}
        }
        answer
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
                match self.loan(len) {
                    Some(mut loan) => {
                        let tangent = req.params;
                        *loan.header_mut() = TangentRequestHeader {
                            version: TangentRequestHeader::VERSION,
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
                    None => Link::Idle,
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
                    loan.header_mut().publish_ns = rt::monotonic_ns();
                    // SAFETY: every element of the slice was written above.
                    match unsafe { loan.send() } {
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
                if let Some(a) = self.answer(pending.as_ref()) {
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
