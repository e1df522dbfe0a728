//! The servo's gate on force data (pure: the caller passes the clock).
//!
//! Every received [`WrenchSample`] is offered to the gate, which accepts it only if its version
//! is right, every value is finite and within the sensor's rated range, its sequence number
//! moves forward (a later sensor epoch, i.e. a restarted sensor, starts a new sequence), and
//! its timestamp is not in the future. At each tick the servo asks for the newest accepted
//! sample; if it is older than the age limit (default 1.5 ms, so that the servo is safe within 2 ms of the last good
//! sample: the limit, plus one 0.1-ms tick, plus the wake latency) or none was ever accepted, the
//! verdict says so and the servo goes to its safe state. Rejected samples never reach the
//! controller as values; each is counted by kind.

use crate::msg::WrenchSample;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::{Deserialize, Serialize};

wire_code! {
    /// Why a sample or a tick was refused. The numbers are the `safe_reason` codes of
    /// [`crate::msg::ServoSample`].
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Verdict {
        /// Accepted / fresh.
        Ok = 0,
        /// A NaN or infinite value.
        NonFinite = 1,
        /// Beyond the sensor's rated range.
        OutOfRange = 2,
        /// The same sequence number again.
        SeqRepeat = 3,
        /// A sequence number (or sensor epoch) older than the newest accepted.
        SeqBackwards = 4,
        /// A timestamp later than now.
        Future = 5,
        /// Wrong message version.
        Version = 6,
        /// The newest accepted sample is older than the age limit.
        Stale = 7,
        /// No sample accepted yet.
        NoData = 8,
    }
}

/// Limits of the gate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateParams {
    /// Largest age of force data at use (ns).
    pub max_age_ns: u64,
    /// Largest |force component| accepted (N): the sensor's rated range.
    pub force_limit_n: f64,
    /// Largest |moment| accepted (N·m).
    pub torque_limit_nm: f64,
    /// How far in the future a timestamp may be (ns), for clock reads racing each other.
    pub future_tolerance_ns: u64,
}

impl Default for GateParams {
    fn default() -> Self {
        Self {
            max_age_ns: 1_500_000,
            force_limit_n: 130.0,
            torque_limit_nm: 10.0,
            future_tolerance_ns: 50_000,
        }
    }
}

wire_struct! {
    /// Counts of offered samples by verdict. It crosses a servo restart in the world snapshot and
    /// goes out in the loop statistics (`#[repr(C)]`, docs/messages.md).
    #[derive(
        Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend, Serialize, Deserialize,
    )]
    #[type_name("afs::GateCounters")]
    pub struct GateCounters {
        /// [`Verdict::NonFinite`].
        pub non_finite: u64,
        /// [`Verdict::OutOfRange`].
        pub out_of_range: u64,
        /// [`Verdict::SeqRepeat`].
        pub seq_repeat: u64,
        /// [`Verdict::SeqBackwards`].
        pub seq_backwards: u64,
        /// [`Verdict::Future`].
        pub future: u64,
        /// [`Verdict::Version`].
        pub version: u64,
        /// Accepted samples.
        pub accepted: u64,
        /// Sensor restarts seen (new epochs).
        pub new_epochs: u64,
    }
}

impl GateCounters {
    /// One more sample judged `v` (a tick's verdicts, `Stale` and `NoData`, are not counted).
    pub fn count(&mut self, v: Verdict) {
        match v {
            Verdict::Ok => self.accepted += 1,
            Verdict::NonFinite => self.non_finite += 1,
            Verdict::OutOfRange => self.out_of_range += 1,
            Verdict::SeqRepeat => self.seq_repeat += 1,
            Verdict::SeqBackwards => self.seq_backwards += 1,
            Verdict::Future => self.future += 1,
            Verdict::Version => self.version += 1,
            Verdict::Stale | Verdict::NoData => {}
        }
    }

    /// Samples refused, whatever the reason.
    pub fn refused(&self) -> u64 {
        self.non_finite
            + self.out_of_range
            + self.seq_repeat
            + self.seq_backwards
            + self.future
            + self.version
    }

    /// Samples judged (accepted or refused).
    pub fn judged(&self) -> u64 {
        self.accepted + self.refused()
    }
}

/// The gate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleGate {
    params: GateParams,
    newest: Option<WrenchSample>,
    counters: GateCounters,
}

impl SampleGate {
    /// A gate with no sample yet.
    pub fn new(params: GateParams) -> Self {
        Self {
            params,
            newest: None,
            counters: GateCounters::default(),
        }
    }

    /// A gate that goes on counting from `counters` (a restarted servo's, from its
    /// predecessor's snapshot); the newest sample is not carried over.
    pub fn resume(params: GateParams, counters: GateCounters) -> Self {
        Self {
            counters,
            ..Self::new(params)
        }
    }

    /// Offers a received sample at monotonic time `now_ns`; returns the verdict.
    pub fn offer(&mut self, s: &WrenchSample, now_ns: u64) -> Verdict {
        let v = self.judge(s, now_ns);
        self.counters.count(v);
        if v == Verdict::Ok {
            if self.newest.is_some_and(|n| s.epoch_ns > n.epoch_ns) {
                self.counters.new_epochs += 1;
            }
            self.newest = Some(*s);
        }
        v
    }

    fn judge(&self, s: &WrenchSample, now_ns: u64) -> Verdict {
        if s.version != WrenchSample::VERSION {
            return Verdict::Version;
        }
        let values = [s.force_n[0], s.force_n[1], s.torque_nm];
        let tare = [s.tare_force_n[0], s.tare_force_n[1], s.tare_torque_nm];
        if values.iter().chain(&tare).any(|v| !v.is_finite()) {
            return Verdict::NonFinite;
        }
        let p = &self.params;
        if s.force_n
            .iter()
            .chain(&s.tare_force_n)
            .any(|f| f.abs() > p.force_limit_n)
            || s.torque_nm.abs() > p.torque_limit_nm
            || s.tare_torque_nm.abs() > p.torque_limit_nm
        {
            return Verdict::OutOfRange;
        }
        let limit = now_ns.saturating_add(p.future_tolerance_ns);
        if s.sample_ns > limit || s.epoch_ns > limit || s.publish_ns > limit {
            return Verdict::Future;
        }
        if let Some(n) = self.newest {
            if s.epoch_ns < n.epoch_ns {
                return Verdict::SeqBackwards;
            }
            if s.epoch_ns == n.epoch_ns {
                if s.seq == n.seq {
                    return Verdict::SeqRepeat;
                }
                if s.seq < n.seq || s.sample_ns < n.sample_ns {
                    return Verdict::SeqBackwards;
                }
            }
        }
        Verdict::Ok
    }

    /// The newest accepted sample and its age at `now_ns`, or why there is none to use.
    pub fn current(&self, now_ns: u64) -> Result<(WrenchSample, u64), Verdict> {
        let n = self.newest.ok_or(Verdict::NoData)?;
        let age = now_ns.saturating_sub(n.sample_ns);
        if age > self.params.max_age_ns {
            Err(Verdict::Stale)
        } else {
            Ok((n, age))
        }
    }

    /// The newest accepted sample, however old.
    #[must_use]
    pub fn newest(&self) -> Option<&WrenchSample> {
        self.newest.as_ref()
    }

    /// The counters.
    pub fn counters(&self) -> GateCounters {
        self.counters
    }

    /// The limits.
    pub fn params(&self) -> &GateParams {
        &self.params
    }
}

/// The age of force data on a loop that a robot's packets clock (issue 48): a sample is as old
/// as the robot's time that has passed since the loop first saw it. A real robot's time runs
/// on, a missed cycle included, while the servo or its host stalls, so a sensor that stopped
/// is found out after the gate's age limit of the robot's time; a simulated robot whose world
/// stalls with the host stops its time too, and a sample that is the newest when the world
/// goes on is not held against it. How late a sample may arrive before it is seen is the
/// sensor board's limit (`--late-ms`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RobotClockAge {
    seen: Option<(u64, u64, f64)>,
}

impl RobotClockAge {
    /// The time (ns, on the samples' clock) at which to judge the newest sample `newest`
    /// ([`SampleGate::current`]) when the robot's time is `robot_time_s`: its stamp plus the
    /// robot's time since the loop first saw it. Without a sample, `now_ns`.
    pub fn due_ns(&mut self, newest: Option<&WrenchSample>, robot_time_s: f64, now_ns: u64) -> u64 {
        let Some(w) = newest else {
            return now_ns;
        };
        let (seq, sample_ns, at) = match self.seen {
            Some((seq, ns, at)) if seq == w.seq && ns == w.sample_ns => (seq, ns, at),
            _ => (w.seq, w.sample_ns, robot_time_s),
        };
        self.seen = Some((seq, sample_ns, at));
        let since_ns = ((robot_time_s - at).max(0.0) * 1e9).round() as u64;
        sample_ns.saturating_add(since_ns)
    }
}

#[cfg(test)]
mod robot_clock_tests {
    use super::*;

    fn sample(seq: u64, sample_ns: u64) -> WrenchSample {
        WrenchSample {
            seq,
            sample_ns,
            ..WrenchSample::default()
        }
    }

    /// A sample seen at robot time t is judged at its stamp plus the robot's time since:
    /// 0 at first, 3 ms after three cycles without a new one, whatever the wall clock did.
    #[test]
    fn the_age_is_the_robots_time_since_the_sample_was_seen() {
        let mut c = RobotClockAge::default();
        let w = sample(7, 1_000_000);
        assert_eq!(c.due_ns(Some(&w), 2.0, 9_000_000_000), 1_000_000);
        // The host stalled 50 ms of wall time; the robot's time went on 1 ms.
        assert_eq!(c.due_ns(Some(&w), 2.001, 9_050_000_000), 2_000_000);
        assert_eq!(c.due_ns(Some(&w), 2.003, 9_060_000_000), 4_000_000);
        // A new sample starts again from its own stamp.
        let v = sample(8, 70_000_000);
        assert_eq!(c.due_ns(Some(&v), 2.004, 9_061_000_000), 70_000_000);
        assert_eq!(c.due_ns(None, 2.005, 123), 123);
    }

    /// Through the gate: a sensor that stops is stale after the limit of the robot's time.
    #[test]
    fn a_stopped_sensor_is_stale_after_the_limit_of_robot_time() {
        let mut gate = SampleGate::new(GateParams {
            max_age_ns: 5_000_000,
            ..GateParams::default()
        });
        let w = WrenchSample {
            version: WrenchSample::VERSION,
            seq: 1,
            sample_ns: 1_000,
            ..WrenchSample::default()
        };
        assert_eq!(gate.offer(&w, 2_000), Verdict::Ok);
        let mut c = RobotClockAge::default();
        for k in 0..=5 {
            let due = c.due_ns(gate.newest(), f64::from(k) * 1e-3, 1_000_000_000);
            assert!(gate.current(due).is_ok(), "cycle {k}");
        }
        let due = c.due_ns(gate.newest(), 6e-3, 1_000_000_000);
        assert_eq!(gate.current(due).err(), Some(Verdict::Stale));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(seq: u64, t: u64) -> WrenchSample {
        WrenchSample {
            version: WrenchSample::VERSION,
            seq,
            epoch_ns: 1_000,
            sample_ns: t,
            publish_ns: t,
            force_n: [1.0, -2.0],
            torque_nm: 0.01,
            ..Default::default()
        }
    }

    /// Good samples pass and age; a stale or missing one is refused at the tick.
    #[test]
    fn fresh_samples_pass_and_age_out() {
        let mut g = SampleGate::new(GateParams::default());
        assert_eq!(g.current(10_000), Err(Verdict::NoData));
        assert_eq!(g.offer(&sample(0, 10_000), 10_100), Verdict::Ok);
        assert_eq!(g.current(10_100).map(|x| x.1), Ok(100));
        assert_eq!(
            g.current(10_000 + 1_500_000),
            Ok((sample(0, 10_000), 1_500_000))
        );
        assert_eq!(g.current(10_000 + 1_500_001), Err(Verdict::Stale));
    }

    /// Each kind of bad sample is refused, counted, and leaves the newest good one in place.
    #[test]
    fn bad_samples_never_replace_good_ones() {
        let mut g = SampleGate::new(GateParams::default());
        let good = sample(5, 50_000);
        assert_eq!(g.offer(&good, 50_000), Verdict::Ok);
        let now = 60_000;
        let mut nan = sample(6, 55_000);
        nan.force_n[1] = f64::NAN;
        let mut inf = sample(6, 55_000);
        inf.tare_torque_nm = f64::INFINITY;
        let mut big = sample(6, 55_000);
        big.force_n[0] = 1e6;
        let mut future = sample(6, 55_000);
        future.sample_ns = now + 1_000_000;
        let mut version = sample(6, 55_000);
        version.version = 0;
        let mut old_epoch = sample(9, 55_000);
        old_epoch.epoch_ns = 10;
        let cases = [
            (nan, Verdict::NonFinite),
            (inf, Verdict::NonFinite),
            (big, Verdict::OutOfRange),
            (future, Verdict::Future),
            (version, Verdict::Version),
            (sample(5, 50_000), Verdict::SeqRepeat),
            (sample(4, 49_000), Verdict::SeqBackwards),
            (sample(7, 40_000), Verdict::SeqBackwards),
            (old_epoch, Verdict::SeqBackwards),
        ];
        for (s, v) in cases {
            assert_eq!(g.offer(&s, now), v, "{s:?}");
            assert_eq!(g.current(now), Ok((good, now - good.sample_ns)));
        }
        let c = g.counters();
        assert_eq!(
            (
                c.non_finite,
                c.out_of_range,
                c.future,
                c.version,
                c.seq_repeat,
                c.seq_backwards
            ),
            (2, 1, 1, 1, 1, 3)
        );
        assert_eq!(c.accepted, 1);
    }

    /// Counts add up by verdict: `refused` is every refusal, `judged` adds the accepted; a tick's
    /// verdicts (stale, no data) count nothing.
    #[test]
    fn counters_add_up_by_verdict() {
        let mut c = GateCounters::default();
        let each = [
            (Verdict::NonFinite, 1),
            (Verdict::OutOfRange, 2),
            (Verdict::SeqRepeat, 4),
            (Verdict::SeqBackwards, 8),
            (Verdict::Future, 16),
            (Verdict::Version, 32),
            (Verdict::Ok, 64),
            (Verdict::Stale, 128),
            (Verdict::NoData, 256),
        ];
        for (v, n) in each {
            for _ in 0..n {
                c.count(v);
            }
        }
        let want = GateCounters {
            non_finite: 1,
            out_of_range: 2,
            seq_repeat: 4,
            seq_backwards: 8,
            future: 16,
            version: 32,
            accepted: 64,
            new_epochs: 0,
        };
        assert_eq!(c, want);
        assert_eq!((c.refused(), c.judged()), (63, 127));
    }

    /// A gate resumed from a predecessor's counts goes on counting from them, but judges the
    /// next sample afresh (no newest sample carried over).
    #[test]
    fn a_resumed_gate_counts_on() {
        let before = GateCounters {
            non_finite: 3,
            accepted: 10,
            ..Default::default()
        };
        let mut g = SampleGate::resume(GateParams::default(), before);
        assert_eq!(g.counters(), before);
        assert_eq!(g.current(10_000), Err(Verdict::NoData));
        assert_eq!(g.offer(&sample(0, 10_000), 10_000), Verdict::Ok);
        let mut nan = sample(1, 10_000);
        nan.force_n[0] = f64::NAN;
        assert_eq!(g.offer(&nan, 10_000), Verdict::NonFinite);
        assert_eq!((g.counters().accepted, g.counters().non_finite), (11, 4));
    }

    /// Each limit holds at its boundary and refuses just past it, value by value: every force
    /// and moment (measured and tare) against the rated range, every timestamp (sample, epoch,
    /// publication) against the future tolerance.
    #[test]
    fn every_limit_holds_at_its_boundary_and_refuses_past_it() {
        let params = GateParams {
            force_limit_n: 60.0,
            torque_limit_nm: 4.0,
            ..GateParams::default()
        };
        let g = SampleGate::new(params);
        assert_eq!(g.params(), &params);
        let (f, m) = (params.force_limit_n, params.torque_limit_nm);
        let now = 1_000_000;
        let setters: [fn(&mut WrenchSample, f64); 6] = [
            |s, v| s.force_n[0] = v,
            |s, v| s.force_n[1] = v,
            |s, v| s.tare_force_n[0] = v,
            |s, v| s.tare_force_n[1] = v,
            |s, v| s.torque_nm = v,
            |s, v| s.tare_torque_nm = v,
        ];
        for (i, set) in setters.iter().enumerate() {
            let limit = if i < 4 { f } else { m };
            for sign in [1.0, -1.0] {
                let mut at = sample(0, now);
                set(&mut at, sign * limit);
                assert_eq!(g.judge(&at, now), Verdict::Ok, "value {i} at {sign}·limit");
                let mut past = sample(0, now);
                set(&mut past, sign * limit * (1.0 + 1e-9));
                assert_eq!(
                    g.judge(&past, now),
                    Verdict::OutOfRange,
                    "value {i} past it"
                );
            }
        }
        let tol = params.future_tolerance_ns;
        let stamps: [fn(&mut WrenchSample, u64); 3] = [
            |s, t| s.sample_ns = t,
            |s, t| s.epoch_ns = t,
            |s, t| s.publish_ns = t,
        ];
        for (i, set) in stamps.iter().enumerate() {
            let mut at = sample(0, now);
            set(&mut at, now + tol);
            assert_eq!(g.judge(&at, now), Verdict::Ok, "stamp {i} at the tolerance");
            let mut past = sample(0, now);
            set(&mut past, now + tol + 1);
            assert_eq!(g.judge(&past, now), Verdict::Future, "stamp {i} past it");
        }
    }

    /// Within an epoch the sequence number and the sample time must not go back, each on its
    /// own; a later sample at the same instant is accepted; no new epoch is counted.
    #[test]
    fn sequence_and_time_each_move_forward() {
        let mut g = SampleGate::new(GateParams::default());
        let now = 100_000;
        assert_eq!(g.offer(&sample(5, 50_000), now), Verdict::Ok);
        // An older number at a later time, a newer number at an earlier time: both backwards.
        assert_eq!(g.offer(&sample(4, 60_000), now), Verdict::SeqBackwards);
        assert_eq!(g.offer(&sample(6, 49_999), now), Verdict::SeqBackwards);
        // A newer number at the same instant: accepted (two readings of one clock tick).
        assert_eq!(g.offer(&sample(6, 50_000), now), Verdict::Ok);
        assert_eq!(g.offer(&sample(7, 60_000), now), Verdict::Ok);
        assert_eq!(g.counters().new_epochs, 0);
        assert_eq!(g.counters().accepted, 3);
    }

    /// A restarted sensor (later epoch) starts its sequence again and is accepted.
    #[test]
    fn a_new_sensor_epoch_restarts_the_sequence() {
        let mut g = SampleGate::new(GateParams::default());
        assert_eq!(g.offer(&sample(900, 50_000), 50_000), Verdict::Ok);
        let mut restarted = sample(0, 70_000);
        restarted.epoch_ns = 65_000;
        assert_eq!(g.offer(&restarted, 70_000), Verdict::Ok);
        assert_eq!(g.counters().new_epochs, 1);
        assert_eq!(g.offer(&sample(901, 71_000), 71_000), Verdict::SeqBackwards);
    }
}
