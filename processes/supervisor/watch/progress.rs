//! The supervisor's status stream (`afs/supervisor/status`, 2 Hz) and its progress line.

use super::Supervisor;
use crate::observe::topics::Rec;
use crate::rt;
use afs_shared::msg::{self, ProcessStatus, SupervisorStatus, fixed_str};
use std::time::{Duration, Instant};

impl Supervisor {
    /// Publishes (and records) the supervisor's status every 0.5 s.
    pub(super) fn publish_status(&mut self) {
        if self.last_status.elapsed() < Duration::from_millis(500) {
            return;
        }
        self.send_status(msg::SupervisorPhase::Running);
    }

    /// Publishes (and records) the supervisor's status now.
    pub(super) fn send_status(&mut self, phase: msg::SupervisorPhase) {
        self.last_status = Instant::now();
        self.status_seq += 1;
        let mut st = SupervisorStatus {
            version: SupervisorStatus::VERSION,
            process_count: self.procs.len() as u32,
            seq: self.status_seq,
            publish_ns: rt::monotonic_ns(),
            pid: std::process::id() as i32,
            phase: phase.into(),
            scenario: fixed_str(self.scenario_name),
            elapsed_s: self.last_time_s,
            duration_s: self.duration,
            ..Default::default()
        };
        for (i, p) in self.procs.iter().enumerate().take(msg::MAX_PROCESSES) {
            st.processes[i] = ProcessStatus {
                name: fixed_str(&p.spec.name),
                pid: p.pid(),
                state: p.state.into(),
                restarts: p.restarts,
                last_exit: p.last_exit.unwrap_or(i32::MIN),
            };
        }
        let _ = self.ports.status.send_copy(st);
        self.sinks.push(Rec::Status(Box::new(st)));
    }

    /// A progress line on stderr every second (rewritten in place on a terminal).
    pub(super) fn print_progress(&mut self, tty: bool) {
        if !self.progress || self.last_progress.elapsed() < Duration::from_secs(1) {
            return;
        }
        self.last_progress = Instant::now();
        let r = self.monitor.report();
        let restarts: u32 = self.procs.iter().map(|p| p.restarts).sum();
        let (jit, age) = self.stats.as_ref().map_or((0.0, 0.0), |st| {
            (
                st.wake_latency.p99 as f64 / 1000.0,
                st.force_age.p99 as f64 / 1000.0,
            )
        });
        let figures = match &r.insertion {
            Some(i) => format!(
                "depth {:5.2} mm  peak force {:5.2} N  jammed ticks {}",
                i.depth_mm, i.peak_force_n, i.jammed_ticks
            ),
            None => format!(
                "travelled {:5.1} mm  tangent err RMS {:4.2}°  estimates {}",
                r.tracking.travelled_m * 1e3,
                r.tracking.tangent_error_rms_deg,
                r.tracking.estimations.estimates,
            ),
        };
        let line = format!(
            "afs: {:6.1}/{:.0} s  {figures}  safe ticks {}  wake p99 {jit:5.1} µs  force age p99 {age:5.1} µs  restarts {restarts}",
            self.last_time_s, self.duration, r.safe_ticks,
        );
        if tty {
            eprint!("\r{line}\x1b[K");
        } else {
            eprintln!("{line}");
        }
    }
}
