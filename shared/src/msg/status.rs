//! Low-rate status: the servo loop's statistics, the estimator's friction identification, the
//! supervisor's view of the stack and the boards' start-up reports.

use crate::watchdog::GateCounters;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

wire_struct! {
    /// Percentiles of a latency distribution (ns).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::Quantiles")]
    pub struct Quantiles {
        /// Median.
        pub p50: u64,
        /// 90th percentile.
        pub p90: u64,
        /// 99th percentile.
        pub p99: u64,
        /// 99.9th percentile.
        pub p999: u64,
        /// 99.99th percentile.
        pub p9999: u64,
        /// Largest.
        pub max: u64,
    }
}

wire_code! {
    /// [`SensorStats::source`]: where the sensor board's samples come from.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
    #[serde(rename_all = "kebab-case")]
    pub enum SensorSource {
        /// The sensor model applied to the simulated world.
        Model = 0,
        /// A device (or its emulator) speaking ATI's RDT over UDP.
        Rdt = 1,
    }
}

wire_message! {
    version = 1;
    /// The sensor board's statistics since it started, published at 10 Hz. The `rdt_*` fields
    /// count what an RDT device sent; they stay 0 for the sensor model.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::SensorStats")]
    pub struct SensorStats {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// [`SensorSource`].
        pub source: u32,
        /// Publication index.
        pub seq: u64,
        /// Monotonic time of publication (ns).
        pub publish_ns: u64,
        /// Wrench samples published.
        pub published: u64,
        /// Model: periods that woke a whole period late.
        pub late_periods: u64,
        /// RDT: datagrams received.
        pub rdt_datagrams: u64,
        /// RDT: datagrams that were not whole records (refused).
        pub rdt_bad_datagrams: u64,
        /// RDT: records received.
        pub rdt_records: u64,
        /// RDT: records missing from the stream (gaps in `rdt_sequence` not filled later).
        pub rdt_lost: u64,
        /// RDT: records received twice.
        pub rdt_repeated: u64,
        /// RDT: records older than one already received.
        pub rdt_reordered: u64,
        /// RDT: records that arrived later than the late limit.
        pub rdt_late: u64,
        /// RDT: records with a non-zero status word.
        pub rdt_status_errors: u64,
        /// RDT: the last non-zero status word.
        pub rdt_last_status: u32,
        /// RDT: 1 while records arrive, 0 while the device is silent.
        pub rdt_streaming: u32,
        /// RDT: streaming requests sent (the first, and one per silence).
        pub rdt_requests: u64,
        /// RDT: time between datagrams (ns): the receive jitter around the device's period.
        pub rdt_interval: Quantiles,
        /// RDT: excess delay of the records over the least-delayed one (ns).
        pub rdt_excess_delay: Quantiles,
    }
}

wire_flags! {
    /// [`LoopStats::flags`]: what the real-time set-up achieved.
    pub struct LoopFlags {
        /// Running at SCHED_FIFO.
        const SCHED_FIFO = 1;
        /// Memory locked (mlockall).
        const MLOCKED = 2;
        /// Pinned to a CPU.
        const PINNED = 4;
    }
}

wire_message! {
    version = 2;
    /// The servo loop's statistics since it started, published at 10 Hz.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::LoopStats.v2")]
    pub struct LoopStats {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// [`LoopFlags`].
        pub flags: LoopFlags,
        /// Publication index.
        pub seq: u64,
        /// Monotonic time of publication (ns).
        pub publish_ns: u64,
        /// Servo period (ns).
        pub period_ns: u64,
        /// Ticks run.
        pub ticks: u64,
        /// Ticks that woke a whole period or more late, or overran their period.
        pub misses: u64,
        /// Wake-up latency: actual − scheduled wake time (ns).
        pub wake_latency: Quantiles,
        /// Execution time of a tick (ns).
        pub exec: Quantiles,
        /// Age of the force data at use (ns).
        pub force_age: Quantiles,
        /// The gate's verdicts on every force sample offered, since the first servo of the run (a
        /// restarted servo goes on counting from its predecessor's snapshot).
        pub gate: GateCounters,
        /// Of those, the samples flagged as injected (`afs chaos`'s bad samples): how many the
        /// servo received and how the gate judged them.
        pub injected: GateCounters,
        /// Ticks whose latest force sample was older than the limit.
        pub stale_ticks: u64,
        /// Entries into the safe state.
        pub safe_entries: u64,
        /// Ticks spent in the safe state.
        pub safe_ticks: u64,
        /// Estimator requests sent (including retries).
        pub requests: u64,
        /// Requests re-sent after a time-out.
        pub retries: u64,
        /// Answers received.
        pub answers: u64,
        /// Samples the servo could not publish (no memory to loan).
        pub publish_failures: u64,
        /// Commands received ([`ServoCommand`]).
        pub commands: u64,
        /// Commands refused (unknown version or command code).
        pub bad_commands: u64,
    }
}

wire_flags! {
    /// [`FrictionReport::status`].
    pub struct FrictionStatus {
        /// `mu` holds.
        const MU_VALID = 1;
        /// The eq. 4.5 coefficients hold.
        const LAW_VALID = 2;
    }
}

wire_message! {
    version = 1;
    /// On-line friction identification from the streams (estimator, about 1 Hz).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::FrictionReport")]
    pub struct FrictionReport {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// [`FrictionStatus`].
        pub status: FrictionStatus,
        /// Publication index.
        pub seq: u64,
        /// Monotonic time of publication (ns).
        pub publish_ns: u64,
        /// Steady undithered windows used.
        pub windows: u64,
        /// Distinct speed levels seen.
        pub speeds: u32,
        /// Padding (0).
        pub reserved: u32,
        /// Friction coefficient μ = mean friction / mean normal force, latest window.
        pub mu: f64,
        /// Spread of μ over the windows at that speed.
        pub mu_std: f64,
        /// Eq. 4.5: F_t (N at the reference normal force).
        pub kinetic_n: f64,
        /// F_v (N·s/m).
        pub viscous_n_s_per_m: f64,
        /// F_s (N).
        pub stribeck_n: f64,
        /// ẋ_s (m/s).
        pub stribeck_velocity_m_per_s: f64,
        /// RMS residual of the fit (N).
        pub rms_residual_n: f64,
    }
}

wire_struct! {
    /// One process in [`SupervisorStatus`].
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::ProcessStatus")]
    pub struct ProcessStatus {
        /// Name, NUL-padded UTF-8.
        pub name: [u8; 16],
        /// Process id (0: not running).
        pub pid: i32,
        /// [`ProcessState`] as its code.
        pub state: u32,
        /// Restarts so far.
        pub restarts: u32,
        /// Last exit status (−signal if killed, i32::MIN if none).
        pub last_exit: i32,
    }
}

/// Most processes a stack can have.
pub const MAX_PROCESSES: usize = 8;

wire_message! {
    version = 1;
    /// The supervisor's view of the stack (2 Hz).
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::SupervisorStatus")]
    pub struct SupervisorStatus {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// Number of valid entries in `processes`.
        pub process_count: u32,
        /// Publication index.
        pub seq: u64,
        /// Monotonic time of publication (ns).
        pub publish_ns: u64,
        /// Supervisor's process id.
        pub pid: i32,
        /// [`SupervisorPhase`] as its code.
        pub phase: u32,
        /// Scenario name, NUL-padded.
        pub scenario: [u8; 32],
        /// Seconds since the scenario started.
        pub elapsed_s: f64,
        /// Planned duration (s).
        pub duration_s: f64,
        /// The processes.
        pub processes: [ProcessStatus; MAX_PROCESSES],
    }
}

wire_code! {
    /// A board of the stack ([`BoardStartup::board`], the fault injector's targets).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
    #[serde(rename_all = "kebab-case")]
    pub enum Board {
        /// The plant/servo board.
        Servo = 0,
        /// The force-sensor board.
        Sensor = 1,
        /// The estimator board.
        Estimator = 2,
    }
}

impl Board {
    /// Every board, in start order.
    pub const ALL: [Board; 3] = [Board::Servo, Board::Sensor, Board::Estimator];

    /// The process name in the stack file.
    pub const fn name(self) -> &'static str {
        match self {
            Board::Servo => "servo",
            Board::Sensor => "sensor",
            Board::Estimator => "estimator",
        }
    }

    /// The board of a process name (None: another process).
    pub fn from_name(name: &str) -> Option<Board> {
        Self::ALL.into_iter().find(|b| b.name() == name)
    }
}

wire_code! {
    /// [`ProcessStatus::state`].
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
    #[serde(rename_all = "snake_case")]
    pub enum ProcessState {
        /// Being started.
        Starting = 0,
        /// Running.
        Running = 1,
        /// Waiting to be restarted.
        Restarting = 2,
        /// Ended and not restarted.
        Exited = 3,
        /// Gave up (restart limit).
        Failed = 4,
    }
}

wire_code! {
    /// [`SupervisorStatus::phase`].
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
    #[serde(rename_all = "snake_case")]
    pub enum SupervisorPhase {
        /// Starting the boards.
        Starting = 0,
        /// Running the scenario.
        Running = 1,
        /// Stopping the boards.
        Stopping = 2,
    }
}

wire_message! {
    version = 1;
    /// A board process's start-up, phase by phase, published once when its data first flows: what
    /// a (re)start spent its time on. Each field is the monotonic time (ns) the phase ended; 0 if
    /// the board has no such phase.
    #[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend, Serialize)]
    #[type_name("afs::BoardStartup")]
    pub struct BoardStartup {
        /// The layout version, `Self::VERSION` (docs/messages.md).
        pub version: u32,
        /// Which ([`Board`] as its code).
        pub board: u32,
        /// Its process id.
        pub pid: i32,
        /// Reserved (0).
        pub reserved: u32,
        /// `main` entered (after the loader and the command line).
        pub main_ns: u64,
        /// The iceoryx2 node created (with the dead-node clean-up iceoryx2 does on creation).
        pub node_ns: u64,
        /// Its services opened and ports created.
        pub ports_ns: u64,
        /// The board's own preparation done: the sensor model and its tare, the servo's world
        /// restored from the snapshot.
        pub prepared_ns: u64,
        /// First input in hand: the sensor's first world sample, the servo's first good force
        /// sample.
        pub input_ns: u64,
        /// Real-time set-up done (memory locked, pinned, SCHED_FIFO).
        pub rt_ns: u64,
        /// First output published.
        pub data_ns: u64,
    }
}
