//! The sensor board's RDT source: a force/torque sensor (ATI Net F/T, Axia80, or `afs-netft`)
//! streaming records over UDP. The board asks for a real-time stream (optionally biasing the
//! device first), blocks on the socket with a short time-out (no busy wait, also at SCHED_FIFO),
//! stamps each datagram at receipt and publishes one `WrenchSample` per fresh, healthy, timely
//! record. Lost, repeated, reordered and late records, non-zero status words and datagrams that
//! are not records are counted on `afs/sensor/stats` and never published. A silent device asks
//! for the stream again every `silence_ms`; the servo meanwhile sees no fresh force and goes
//! safe, as for a dead sensor board. docs/sensor.md.

use super::{SensorArgs, SensorSummary, StatsOut};
use crate::boards::Startup;
use crate::{hist, ipc, rt};
use afs_shared::msg::{Board, SensorSource, SensorStats, WrenchFlags, WrenchSample};
use afs_shared::rdt::{
    Calibration, Command, Lateness, MAX_RECORDS_PER_PACKET, Mounting, RECORD_LEN, Record, Request,
    SequenceTracker, Verdict, status_healthy,
};
use anyhow::{Context, Result, bail};
use hdrhistogram::Histogram;
use std::io::ErrorKind;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// How to reach and read the device.
#[derive(Debug, Clone)]
pub struct RdtSettings {
    /// The device's address and port.
    pub address: SocketAddr,
    /// Its counts per N and per N·m.
    pub calibration: Calibration,
    /// How it is mounted (which plane is afs's).
    pub mounting: Mounting,
    /// Send "set bias" before streaming (only with the sensor unloaded, in free air).
    pub bias: bool,
    /// The device's internal sample rate (Hz): the rate of `ft_sequence`.
    pub rate_hz: f64,
    /// A record whose excess delay passes this is late and not published (ms).
    pub late_ms: f64,
    /// Silent this long (ms): ask for the stream again.
    pub silence_ms: f64,
    /// Local UDP port (0: any). A board restarted on the same port is the same client to the
    /// device, which streams to one client and ignores others until stopped.
    pub local_port: u16,
}

impl RdtSettings {
    /// Refuses settings that cannot work.
    pub fn validate(&self) -> Result<()> {
        self.calibration.validate()?;
        for (name, v, lo, hi) in [
            ("rate", self.rate_hz, 10.0, 100_000.0),
            ("late limit (ms)", self.late_ms, 0.01, 1000.0),
            ("silence (ms)", self.silence_ms, 1.0, 60_000.0),
        ] {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                bail!("the RDT {name} {v} must lie in [{lo}, {hi}]");
            }
        }
        if !self.mounting.angle_rad.is_finite() {
            bail!("the mounting angle must be a finite number of degrees");
        }
        Ok(())
    }
}

/// What one wait on the socket gave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Poll {
    /// A datagram (records published or counted).
    Datagram,
    /// Nothing within the time-out.
    Quiet,
    /// The device's host refused (nothing listens on the port).
    Refused,
}

/// The receiving end: socket, order and lateness tracking, counters.
pub struct Receiver {
    socket: UdpSocket,
    settings: RdtSettings,
    period_ns: f64,
    ft: SequenceTracker,
    rdt: SequenceTracker,
    lateness: Lateness,
    backwards_run: u32,
    late_run: u32,
    resync_after: u32,
    last_rx_ns: u64,
    last_request_ns: u64,
    biased: bool,
    buf: Box<[u8; RECORD_LEN * MAX_RECORDS_PER_PACKET + 1]>,
    /// The counters (`rdt_*` fields of the statistics message).
    pub stats: SensorStats,
    /// Time between datagrams (ns).
    pub interval: Histogram<u64>,
    /// Excess delay of the records (ns).
    pub excess: Histogram<u64>,
    /// Size of the last datagram that was not records.
    pub last_bad_size: usize,
    epoch_ns: u64,
    seq: u64,
}

impl Receiver {
    /// A socket connected to the device (nothing sent yet).
    pub fn connect(settings: &RdtSettings) -> Result<Self> {
        settings.validate()?;
        let any: std::net::IpAddr = if settings.address.is_ipv4() {
            std::net::Ipv4Addr::UNSPECIFIED.into()
        } else {
            std::net::Ipv6Addr::UNSPECIFIED.into()
        };
        let local = SocketAddr::new(any, settings.local_port);
        let socket = UdpSocket::bind(local)
            .with_context(|| format!("opening a UDP socket on local port {}: is another client of the sensor running on it?", settings.local_port))?;
        socket
            .connect(settings.address)
            .with_context(|| format!("addressing the sensor at {}", settings.address))?;
        socket
            .set_read_timeout(Some(Duration::from_millis(20)))
            .context("setting the socket's time-out")?;
        let period_ns = 1e9 / settings.rate_hz;
        Ok(Self {
            socket,
            settings: settings.clone(),
            period_ns,
            ft: SequenceTracker::default(),
            rdt: SequenceTracker::default(),
            lateness: Lateness::new(period_ns, 1_000_000_000),
            backwards_run: 0,
            late_run: 0,
            resync_after: ((0.05 * settings.rate_hz) as u32).max(50),
            last_rx_ns: 0,
            last_request_ns: 0,
            biased: false,
            buf: Box::new([0; RECORD_LEN * MAX_RECORDS_PER_PACKET + 1]),
            stats: SensorStats {
                version: SensorStats::VERSION,
                source: SensorSource::Rdt.into(),
                ..Default::default()
            },
            interval: hist::new()?,
            excess: hist::new()?,
            last_bad_size: 0,
            epoch_ns: rt::monotonic_ns(),
            seq: 0,
        })
    }

    fn send(&self, command: Command) -> std::io::Result<()> {
        let req = Request { command, count: 0 }.encode();
        self.socket.send(&req).map(|_| ())
    }

    /// Asks for a real-time stream (biasing first if set and not done yet).
    pub fn request_stream(&mut self) {
        if self.settings.bias && !self.biased {
            self.biased = self.send(Command::SetBias).is_ok();
        }
        // A refused send shows up again at the next receive; the request is retried after
        // the silence time.
        let _ = self.send(Command::RealTime);
        self.stats.rdt_requests += 1;
        self.last_request_ns = rt::monotonic_ns();
    }

    /// Asks the device to stop streaming.
    pub fn stop_stream(&self) {
        let _ = self.send(Command::Stop);
    }

    /// Waits up to 20 ms for a datagram; `out` gets each record worth publishing (stamped at
    /// receipt, the earlier records of a buffered datagram one device period apart).
    pub fn poll(&mut self, mut out: impl FnMut(WrenchSample)) -> Poll {
        let now = rt::monotonic_ns();
        let silence_ns = (self.settings.silence_ms * 1e6) as u64;
        if now.saturating_sub(self.last_rx_ns.max(self.last_request_ns)) >= silence_ns {
            self.stats.rdt_streaming = 0;
            self.request_stream();
        }
        let n = match self.socket.recv(&mut self.buf[..]) {
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::ConnectionRefused => {
                self.stats.rdt_streaming = 0;
                // Let the time-out pass instead of spinning on the refusals.
                std::thread::sleep(Duration::from_millis(20));
                return Poll::Refused;
            }
            Err(_) => return Poll::Quiet,
        };
        let receipt = rt::monotonic_ns();
        self.stats.rdt_datagrams += 1;
        if self.last_rx_ns != 0 {
            hist::record(&mut self.interval, receipt - self.last_rx_ns);
        }
        self.last_rx_ns = receipt;
        self.stats.rdt_streaming = 1;
        let Ok(records) = Record::decode_packet(&self.buf[..n]) else {
            self.stats.rdt_bad_datagrams += 1;
            self.last_bad_size = n;
            return Poll::Datagram;
        };
        let count = n / RECORD_LEN;
        let last: &[u8; RECORD_LEN] = self.buf[(count - 1) * RECORD_LEN..n]
            .try_into()
            .expect("a whole record");
        let last_ft = Record::decode(last).ft_sequence;
        for r in records {
            self.stats.rdt_records += 1;
            match self.ft.judge(r.ft_sequence) {
                Verdict::Repeated => {
                    self.stats.rdt_repeated += 1;
                    continue;
                }
                Verdict::Reordered => {
                    self.stats.rdt_reordered += 1;
                    // Counted lost when its successor came: it was late, not lost.
                    if self.rdt.judge(r.rdt_sequence) == Verdict::Reordered {
                        self.stats.rdt_lost = self.stats.rdt_lost.saturating_sub(1);
                    }
                    self.backwards_run += 1;
                    if self.backwards_run >= self.resync_after {
                        // The device started again (its sample count went back): follow it.
                        self.ft.restart();
                        self.rdt.restart();
                        self.lateness = Lateness::new(self.period_ns, 1_000_000_000);
                        self.backwards_run = 0;
                    }
                    continue;
                }
                Verdict::Fresh { .. } => self.backwards_run = 0,
            }
            match self.rdt.judge(r.rdt_sequence) {
                Verdict::Fresh { lost } => self.stats.rdt_lost += u64::from(lost),
                // Newer by the device's count but not by the stream's: a new stream.
                _ => {
                    self.rdt.restart();
                    self.rdt.judge(r.rdt_sequence);
                }
            }
            let back = f64::from(last_ft.wrapping_sub(r.ft_sequence)) * self.period_ns;
            let sample_ns = receipt.saturating_sub(back as u64);
            let excess = self.lateness.observe(r.ft_sequence, sample_ns);
            hist::record(&mut self.excess, excess as u64);
            if !status_healthy(r.status) {
                self.stats.rdt_status_errors += 1;
                self.stats.rdt_last_status = r.status;
                continue;
            }
            if excess > self.settings.late_ms * 1e6 {
                self.stats.rdt_late += 1;
                self.late_run += 1;
                if self.late_run >= self.resync_after {
                    // Every record late for 0.05 s: the device's clock jumped (it skipped
                    // samples or restarted), not the network; measure from here again.
                    self.lateness = Lateness::new(self.period_ns, 1_000_000_000);
                    self.late_run = 0;
                }
                continue;
            }
            self.late_run = 0;
            let six = self.settings.calibration.to_si(&r.counts);
            let w = self.settings.mounting.planar(&six);
            let saturated = r.counts.iter().any(|c| *c == i32::MAX || *c == i32::MIN);
            let sample = WrenchSample {
                version: WrenchSample::VERSION,
                flags: if saturated {
                    WrenchFlags::SATURATED
                } else {
                    WrenchFlags::empty()
                },
                seq: self.seq,
                epoch_ns: self.epoch_ns,
                plant_seq: 0,
                plant_tick_ns: 0,
                sample_ns,
                publish_ns: rt::monotonic_ns(),
                force_n: [w.force.x, w.force.y],
                torque_nm: w.torque,
                tare_force_n: [0.0; 2],
                tare_torque_nm: 0.0,
            };
            self.seq += 1;
            out(sample);
        }
        Poll::Datagram
    }
}

/// Runs the board's RDT source until `stop` is set: every fresh record on the wrench topic.
pub fn run_board(
    args: &SensorArgs,
    settings: &RdtSettings,
    stop: &AtomicBool,
) -> Result<SensorSummary> {
    let mut startup = Startup::new(Board::Sensor, args.main_ns);
    let node = ipc::node(&args.prefix, Board::Sensor.name())?;
    startup.report.node_ns = Startup::now();
    let publisher = super::wrench_publisher(&node)?;
    let mut stats = StatsOut::open(&node, SensorSource::Rdt)?;
    startup.open(&node)?;
    startup.report.ports_ns = Startup::now();
    let mut rx = Receiver::connect(settings)?;
    startup.report.prepared_ns = Startup::now();
    super::go_realtime(&mut startup, args);
    let mut summary = SensorSummary::default();
    rx.request_stream();
    let mut connections = rt::Every::new(rt::CONNECTIONS_EVERY_NS, rt::monotonic_ns());
    while !stop.load(Ordering::Relaxed) {
        rx.poll(|mut w| {
            if startup.report.input_ns == 0 {
                startup.report.input_ns = w.sample_ns;
            }
            w.publish_ns = rt::monotonic_ns();
            if publisher.send_copy(w).is_ok() {
                summary.published += 1;
                if summary.published == 1 {
                    startup.report.data_ns = w.publish_ns;
                    startup.send();
                }
            }
        });
        let now = rt::monotonic_ns();
        if stats.due(now) {
            copy_counters(&rx, &mut stats.stats, summary.published);
            stats.publish(now);
        }
        if connections.due(now) {
            startup.update_connections();
        }
    }
    rx.stop_stream();
    Ok(summary)
}

/// The receiver's counters into the statistics message.
pub fn copy_counters(rx: &Receiver, out: &mut SensorStats, published: u64) {
    let (seq, publish_ns) = (out.seq, out.publish_ns);
    *out = rx.stats;
    out.seq = seq;
    out.publish_ns = publish_ns;
    out.published = published;
    out.rdt_interval = hist::quantiles(&rx.interval);
    out.rdt_excess_delay = hist::quantiles(&rx.excess);
}

/// The command-line options of an RDT source (`afs-sensor --source rdt`, `afs sensor`).
#[derive(Debug, Clone, clap::Args)]
pub struct RdtArgs {
    /// The sensor's address: a host name or IP, optionally with `:port`.
    #[arg(long)]
    pub address: Option<String>,
    /// The sensor's RDT port (when the address has none).
    #[arg(long, default_value_t = afs_shared::rdt::PORT)]
    pub port: u16,
    /// Counts per newton (the device's calibration page: "counts per force").
    #[arg(long, default_value_t = afs_shared::rdt::DEFAULT_COUNTS_PER_FORCE)]
    pub counts_per_force: f64,
    /// Counts per newton-metre ("counts per torque").
    #[arg(long, default_value_t = afs_shared::rdt::DEFAULT_COUNTS_PER_TORQUE)]
    pub counts_per_torque: f64,
    /// The sensor's plane that is afs's plane of motion: xy, yz or zx.
    #[arg(long, default_value = "xy", value_parser = ["xy", "yz", "zx"])]
    pub plane: String,
    /// Angle from the plane's first axis to afs's x, about the plane's normal (degrees).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub angle_deg: f64,
    /// Bias (zero) the sensor before streaming: only with the sensor unloaded, in free air.
    #[arg(long)]
    pub bias: bool,
    /// A record delayed this much beyond the least-delayed one is late and not used (ms).
    #[arg(long, default_value_t = 1.0)]
    pub late_ms: f64,
    /// Ask for the stream again after this long without a datagram (ms).
    #[arg(long, default_value_t = 100.0)]
    pub silence_ms: f64,
    /// Local UDP port to receive on (0: any free one). Give a fixed one to a supervised board:
    /// a restarted board is then the same client to the device, which serves one client at a
    /// time and would ignore a new one while it still streams to the old.
    #[arg(long, default_value_t = 0)]
    pub local_port: u16,
}

impl RdtArgs {
    /// The settings, for a device sampling at `rate_hz`.
    pub fn settings(&self, rate_hz: f64) -> Result<RdtSettings> {
        use std::net::ToSocketAddrs;
        let Some(a) = &self.address else {
            bail!("an RDT source needs the sensor's address: --address HOST[:PORT]");
        };
        let resolved = if let Ok(sa) = a.parse::<SocketAddr>() {
            Ok(vec![sa])
        } else if let Ok(ip) = a.parse::<std::net::IpAddr>() {
            Ok(vec![SocketAddr::new(ip, self.port)])
        } else if a.contains(':') {
            a.to_socket_addrs().map(Iterator::collect)
        } else {
            (a.as_str(), self.port)
                .to_socket_addrs()
                .map(Iterator::collect)
        };
        let address = resolved
            .with_context(|| format!("resolving the sensor's address '{a}'"))?
            .into_iter()
            .next()
            .with_context(|| format!("the sensor's address '{a}' resolves to nothing"))?;
        let plane = afs_shared::rdt::Plane::from_name(&self.plane)
            .with_context(|| format!("unknown plane '{}' (xy, yz or zx)", self.plane))?;
        let s = RdtSettings {
            address,
            calibration: Calibration {
                counts_per_force: self.counts_per_force,
                counts_per_torque: self.counts_per_torque,
            },
            mounting: Mounting {
                plane,
                angle_rad: self.angle_deg.to_radians(),
            },
            bias: self.bias,
            rate_hz,
            late_ms: self.late_ms,
            silence_ms: self.silence_ms,
            local_port: self.local_port,
        };
        s.validate()?;
        Ok(s)
    }
}
