//! ATI's Raw Data Transfer (RDT) protocol, as ATI's Net F/T, Axia80 and other force/torque
//! sensors speak it over UDP (port 49152), without I/O: requests and records to and from bytes,
//! counts to SI units, the sensor's mounting, the checks a receiver makes on each record, and
//! the device's own behaviour (for the emulator, `afs-netft`). docs/sensor.md describes the
//! protocol and each choice.
//!
//! Everything on the wire is big-endian (network order):
//!
//! ```text
//! request (8 bytes):  u16 header = 0x1234 | u16 command | u32 sample count (0: no end)
//! record (36 bytes):  u32 rdt_sequence | u32 ft_sequence | u32 status
//!                     | i32 Fx | i32 Fy | i32 Fz | i32 Tx | i32 Ty | i32 Tz   (counts)
//! ```
//!
//! A real-time stream carries one record per datagram; a buffered stream several.

mod device;

pub use device::{Answer, Device, Impairments, Outgoing, Sends, Shaper};

use crate::math::Vec2;
use crate::sensor::Wrench;

/// The device's UDP port.
pub const PORT: u16 = 49152;
/// The first two bytes of every request.
pub const REQUEST_HEADER: u16 = 0x1234;
/// Bytes of a request.
pub const REQUEST_LEN: usize = 8;
/// Bytes of a record.
pub const RECORD_LEN: usize = 36;
/// Most records in one datagram that afs accepts (a buffered stream's packet).
pub const MAX_RECORDS_PER_PACKET: usize = 40;
/// Counts per newton of the device's factory calibration that afs assumes by default (read
/// the device's own value off its web page or `netftapi2.xml`: `cfgcpf`).
pub const DEFAULT_COUNTS_PER_FORCE: f64 = 1_000_000.0;
/// Counts per newton-metre (`cfgcpt`).
pub const DEFAULT_COUNTS_PER_TORQUE: f64 = 1_000_000.0;
/// The status word's summary bit: the device reports an error.
pub const STATUS_ERROR: u32 = 1 << 31;

/// A packet or request that is not RDT.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RdtError {
    /// A request whose length is not 8 bytes.
    #[error("an RDT request is {REQUEST_LEN} bytes, this one is {0}")]
    RequestLength(usize),
    /// A request that does not start with 0x1234.
    #[error("an RDT request starts with 0x1234, this one with {0:#06x}")]
    RequestHeader(u16),
    /// A command this implementation does not know.
    #[error(
        "unknown RDT command {0:#06x} (known: stop 0x0000, real-time 0x0002, buffered 0x0003, set bias 0x0042)"
    )]
    Command(u16),
    /// A datagram that is not a whole number of records.
    #[error(
        "an RDT datagram holds 1 to {MAX_RECORDS_PER_PACKET} records of {RECORD_LEN} bytes, this one is {0} bytes"
    )]
    PacketLength(usize),
}

wire_code! {
    /// An RDT command (a `u16` on the wire).
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Command {
        /// Stop streaming.
        Stop = 0x0000,
        /// Stream one record per datagram, each as soon as it is sampled.
        RealTime = 0x0002,
        /// Stream several records per datagram.
        Buffered = 0x0003,
        /// Take the present reading as the zero of the following ones (software bias).
        SetBias = 0x0042,
    }
}

/// A request to the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Request {
    /// What to do.
    pub command: Command,
    /// Records to send before stopping (0: until stopped). Used by the streaming commands.
    pub count: u32,
}

impl Request {
    /// The request's bytes.
    pub fn encode(&self) -> [u8; REQUEST_LEN] {
        let mut b = [0u8; REQUEST_LEN];
        b[0..2].copy_from_slice(&REQUEST_HEADER.to_be_bytes());
        b[2..4].copy_from_slice(&(u32::from(self.command) as u16).to_be_bytes());
        b[4..8].copy_from_slice(&self.count.to_be_bytes());
        b
    }

    /// A request from its bytes.
    pub fn decode(b: &[u8]) -> Result<Self, RdtError> {
        let b: &[u8; REQUEST_LEN] = b.try_into().map_err(|_| RdtError::RequestLength(b.len()))?;
        let header = u16::from_be_bytes([b[0], b[1]]);
        if header != REQUEST_HEADER {
            return Err(RdtError::RequestHeader(header));
        }
        let code = u16::from_be_bytes([b[2], b[3]]);
        let command = Command::try_from(u32::from(code)).map_err(|_| RdtError::Command(code))?;
        Ok(Self {
            command,
            count: u32::from_be_bytes([b[4], b[5], b[6], b[7]]),
        })
    }
}

/// One record: a sample of the six axes in counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Record {
    /// The record's place in its stream: 1 for the first after a streaming request.
    pub rdt_sequence: u32,
    /// The device's sample number, free-running at its internal rate.
    pub ft_sequence: u32,
    /// The device's status word (0: healthy).
    pub status: u32,
    /// Fx, Fy, Fz, Tx, Ty, Tz in counts.
    pub counts: [i32; 6],
}

impl Record {
    /// The record's bytes.
    pub fn encode(&self) -> [u8; RECORD_LEN] {
        let mut b = [0u8; RECORD_LEN];
        b[0..4].copy_from_slice(&self.rdt_sequence.to_be_bytes());
        b[4..8].copy_from_slice(&self.ft_sequence.to_be_bytes());
        b[8..12].copy_from_slice(&self.status.to_be_bytes());
        for (i, c) in self.counts.iter().enumerate() {
            b[12 + 4 * i..16 + 4 * i].copy_from_slice(&c.to_be_bytes());
        }
        b
    }

    /// A record from its 36 bytes.
    pub fn decode(b: &[u8; RECORD_LEN]) -> Self {
        let u = |i: usize| u32::from_be_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        let mut counts = [0i32; 6];
        for (i, c) in counts.iter_mut().enumerate() {
            *c = u(12 + 4 * i) as i32;
        }
        Self {
            rdt_sequence: u(0),
            ft_sequence: u(4),
            status: u(8),
            counts,
        }
    }

    /// The records of a datagram (1 to [`MAX_RECORDS_PER_PACKET`] whole records).
    pub fn decode_packet(b: &[u8]) -> Result<impl Iterator<Item = Record> + '_, RdtError> {
        if b.is_empty()
            || !b.len().is_multiple_of(RECORD_LEN)
            || b.len() / RECORD_LEN > MAX_RECORDS_PER_PACKET
        {
            return Err(RdtError::PacketLength(b.len()));
        }
        Ok(b.chunks_exact(RECORD_LEN)
            .map(|c| Record::decode(c.try_into().expect("chunks of RECORD_LEN"))))
    }
}

/// The device's status word, as far as afs reads it: zero is healthy; any other value keeps
/// the record from the servo. Bit 31 is the manual's summary bit (an error is present); the
/// other bits are device-specific and reported as the raw word.
pub fn status_healthy(status: u32) -> bool {
    status == 0
}

/// Counts to SI units: the device's calibration (counts per N and per N·m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// Counts per newton.
    pub counts_per_force: f64,
    /// Counts per newton-metre.
    pub counts_per_torque: f64,
}

impl Default for Calibration {
    fn default() -> Self {
        Self {
            counts_per_force: DEFAULT_COUNTS_PER_FORCE,
            counts_per_torque: DEFAULT_COUNTS_PER_TORQUE,
        }
    }
}

impl Calibration {
    /// Refuses a calibration that is not a positive finite number of counts.
    pub fn validate(&self) -> Result<(), crate::error::ConfigError> {
        for (name, v) in [
            ("counts_per_force", self.counts_per_force),
            ("counts_per_torque", self.counts_per_torque),
        ] {
            if !(v.is_finite() && (1.0..=1e9).contains(&v)) {
                return Err(crate::error::ConfigError::setting(
                    name,
                    v,
                    "must lie in [1, 1e9] counts (read it off the device's calibration page)",
                ));
            }
        }
        Ok(())
    }

    /// Fx, Fy, Fz (N) and Tx, Ty, Tz (N·m) of a record's counts.
    pub fn to_si(&self, counts: &[i32; 6]) -> [f64; 6] {
        let mut v = [0.0; 6];
        for (i, c) in counts.iter().enumerate() {
            let per = if i < 3 {
                self.counts_per_force
            } else {
                self.counts_per_torque
            };
            v[i] = f64::from(*c) / per;
        }
        v
    }

    /// Counts of six SI values, rounded to the nearest count and held at the `i32` range
    /// (`true`: an axis was held). Non-finite values give `i32::MAX` and `true`.
    pub fn to_counts(&self, si: &[f64; 6]) -> ([i32; 6], bool) {
        let mut c = [0i32; 6];
        let mut held = false;
        for (i, v) in si.iter().enumerate() {
            let per = if i < 3 {
                self.counts_per_force
            } else {
                self.counts_per_torque
            };
            let x = (v * per).round();
            if !x.is_finite() || x > f64::from(i32::MAX) || x < f64::from(i32::MIN) {
                held = true;
                c[i] = if x < 0.0 { i32::MIN } else { i32::MAX };
            } else {
                c[i] = x as i32;
            }
        }
        (c, held)
    }
}

/// Which of the sensor's coordinate planes is afs's plane of motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Plane {
    /// afs's x, y are the sensor's x, y; its moment is Tz.
    #[default]
    Xy,
    /// afs's x, y are the sensor's y, z; its moment is Tx.
    Yz,
    /// afs's x, y are the sensor's z, x; its moment is Ty.
    Zx,
}

impl Plane {
    /// The plane from its name (`xy`, `yz`, `zx`).
    pub fn from_name(s: &str) -> Option<Self> {
        match s {
            "xy" => Some(Plane::Xy),
            "yz" => Some(Plane::Yz),
            "zx" => Some(Plane::Zx),
            _ => None,
        }
    }

    /// The sensor axes (0 x, 1 y, 2 z) that are afs's x, y and the plane's normal; the three
    /// are a right-handed frame.
    fn axes(self) -> [usize; 3] {
        match self {
            Plane::Xy => [0, 1, 2],
            Plane::Yz => [1, 2, 0],
            Plane::Zx => [2, 0, 1],
        }
    }
}

/// How the sensor is mounted: afs's planar sensor frame is the sensor's `plane`, turned by
/// `angle_rad` about the plane's normal (afs's x is the plane's first axis turned by the angle).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Mounting {
    /// The plane of motion in the sensor's axes.
    pub plane: Plane,
    /// The angle from the plane's first axis to afs's x, about the normal (rad).
    pub angle_rad: f64,
}

impl Mounting {
    /// afs's planar wrench (Fx, Fy in afs's frame; the moment about the normal) from the
    /// sensor's six axes: `f = R(−angle) [F·e1, F·e2]`, `τ = T·n`.
    pub fn planar(&self, six: &[f64; 6]) -> Wrench {
        let [a, b, n] = self.plane.axes();
        let (s, c) = self.angle_rad.sin_cos();
        let (f1, f2) = (six[a], six[b]);
        Wrench {
            force: Vec2::new(c * f1 + s * f2, -s * f1 + c * f2),
            torque: six[3 + n],
        }
    }

    /// The sensor's six axes of a planar wrench (the out-of-plane ones zero): the inverse of
    /// [`Mounting::planar`], for the emulator.
    pub fn six(&self, w: Wrench) -> [f64; 6] {
        let [a, b, n] = self.plane.axes();
        let (s, c) = self.angle_rad.sin_cos();
        let mut v = [0.0; 6];
        v[a] = c * w.force.x - s * w.force.y;
        v[b] = s * w.force.x + c * w.force.y;
        v[3 + n] = w.torque;
        v
    }
}

/// What a receiver makes of a record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Newer than every record before it; `lost` records of the stream were skipped.
    Fresh {
        /// Records missing between the previous fresh one and this one.
        lost: u32,
    },
    /// The same `rdt_sequence` as the newest record: a duplicate.
    Repeated,
    /// Older than the newest record: overtaken on the way (or a stale datagram).
    Reordered,
}

/// Keeps a stream's order by `rdt_sequence`, across its wrap at 2^32: a record is newer than
/// another when the difference, modulo 2^32, is below 2^31.
#[derive(Debug, Clone, Copy, Default)]
pub struct SequenceTracker {
    newest: Option<u32>,
}

impl SequenceTracker {
    /// Starts a new stream (after a streaming request: the device numbers it from 1 again).
    pub fn restart(&mut self) {
        self.newest = None;
    }

    /// Judges a record's `rdt_sequence`.
    pub fn judge(&mut self, rdt_sequence: u32) -> Verdict {
        let Some(newest) = self.newest else {
            self.newest = Some(rdt_sequence);
            return Verdict::Fresh { lost: 0 };
        };
        let d = rdt_sequence.wrapping_sub(newest);
        if d == 0 {
            Verdict::Repeated
        } else if d < 1 << 31 {
            self.newest = Some(rdt_sequence);
            Verdict::Fresh { lost: d - 1 }
        } else {
            Verdict::Reordered
        }
    }
}

/// How late records arrive: the excess of each record's receipt over the earliest it could
/// have arrived, `receipt − (offset + ft_sequence·period)`, where the offset is the smallest
/// `receipt − ft_sequence·period` seen (the least-delayed record) in the present and the last
/// window. ft_sequence is unwrapped to 64 bits; a jump backwards (the device restarted) or by
/// more than a minute starts again.
#[derive(Debug, Clone, Copy)]
pub struct Lateness {
    period_ns: f64,
    window_ns: u64,
    last_ft: Option<u32>,
    ft: u64,
    window_start_ns: u64,
    min_this: f64,
    min_last: f64,
}

impl Lateness {
    /// At the device's sample period, the offset's window `window_ns` long (the device's
    /// clock drifts against ours; a window of a second follows it to well under a sample).
    pub fn new(period_ns: f64, window_ns: u64) -> Self {
        Self {
            period_ns,
            window_ns,
            last_ft: None,
            ft: 0,
            window_start_ns: 0,
            min_this: f64::INFINITY,
            min_last: f64::INFINITY,
        }
    }

    /// The excess delay of a record (ns, ≥ 0) received at `receipt_ns`.
    pub fn observe(&mut self, ft_sequence: u32, receipt_ns: u64) -> f64 {
        if let Some(last) = self.last_ft {
            let d = ft_sequence.wrapping_sub(last);
            let minute = (60e9 / self.period_ns) as u32;
            if d < 1 << 31 && d <= minute {
                self.ft += u64::from(d);
            } else if d >= 1 << 31 && d.wrapping_neg() <= minute {
                // An older record (reordered): place it without moving the newest.
                let back = u64::from(d.wrapping_neg());
                let t = receipt_ns as f64 - self.ft.saturating_sub(back) as f64 * self.period_ns;
                return (t - self.min_this.min(self.min_last)).max(0.0);
            } else {
                *self = Self::new(self.period_ns, self.window_ns);
            }
        }
        if self.last_ft.is_none() {
            self.window_start_ns = receipt_ns;
        }
        self.last_ft = Some(ft_sequence);
        let t = receipt_ns as f64 - self.ft as f64 * self.period_ns;
        if receipt_ns >= self.window_start_ns + self.window_ns {
            self.min_last = self.min_this;
            self.min_this = f64::INFINITY;
            self.window_start_ns = receipt_ns;
        }
        self.min_this = self.min_this.min(t);
        (t - self.min_this.min(self.min_last)).max(0.0)
    }
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;
