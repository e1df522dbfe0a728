//! iceoryx2's own publish-subscribe benchmark's method (upstream `benchmarks/publish-subscribe`),
//! as series of `afs bench hop` measured in the same rounds as afs's: two participants pinned
//! to CPUs 0 and 1, two services of byte slices (A → B, B → A) with a subscriber buffer of
//! one and no history, loaned samples (no copy), back to back: A sends and busy-polls for B's
//! answer, B busy-polls and answers; one way = the batch's total time / (2 × its iterations).
//! No clock is read per message. Run as two threads of one process (upstream's set-up) and
//! across afs's two processes (this process and `afs bench-peer`).

use crate::ipc::{self, Svc};
use anyhow::{Context, Result, bail};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use std::sync::Barrier;
use std::time::{Duration, Instant};

/// Payload each way (bytes): a wrench sample's size, as upstream was run here.
pub(super) const PAYLOAD: usize = std::mem::size_of::<afs_shared::msg::WrenchSample>();

const A2B: &str = "afs/bench/upstream_a2b";
const B2A: &str = "afs/bench/upstream_b2a";

/// Longest a participant polls for the other's message before giving up (it died).
const TIMEOUT: Duration = Duration::from_secs(2);

type Factory = PortFactory<Svc, [u8], ()>;

/// The two services.
pub(super) struct Services {
    a2b: Factory,
    b2a: Factory,
}

impl Services {
    /// Opens (or creates) them on `node`: buffer one, no history, safe overflow, room for the
    /// in-process B and the peer's.
    pub(super) fn open(node: &Node<Svc>) -> Result<Self> {
        let open = |name: &str| -> Result<Factory> {
            node.service_builder(&ipc::name(name)?)
                .publish_subscribe::<[u8]>()
                .max_publishers(2)
                .max_subscribers(2)
                .history_size(0)
                .subscriber_max_buffer_size(1)
                .enable_safe_overflow(true)
                .open_or_create()
                .with_context(|| format!("opening {name}"))
        };
        Ok(Self {
            a2b: open(A2B)?,
            b2a: open(B2A)?,
        })
    }
}

/// What a participant does beyond upstream's method, to find where afs's per-message series
/// spend the difference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(super) struct Extra {
    /// Writes the whole payload before sending, reads it all on receipt (upstream sends
    /// uninitialised loans and never reads them: only iceoryx2's own queues cross the cores).
    pub(super) touch: bool,
    /// Reads the monotonic clock before each send and after each receipt, as the per-message
    /// series do to timestamp.
    pub(super) clock: bool,
    /// Polls with a spin-loop hint between attempts (x86's `pause`), as the per-message
    /// series do; upstream polls back to back.
    pub(super) pause: bool,
    /// Loans the message it sends when it sends it, as a servo does and the per-message series
    /// do: upstream loans the next message while it waits (A after its send, B before it polls),
    /// which takes the loan off the measured path.
    pub(super) late_loan: bool,
}

impl Extra {
    /// The ladder of the series: upstream's method, then one more of the per-message series'
    /// habits at each step (touch, clock, pause).
    pub(super) const LADDER: [Extra; 5] = [
        Extra::of_code(0),
        Extra::of_code(1),
        Extra::of_code(3),
        Extra::of_code(7),
        Extra::of_code(15),
    ];

    /// Its code on the peer's control socket (added to the command).
    pub(super) fn code(self) -> u32 {
        u32::from(self.touch)
            + 2 * u32::from(self.clock)
            + 4 * u32::from(self.pause)
            + 8 * u32::from(self.late_loan)
    }

    /// The extra of a code.
    pub(super) const fn of_code(c: u32) -> Self {
        Self {
            touch: c & 1 != 0,
            clock: c & 2 != 0,
            pause: c & 4 != 0,
            late_loan: c & 8 != 0,
        }
    }
}

/// One participant's ports: it sends on one service and receives on the other.
pub(super) struct Participant {
    publisher: Publisher<Svc, [u8], ()>,
    subscriber: Subscriber<Svc, [u8], ()>,
    extra: Extra,
}

impl Participant {
    /// Participant A (sends on A → B) or B.
    pub(super) fn open(s: &Services, a: bool) -> Result<Self> {
        let (out, inp) = if a {
            (&s.a2b, &s.b2a)
        } else {
            (&s.b2a, &s.a2b)
        };
        Ok(Self {
            extra: Extra::default(),
            publisher: out
                .publisher_builder()
                .initial_max_slice_len(PAYLOAD)
                .create()
                .context("upstream method's publisher")?,
            subscriber: inp
                .subscriber_builder()
                .create()
                .context("upstream method's subscriber")?,
        })
    }

    /// The same participant doing `extra` as well.
    pub(super) fn with(self, extra: Extra) -> Self {
        Self { extra, ..self }
    }

    /// Busy-polls for the other's message (a bounded wait: the other may have died); reads
    /// it with [`Extra::touch`], and the clock after it with [`Extra::clock`].
    fn wait(&self) -> Result<()> {
        let t0 = Instant::now();
        let mut n = 0u32;
        loop {
            if let Some(s) = self.subscriber.receive().context("receive")? {
                if self.extra.touch {
                    std::hint::black_box(s.payload().iter().fold(0u8, |a, b| a ^ b));
                }
                if self.extra.clock {
                    std::hint::black_box(crate::rt::monotonic_ns());
                }
                return Ok(());
            }
            n = n.wrapping_add(1);
            if n.is_multiple_of(1 << 16) && t0.elapsed() > TIMEOUT {
                bail!("the other participant did not answer within {TIMEOUT:?}");
            }
            if self.extra.pause {
                std::hint::spin_loop();
            }
        }
    }

    fn loan(&self) -> Result<iceoryx2::sample_mut::SampleMut<Svc, [u8], ()>> {
        let mut s = self.publisher.loan_slice_uninit(PAYLOAD).context("loan")?;
        if self.extra.touch {
            for (i, b) in s.payload_mut().iter_mut().enumerate() {
                b.write(i as u8);
            }
        }
        // SAFETY: a byte payload; what it holds does not matter to the method (upstream sends
        // it uninitialised too); with `touch` every byte is written above.
        Ok(unsafe { s.assume_init() })
    }

    /// Sends `sample`, reading the clock first with [`Extra::clock`].
    fn send(&self, sample: iceoryx2::sample_mut::SampleMut<Svc, [u8], ()>) -> Result<()> {
        if self.extra.clock {
            std::hint::black_box(crate::rt::monotonic_ns());
        }
        sample.send().context("send")?;
        Ok(())
    }

    /// A's side of `n` exchanges: send, loan the next, wait for the answer (with
    /// [`Extra::late_loan`]: loan, send, wait). Returns the total time (ns).
    pub(super) fn run_a(&self, n: u32) -> Result<u64> {
        let t0 = Instant::now();
        if self.extra.late_loan {
            for _ in 0..n {
                self.send(self.loan()?)?;
                self.wait()?;
            }
        } else {
            let mut sample = self.loan()?;
            for _ in 0..n {
                self.send(sample)?;
                sample = self.loan()?;
                self.wait()?;
            }
        }
        Ok(t0.elapsed().as_nanos() as u64)
    }

    /// B's side of `n` exchanges: loan, wait for A's message, answer (with
    /// [`Extra::late_loan`]: wait, loan, answer).
    pub(super) fn run_b(&self, n: u32) -> Result<()> {
        for _ in 0..n {
            if self.extra.late_loan {
                self.wait()?;
                self.send(self.loan()?)?;
            } else {
                let sample = self.loan()?;
                self.wait()?;
                self.send(sample)?;
            }
        }
        Ok(())
    }
}

/// Upstream's set-up: B as a second thread of this process, pinned to `cpu_b`; A is the calling
/// thread. Returns the one-way latency (total / 2n, ns).
pub(super) fn threads(s: &Services, a: &Participant, n: u32, cpu_b: usize) -> Result<f64> {
    let ready = Barrier::new(2);
    std::thread::scope(|sc| {
        let b = sc.spawn(|| -> Result<()> {
            crate::rt::pin_thread(cpu_b, "afs bench");
            let b = Participant::open(s, false);
            ready.wait();
            b?.run_b(n)
        });
        ready.wait();
        let total = a.run_a(n);
        b.join()
            .map_err(|_| anyhow::anyhow!("the upstream method's B thread panicked"))??;
        Ok(total? as f64 / (2.0 * f64::from(n)))
    })
}
