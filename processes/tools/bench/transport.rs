//! The hop benchmark's transports: the atomic shared-memory page, the afs and bare iceoryx2
//! ports, the Unix socket's control protocol, one round trip on each, and the peer's side.

use crate::ipc::{self, Svc};
use crate::rt;
use afs_shared::msg::{ServoSample, WrenchSample};
use afs_shared::watchdog::{GateParams, SampleGate};
use anyhow::{Context, Result, bail};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Transports of the hop benchmark, in round order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub(super) enum Transport {
    Atomic = 0,
    AfsPoll = 1,
    AfsEvent = 2,
    BarePoll = 3,
    Uds = 4,
}

pub(super) const TRANSPORTS: [Transport; 5] = [
    Transport::Atomic,
    Transport::AfsPoll,
    Transport::AfsEvent,
    Transport::BarePoll,
    Transport::Uds,
];

/// Control command that ends the peer.
pub(super) const QUIT: u32 = u32::MAX;

/// Control command: be participant B of upstream's method for `count` exchanges (plus the code
/// of its `Extra`, 0 to 15).
pub(super) const UPSTREAM: u32 = 100;

/// Size of the ping (the wrench sample's) and of the pong (the servo sample's).
pub(super) const PING: usize = std::mem::size_of::<WrenchSample>();
pub(super) const PONG: usize = std::mem::size_of::<ServoSample>();

/// Longest wait for the peer's answer before the benchmark gives up.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(2);

const BARE_PING: &str = "afs/bench/bare_ping";
const BARE_PONG: &str = "afs/bench/bare_pong";
const EVENT_PING: &str = "afs/bench/ping_event";
const EVENT_PONG: &str = "afs/bench/pong_event";

/// The shared-memory page of the atomic ping-pong: a sequence number and a payload each way,
/// on separate cache lines.
pub(super) struct AtomicPage {
    ptr: *mut u8,
    path: PathBuf,
    owner: bool,
}

const PAGE: usize = 4096;
const PING_SEQ: usize = 0;
const PING_DATA: usize = 64;
const PONG_SEQ: usize = 512;
const PONG_DATA: usize = 576;

impl AtomicPage {
    fn path(prefix: &str) -> PathBuf {
        PathBuf::from(format!("/dev/shm/{}bench_atomic", ipc::file_prefix(prefix)))
    }

    pub(super) fn open(prefix: &str, create: bool) -> Result<Self> {
        let path = Self::path(prefix);
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(create)
            .truncate(create)
            .open(&path)
            .with_context(|| format!("opening {}", path.display()))?;
        if create {
            f.set_len(PAGE as u64)
                .with_context(|| format!("sizing {}", path.display()))?;
        }
        use std::os::fd::AsRawFd;
        // SAFETY: maps PAGE bytes of a file we hold open and sized; checked for MAP_FAILED.
        let ptr = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                PAGE,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                f.as_raw_fd(),
                0,
            )
        };
        if ptr == libc::MAP_FAILED {
            bail!(
                "mapping {}: {}",
                path.display(),
                std::io::Error::last_os_error()
            );
        }
        Ok(Self {
            ptr: ptr.cast(),
            path,
            owner: create,
        })
    }

    fn seq(&self, at: usize) -> &AtomicU64 {
        // SAFETY: `at` is 8-byte aligned inside the page-aligned mapping, which lives as long
        // as self; both processes access it only through atomics.
        unsafe { &*(self.ptr.add(at) as *const AtomicU64) }
    }

    fn write(&self, at: usize, data: &[u8]) {
        // SAFETY: in bounds (at + len ≤ PAGE); the reader reads only after the Release store
        // of the sequence number that follows.
        unsafe { std::ptr::copy_nonoverlapping(data.as_ptr(), self.ptr.add(at), data.len()) }
    }

    fn read(&self, at: usize, data: &mut [u8]) {
        // SAFETY: in bounds; read after the Acquire load that saw the writer's sequence number.
        unsafe { std::ptr::copy_nonoverlapping(self.ptr.add(at), data.as_mut_ptr(), data.len()) }
    }
}

impl Drop for AtomicPage {
    fn drop(&mut self) {
        // SAFETY: unmaps the mapping made in open.
        unsafe {
            libc::munmap(self.ptr.cast(), PAGE);
        }
        if self.owner {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Ports of one side of the hop benchmark.
pub(super) struct Ports {
    afs_wrench_pub: Publisher<Svc, WrenchSample, ()>,
    afs_servo_sub: Subscriber<Svc, ServoSample, ()>,
    bare_pub: Publisher<Svc, [u8; PING], ()>,
    bare_sub: Subscriber<Svc, [u8; PONG], ()>,
    notifier: Notifier<Svc>,
    listener: Listener<Svc>,
}

fn bare_ping(
    node: &Node<Svc>,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, [u8; PING], ()>> {
    node.service_builder(&ipc::name(BARE_PING)?)
        .publish_subscribe::<[u8; PING]>()
        .open_or_create()
        .context("bare ping service")
}

fn bare_pong(
    node: &Node<Svc>,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, [u8; PONG], ()>> {
    node.service_builder(&ipc::name(BARE_PONG)?)
        .publish_subscribe::<[u8; PONG]>()
        .open_or_create()
        .context("bare pong service")
}

fn event(
    node: &Node<Svc>,
    name: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>> {
    node.service_builder(&ipc::name(name)?)
        .event()
        .open_or_create()
        .with_context(|| format!("event service {name}"))
}

/// The initiator's ports (ping publishers, pong subscribers).
pub(super) fn initiator_ports(node: &Node<Svc>) -> Result<Ports> {
    Ok(Ports {
        afs_wrench_pub: ipc::wrench(node)?
            .publisher_builder()
            .create()
            .context("wrench publisher")?,
        afs_servo_sub: ipc::servo(node)?
            .subscriber_builder()
            .create()
            .context("servo subscriber")?,
        bare_pub: bare_ping(node)?
            .publisher_builder()
            .create()
            .context("bare publisher")?,
        bare_sub: bare_pong(node)?
            .subscriber_builder()
            .create()
            .context("bare subscriber")?,
        notifier: event(node, EVENT_PING)?
            .notifier_builder()
            .create()
            .context("notifier")?,
        listener: event(node, EVENT_PONG)?
            .listener_builder()
            .create()
            .context("listener")?,
    })
}

/// Spins until `f` gives a value, or fails after [`ANSWER_TIMEOUT`] (the peer died).
fn spin<T>(mut f: impl FnMut() -> Result<Option<T>>) -> Result<T> {
    let t0 = Instant::now();
    let mut n = 0u32;
    loop {
        if let Some(v) = f()? {
            return Ok(v);
        }
        n = n.wrapping_add(1);
        if n.is_multiple_of(1024) && t0.elapsed() > ANSWER_TIMEOUT {
            bail!("the peer did not answer within {ANSWER_TIMEOUT:?}");
        }
        std::hint::spin_loop();
    }
}

fn put(buf: &mut [u8], at: usize, v: u64) {
    buf[at..at + 8].copy_from_slice(&v.to_ne_bytes());
}

fn get(buf: &[u8], at: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&buf[at..at + 8]);
    u64::from_ne_bytes(b)
}

/// One round trip from the initiator; returns (round trip, one way) in ns.
pub(super) fn ping(
    t: Transport,
    seq: u64,
    ports: &Ports,
    page: &AtomicPage,
    sock: &mut UnixStream,
) -> Result<(u64, u64)> {
    let t0 = rt::monotonic_ns();
    let oneway = match t {
        Transport::Atomic => {
            let mut b = [0u8; PING];
            put(&mut b, 0, seq);
            put(&mut b, 8, t0);
            page.write(PING_DATA, &b);
            page.seq(PING_SEQ).store(seq, Ordering::Release);
            spin(|| Ok((page.seq(PONG_SEQ).load(Ordering::Acquire) == seq).then_some(())))?;
            let mut r = [0u8; PONG];
            page.read(PONG_DATA, &mut r);
            get(&r, 16)
        }
        Transport::AfsPoll | Transport::AfsEvent => {
            let w = WrenchSample {
                version: WrenchSample::VERSION,
                seq,
                sample_ns: t0,
                publish_ns: t0,
                epoch_ns: 1,
                ..Default::default()
            };
            ports
                .afs_wrench_pub
                .send_copy(w)
                .context("sending a wrench sample")?;
            if t == Transport::AfsEvent {
                ports.notifier.notify().context("notify")?;
            }
            let sub = &ports.afs_servo_sub;
            let s = if t == Transport::AfsEvent {
                wait_event(&ports.listener, || receive_seq(sub, seq))?
            } else {
                spin(|| receive_seq(sub, seq))?
            };
            s.force_age_ns
        }
        Transport::BarePoll => {
            let mut b = [0u8; PING];
            put(&mut b, 0, seq);
            put(&mut b, 8, t0);
            ports.bare_pub.send_copy(b).context("bare send")?;
            let r = spin(|| {
                Ok(ports
                    .bare_sub
                    .receive()
                    .context("bare receive")?
                    .map(|s| *s.payload()))
            })?;
            get(&r, 16)
        }
        Transport::Uds => {
            let mut b = [0u8; PING];
            put(&mut b, 0, seq);
            put(&mut b, 8, t0);
            sock.write_all(&b).context("socket write")?;
            let mut r = [0u8; PONG];
            sock.read_exact(&mut r).context("socket read")?;
            get(&r, 16)
        }
    };
    let t1 = rt::monotonic_ns();
    Ok((t1.saturating_sub(t0), oneway))
}

fn receive_seq(sub: &Subscriber<Svc, ServoSample, ()>, seq: u64) -> Result<Option<ServoSample>> {
    while let Some(s) = sub.receive().context("receive")? {
        if s.seq == seq {
            return Ok(Some(*s.payload()));
        }
    }
    Ok(None)
}

/// Blocks on the listener until `f` gives a value (a notification may arrive before or after
/// the sample is visible: check first, then wait).
fn wait_event<T>(l: &Listener<Svc>, mut f: impl FnMut() -> Result<Option<T>>) -> Result<T> {
    let t0 = Instant::now();
    loop {
        if let Some(v) = f()? {
            return Ok(v);
        }
        l.timed_wait(|_| {}, Duration::from_millis(100))
            .context("listener wait")?;
        if t0.elapsed() > ANSWER_TIMEOUT {
            bail!("the peer did not answer within {ANSWER_TIMEOUT:?}");
        }
    }
}

pub(super) fn command(sock: &mut UnixStream, t: u32, count: u32) -> Result<()> {
    let mut b = [0u8; 8];
    b[..4].copy_from_slice(&t.to_ne_bytes());
    b[4..].copy_from_slice(&count.to_ne_bytes());
    sock.write_all(&b)
        .context("writing a command to the peer")?;
    let mut ack = [0u8; 4];
    sock.read_exact(&mut ack)
        .context("the peer did not acknowledge (did it die? see its error above)")?;
    Ok(())
}

/// The peer of the hop benchmark (`afs bench-peer`): answers every ping on the transport the
/// initiator names, until told to quit.
pub fn peer(prefix: &str, socket: &Path, cpu: Option<usize>) -> Result<()> {
    if let Some(c) = cpu {
        rt::pin_thread(c, "afs bench");
    }
    let node = ipc::node(prefix, "bench-peer")?;
    let wrench_sub = ipc::wrench(&node)?
        .subscriber_builder()
        .create()
        .context("wrench subscriber")?;
    let servo_pub = ipc::servo(&node)?
        .publisher_builder()
        .create()
        .context("servo publisher")?;
    let bare_sub = bare_ping(&node)?
        .subscriber_builder()
        .create()
        .context("bare subscriber")?;
    let bare_pub = bare_pong(&node)?
        .publisher_builder()
        .create()
        .context("bare publisher")?;
    let listener = event(&node, EVENT_PING)?
        .listener_builder()
        .create()
        .context("listener")?;
    let notifier = event(&node, EVENT_PONG)?
        .notifier_builder()
        .create()
        .context("notifier")?;
    let page = AtomicPage::open(prefix, false)?;
    let mut sock = UnixStream::connect(socket)
        .with_context(|| format!("connecting to {}", socket.display()))?;
    let upstream = super::upstream::Services::open(&node)?;
    let mut gate = SampleGate::new(GateParams {
        future_tolerance_ns: u64::MAX / 4,
        ..GateParams::default()
    });
    loop {
        let mut cmd = [0u8; 8];
        sock.read_exact(&mut cmd).context("reading a command")?;
        let t = u32::from_ne_bytes(cmd[..4].try_into().expect("4 bytes"));
        let n = u32::from_ne_bytes(cmd[4..].try_into().expect("4 bytes"));
        if (UPSTREAM..UPSTREAM + 16).contains(&t) {
            // Its ports exist only for the batch: the in-process B's batches see one
            // subscriber, as upstream's do.
            let b = super::upstream::Participant::open(&upstream, false)?
                .with(super::upstream::Extra::of_code(t - UPSTREAM));
            sock.write_all(&[0; 4])?;
            b.run_b(n)?;
            continue;
        }
        sock.write_all(&[0; 4])?;
        if t == QUIT {
            return Ok(());
        }
        let Some(&t) = TRANSPORTS.get(t as usize) else {
            bail!("unknown transport {t}");
        };
        for _ in 0..n {
            match t {
                Transport::Atomic => {
                    let last = page.seq(PONG_SEQ).load(Ordering::Relaxed);
                    spin(|| Ok((page.seq(PING_SEQ).load(Ordering::Acquire) > last).then_some(())))?;
                    let now = rt::monotonic_ns();
                    let mut b = [0u8; PING];
                    page.read(PING_DATA, &mut b);
                    let seq = get(&b, 0);
                    let mut r = [0u8; PONG];
                    put(&mut r, 0, seq);
                    put(&mut r, 16, now.saturating_sub(get(&b, 8)));
                    page.write(PONG_DATA, &r);
                    page.seq(PONG_SEQ).store(seq, Ordering::Release);
                }
                Transport::AfsPoll | Transport::AfsEvent => {
                    let recv = || -> Result<Option<WrenchSample>> {
                        Ok(wrench_sub
                            .receive()
                            .context("receive")?
                            .map(|s| *s.payload()))
                    };
                    let w = if t == Transport::AfsEvent {
                        wait_event(&listener, recv)?
                    } else {
                        spin(recv)?
                    };
                    let now = rt::monotonic_ns();
                    // What the servo does with a sample on receipt.
                    let _ = gate.offer(&w, now);
                    let s = ServoSample {
                        version: ServoSample::VERSION,
                        seq: w.seq,
                        force_age_ns: now.saturating_sub(w.publish_ns),
                        ..Default::default()
                    };
                    servo_pub.send_copy(s).context("send")?;
                    if t == Transport::AfsEvent {
                        notifier.notify().context("notify")?;
                    }
                }
                Transport::BarePoll => {
                    let b =
                        spin(|| Ok(bare_sub.receive().context("receive")?.map(|s| *s.payload())))?;
                    let now = rt::monotonic_ns();
                    let mut r = [0u8; PONG];
                    put(&mut r, 0, get(&b, 0));
                    put(&mut r, 16, now.saturating_sub(get(&b, 8)));
                    bare_pub.send_copy(r).context("send")?;
                }
                Transport::Uds => {
                    let mut b = [0u8; PING];
                    sock.read_exact(&mut b).context("socket read")?;
                    let now = rt::monotonic_ns();
                    let mut r = [0u8; PONG];
                    put(&mut r, 0, get(&b, 0));
                    put(&mut r, 16, now.saturating_sub(get(&b, 8)));
                    sock.write_all(&r).context("socket write")?;
                }
            }
        }
    }
}
