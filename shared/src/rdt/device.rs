//! An RDT device's behaviour without I/O: the core of the emulator (`afs-netft`), and the
//! faults it can put on its stream.

use super::{Command, MAX_RECORDS_PER_PACKET, RdtError, Record, Request, STATUS_ERROR};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// Where a device's records go: the client that asked, and how.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stream<A> {
    client: A,
    buffered: bool,
    remaining: Option<u32>,
    rdt_sequence: u32,
}

/// What a device did with a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answer {
    /// Streaming to the requester from now on.
    Streaming,
    /// Stopped streaming.
    Stopped,
    /// The present reading is the new zero.
    Biased,
    /// Ignored: the device streams to another client (one at a time).
    Busy,
    /// Ignored: not an RDT request.
    Invalid(RdtError),
}

/// An RDT device's behaviour, without I/O (the emulator's core): one client at a time;
/// `rdt_sequence` from 1 after each streaming request; `ft_sequence` free-running at the
/// device's rate; a sample count that ends the stream; a software bias; buffered streams of
/// `records_per_packet` records per datagram. `A` is the client's address.
#[derive(Debug, Clone)]
pub struct Device<A> {
    stream: Option<Stream<A>>,
    ft_sequence: u32,
    first_rdt_sequence: u32,
    bias: [i32; 6],
    latest: [i32; 6],
    records_per_packet: usize,
    packet: [Record; MAX_RECORDS_PER_PACKET],
    in_packet: usize,
}

impl<A: Copy + PartialEq> Device<A> {
    /// A device whose next sample is `ft_sequence` and whose streams start at
    /// `first_rdt_sequence` (1 on a real device; nearer 2^32 to test the wrap), sending
    /// `records_per_packet` (1 to 40) records per datagram when buffered.
    pub fn new(ft_sequence: u32, first_rdt_sequence: u32, records_per_packet: usize) -> Self {
        Self {
            stream: None,
            ft_sequence,
            first_rdt_sequence,
            bias: [0; 6],
            latest: [0; 6],
            records_per_packet: records_per_packet.clamp(1, MAX_RECORDS_PER_PACKET),
            packet: [Record::default(); MAX_RECORDS_PER_PACKET],
            in_packet: 0,
        }
    }

    /// The client it streams to.
    pub fn client(&self) -> Option<A> {
        self.stream.map(|s| s.client)
    }

    /// Sets the zero (counts): the device was biased before (in free air, by its operator).
    pub fn set_bias(&mut self, bias: [i32; 6]) {
        self.bias = bias;
    }

    /// The present zero (counts).
    pub fn bias(&self) -> [i32; 6] {
        self.bias
    }

    /// Handles a request's bytes from `from`.
    pub fn request(&mut self, from: A, bytes: &[u8]) -> Answer {
        let r = match Request::decode(bytes) {
            Ok(r) => r,
            Err(e) => return Answer::Invalid(e),
        };
        let other = self.stream.is_some_and(|s| s.client != from);
        match r.command {
            Command::SetBias => {
                self.bias = self.latest;
                Answer::Biased
            }
            _ if other => Answer::Busy,
            Command::Stop => {
                self.stream = None;
                self.in_packet = 0;
                Answer::Stopped
            }
            Command::RealTime | Command::Buffered => {
                self.stream = Some(Stream {
                    client: from,
                    buffered: r.command == Command::Buffered,
                    remaining: (r.count != 0).then_some(r.count),
                    rdt_sequence: self.first_rdt_sequence,
                });
                self.in_packet = 0;
                Answer::Streaming
            }
        }
    }

    /// Samples the device took without anyone seeing them (its clock ran while its host
    /// stalled): `ft_sequence` moves on by `n`, as a device's counter follows time.
    pub fn skip(&mut self, n: u32) {
        self.ft_sequence = self.ft_sequence.wrapping_add(n);
    }

    /// One internal sample (raw counts, before the bias; the status word): the records to send
    /// now and to whom (none between a buffered stream's datagrams, or when not streaming).
    pub fn sample(&mut self, raw: [i32; 6], status: u32) -> Option<(A, &[Record])> {
        self.latest = raw;
        let ft = self.ft_sequence;
        self.ft_sequence = self.ft_sequence.wrapping_add(1);
        let s = self.stream.as_mut()?;
        let mut counts = [0i32; 6];
        for (i, c) in counts.iter_mut().enumerate() {
            *c = raw[i].saturating_sub(self.bias[i]);
        }
        self.packet[self.in_packet] = Record {
            rdt_sequence: s.rdt_sequence,
            ft_sequence: ft,
            status,
            counts,
        };
        self.in_packet += 1;
        s.rdt_sequence = s.rdt_sequence.wrapping_add(1);
        let client = s.client;
        let mut last = false;
        if let Some(n) = s.remaining.as_mut() {
            *n -= 1;
            last = *n == 0;
        }
        let full = !s.buffered || self.in_packet == self.records_per_packet;
        if last {
            self.stream = None;
        }
        if full || last {
            let n = self.in_packet;
            self.in_packet = 0;
            Some((client, &self.packet[..n]))
        } else {
            None
        }
    }
}

/// Faults the emulator puts on its stream, each datagram drawn at random from a seed.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Impairments {
    /// Fraction of datagrams dropped.
    pub loss: f64,
    /// Fraction of datagrams sent twice.
    pub duplicate: f64,
    /// Fraction of datagrams held back and sent after the next one.
    pub reorder: f64,
    /// From this many seconds after the device's first sample on, for `status_error_s`
    /// seconds, records carry a status word with the error bit (0: never).
    pub status_error_at_s: f64,
    /// How long the status error lasts (s).
    pub status_error_s: f64,
    /// From this many seconds after the device's first sample on, it sends nothing more
    /// (0: never).
    pub silent_at_s: f64,
    /// Streams and samples start this many records before their sequence numbers wrap at
    /// 2^32 (0: a real device's numbering, rdt_sequence from 1 and ft_sequence from 0).
    pub wrap_in: u32,
}

impl Impairments {
    /// Refuses fractions outside [0, 1] and negative times.
    pub fn validate(&self) -> Result<(), crate::error::ConfigError> {
        for (name, v) in [
            ("loss", self.loss),
            ("duplicate", self.duplicate),
            ("reorder", self.reorder),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(crate::error::ConfigError::setting(
                    name,
                    v,
                    "must be a fraction of datagrams in [0, 1]",
                ));
            }
        }
        for (name, v) in [
            ("status_error_at_s", self.status_error_at_s),
            ("status_error_s", self.status_error_s),
            ("silent_at_s", self.silent_at_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(crate::error::ConfigError::setting(
                    name,
                    v,
                    "must be a number of seconds >= 0",
                ));
            }
        }
        Ok(())
    }

    /// The first `ft_sequence` and `rdt_sequence` of a device with these faults.
    pub fn first_sequences(&self) -> (u32, u32) {
        if self.wrap_in == 0 {
            (0, 1)
        } else {
            let s = 0u32.wrapping_sub(self.wrap_in);
            (s, s)
        }
    }
}

/// What to send of one datagram: up to three datagrams (a held one, this one, its duplicate),
/// the index of each in the caller's list.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sends {
    /// Datagrams to send now, in order: `Held` the one held back before, `This` the new one.
    pub order: [Option<Outgoing>; 3],
}

/// One of [`Sends::order`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outgoing {
    /// The datagram held back from before.
    Held,
    /// The datagram just made.
    This,
}

/// Applies [`Impairments`] to a stream of datagrams, deterministically from a seed. Holding a
/// datagram back for reordering is the caller's (it owns the bytes): `Outgoing::Held` means the
/// one it kept when the previous call returned `hold = true`.
#[derive(Debug, Clone)]
pub struct Shaper {
    imp: Impairments,
    rng: ChaCha8Rng,
    holding: bool,
}

impl Shaper {
    /// Faults from `seed`.
    pub fn new(imp: Impairments, seed: u64) -> Self {
        Self {
            imp,
            rng: ChaCha8Rng::seed_from_u64(seed),
            holding: false,
        }
    }

    /// The status word for a record `t_s` after the device's first sample.
    pub fn status(&self, t_s: f64) -> u32 {
        let i = &self.imp;
        if i.status_error_at_s > 0.0
            && t_s >= i.status_error_at_s
            && t_s < i.status_error_at_s + i.status_error_s
        {
            STATUS_ERROR
        } else {
            0
        }
    }

    /// Whether the device has gone silent `t_s` after its first sample.
    pub fn silent(&self, t_s: f64) -> bool {
        self.imp.silent_at_s > 0.0 && t_s >= self.imp.silent_at_s
    }

    /// What to send of a new datagram, and whether to keep it back (`true`: the caller keeps
    /// its bytes for a later `Outgoing::Held`).
    pub fn datagram(&mut self) -> (Sends, bool) {
        let mut u = || self.rng.next_u64() as f64 / u64::MAX as f64;
        let (lose, dup, reorder) = (u(), u(), u());
        let mut s = Sends::default();
        let mut n = 0;
        if lose < self.imp.loss {
            // Lost; a held datagram still goes, after its successor would have.
            if self.holding {
                s.order[0] = Some(Outgoing::Held);
                self.holding = false;
            }
            return (s, false);
        }
        if !self.holding && reorder < self.imp.reorder {
            self.holding = true;
            return (s, true);
        }
        s.order[n] = Some(Outgoing::This);
        n += 1;
        if dup < self.imp.duplicate {
            s.order[n] = Some(Outgoing::This);
            n += 1;
        }
        if self.holding {
            s.order[n] = Some(Outgoing::Held);
            self.holding = false;
        }
        (s, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(v: i32) -> [i32; 6] {
        [v, -v, 0, 0, 0, 1]
    }

    #[test]
    fn the_device_serves_one_client_numbers_its_stream_and_stops_at_the_count() {
        let mut d: Device<u8> = Device::new(100, 1, 4);
        assert!(d.sample(raw(1), 0).is_none());
        let rt = Request {
            command: Command::RealTime,
            count: 3,
        }
        .encode();
        assert_eq!(d.request(7, &rt), Answer::Streaming);
        assert_eq!(d.request(8, &rt), Answer::Busy);
        let mut seen = vec![];
        for k in 0..5 {
            if let Some((to, recs)) = d.sample(raw(k), 0) {
                assert_eq!(to, 7);
                assert_eq!(recs.len(), 1);
                seen.push((recs[0].rdt_sequence, recs[0].ft_sequence));
            }
        }
        assert_eq!(seen, [(1, 101), (2, 102), (3, 103)]);
        assert_eq!(d.client(), None);
        // Another client now; a new stream numbers from 1 again; ft_sequence runs on.
        assert_eq!(d.request(8, &rt), Answer::Streaming);
        let (_, r) = d.sample(raw(9), 0).unwrap();
        assert_eq!((r[0].rdt_sequence, r[0].ft_sequence), (1, 106));
        assert_eq!(
            d.request(
                8,
                &Request {
                    command: Command::Stop,
                    count: 0
                }
                .encode()
            ),
            Answer::Stopped
        );
        assert!(d.sample(raw(1), 0).is_none());
        assert!(matches!(d.request(8, &[1, 2, 3]), Answer::Invalid(_)));
    }

    #[test]
    fn the_device_buffers_and_biases() {
        let mut d: Device<u8> = Device::new(0, 1, 3);
        d.sample(raw(50), 0);
        let bias = Request {
            command: Command::SetBias,
            count: 0,
        }
        .encode();
        assert_eq!(d.request(1, &bias), Answer::Biased);
        assert_eq!(d.bias(), raw(50));
        let b = Request {
            command: Command::Buffered,
            count: 0,
        }
        .encode();
        assert_eq!(d.request(1, &b), Answer::Streaming);
        assert!(d.sample(raw(51), 0).is_none());
        assert!(d.sample(raw(52), 0).is_none());
        let (_, recs) = d.sample(raw(53), 5).unwrap();
        let seqs: Vec<u32> = recs.iter().map(|r| r.rdt_sequence).collect();
        assert_eq!(seqs, [1, 2, 3]);
        assert_eq!(recs[2].counts, [3, -3, 0, 0, 0, 0]);
        assert_eq!(recs[2].status, 5);
    }

    /// Over many datagrams each fault happens at its configured rate, and a held datagram is
    /// always sent right after the next one that is sent.
    #[test]
    fn the_shaper_loses_duplicates_and_reorders_at_its_rates() {
        let imp = Impairments {
            loss: 0.05,
            duplicate: 0.02,
            reorder: 0.03,
            ..Impairments::default()
        };
        let mut s = Shaper::new(imp, 3);
        let n = 200_000;
        let (mut sent, mut this, mut held, mut holds, mut dups) = (0, 0, 0, 0, 0);
        for _ in 0..n {
            let (sends, hold) = s.datagram();
            holds += hold as u32;
            let k: Vec<Outgoing> = sends.order.iter().flatten().copied().collect();
            sent += k.len();
            this += k.iter().filter(|x| **x == Outgoing::This).count();
            held += k.iter().filter(|x| **x == Outgoing::Held).count();
            dups += (k.iter().filter(|x| **x == Outgoing::This).count() == 2) as u32;
            if let Some(p) = k.iter().position(|x| *x == Outgoing::Held) {
                assert_eq!(p, k.len() - 1, "a held datagram goes after the new ones");
            }
        }
        let f = |x: f64| x / n as f64;
        assert!((f(holds as f64) - 0.95 * 0.03).abs() < 0.003, "{holds}");
        assert!(
            (f(dups as f64) - 0.95 * 0.97 * 0.02).abs() < 0.002,
            "{dups}"
        );
        assert!((held as i64 - holds as i64).abs() <= 1);
        assert_eq!(sent, this + held);
        // Every datagram not lost is sent at least once.
        let lost = n - (this - dups as usize) - held;
        assert!((f(lost as f64) - 0.05).abs() < 0.003, "{lost}");
        // Time-based faults.
        let t = Shaper::new(
            Impairments {
                status_error_at_s: 1.0,
                status_error_s: 0.5,
                silent_at_s: 2.0,
                ..Impairments::default()
            },
            0,
        );
        assert_eq!(
            (t.status(0.9), t.status(1.2), t.status(1.6)),
            (0, STATUS_ERROR, 0)
        );
        assert!(!t.silent(1.9) && t.silent(2.0));
        assert_eq!(Impairments::default().first_sequences(), (0, 1));
        assert!(Impairments { loss: 1.5, ..imp }.validate().is_err());
    }
}
