//! Real-time plumbing for the process shells: the monotonic clock every timestamp uses,
//! absolute-time sleeps, SCHED_FIFO, mlockall and CPU affinity. Each setting degrades to a
//! warning where the system refuses it; nothing here busy-spins.

use std::io;

/// `CLOCK_MONOTONIC` in nanoseconds: the one clock of every timestamp in the stack.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the timespec we own; CLOCK_MONOTONIC always exists on
    // Linux.
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// The deadline after `deadline` for a loop of `period` (ns) that finished its work at `now`:
/// one period on, or, far behind (stopped in a debugger, the machine suspended, more than 100
/// periods), re-anchored one period after `now` instead of a burst of late periods.
pub fn next_deadline(deadline: u64, period: u64, now: u64) -> u64 {
    let next = deadline + period;
    if now > next + 100 * period {
        now + period
    } else {
        next
    }
}

/// How often a board drops the connections of dead peers and connects restarted ones on its
/// rarely-used ports (ns): by the clock, so a 1-kHz or 500-Hz loop does it as soon as a 10-kHz
/// one.
pub const CONNECTIONS_EVERY_NS: u64 = 100_000_000;

/// A chore due every `interval_ns` of the monotonic clock, whatever a loop's rate: a loop that
/// counted its own ticks would do it ten times less often at 1 kHz than at 10 kHz.
#[derive(Debug, Clone, Copy)]
pub struct Every {
    interval_ns: u64,
    next_ns: u64,
}

impl Every {
    /// First due `interval_ns` after `now_ns`.
    pub fn new(interval_ns: u64, now_ns: u64) -> Self {
        Self {
            interval_ns,
            next_ns: now_ns + interval_ns,
        }
    }

    /// Whether the chore is due at `now_ns`; if so, the next one is `interval_ns` on from now
    /// (a loop that skips a check does the chore once, not a burst).
    pub fn due(&mut self, now_ns: u64) -> bool {
        if now_ns < self.next_ns {
            return false;
        }
        self.next_ns = now_ns + self.interval_ns;
        true
    }
}

/// Sleeps until the monotonic time `deadline_ns` (absolute, so periods do not drift). Returns
/// at once if the deadline has passed; resumes after signals.
pub fn sleep_until(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: the timespec is valid; the remaining-time pointer may be null with
        // TIMER_ABSTIME.
        let r = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if r != libc::EINTR {
            return;
        }
    }
}

/// What the real-time set-up achieved.
#[derive(Debug, Clone, Default)]
pub struct RtReport {
    /// Running at SCHED_FIFO.
    pub fifo: bool,
    /// Memory locked.
    pub mlocked: bool,
    /// Pinned to the requested CPU.
    pub pinned: bool,
    /// What was refused, one line each.
    pub warnings: Vec<String>,
}

/// Asks for SCHED_FIFO at `priority` (1–99; 0 leaves the normal scheduler), `mlockall` when
/// `lock_memory`, and affinity to `cpu` when given. Anything refused becomes a warning.
pub fn setup(priority: u8, lock_memory: bool, cpu: Option<usize>) -> RtReport {
    let mut r = RtReport::default();
    if lock_memory {
        // Everything mapped now is faulted in and locked. Later mappings are locked page by
        // page as they are first touched (MCL_ONFAULT): a peer that restarts brings a new
        // shared-memory segment of up to tens of MB, and populating all of it at connection
        // time (plain MCL_FUTURE) stalled the servo's tick for milliseconds.
        // SAFETY: plain syscalls with flag arguments.
        let rc = unsafe {
            match libc::mlockall(libc::MCL_CURRENT) {
                0 => libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE | libc::MCL_ONFAULT),
                e => e,
            }
        };
        if rc == 0 {
            r.mlocked = true;
        } else {
            r.warnings.push(format!(
                "mlockall refused ({}); page faults may add latency (raise RLIMIT_MEMLOCK or run as root)",
                io::Error::last_os_error()
            ));
        }
    }
    if let Some(cpu) = cpu {
        let n = available_cpus();
        if cpu >= n {
            r.warnings.push(format!(
                "pinning to CPU {cpu} skipped: it does not exist here ({n} CPUs)"
            ));
        } else {
            // SAFETY: cpu_set_t is plain data; CPU_SET indexes within its size (cpu < n).
            let rc = unsafe {
                let mut set: libc::cpu_set_t = std::mem::zeroed();
                libc::CPU_SET(cpu, &mut set);
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
            };
            if rc == 0 {
                r.pinned = true;
            } else {
                r.warnings.push(format!(
                    "pinning to CPU {cpu} refused ({})",
                    io::Error::last_os_error()
                ));
            }
        }
    }
    if priority > 0 {
        let param = libc::sched_param {
            sched_priority: i32::from(priority.min(99)),
        };
        // SAFETY: plain syscall on this process with a valid sched_param.
        let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
        if rc == 0 {
            r.fifo = true;
        } else {
            let err = io::Error::last_os_error();
            // The normal scheduler rounds a sleep's end up by the thread's timer slack (50 µs
            // by default), half a 10-kHz period; any user may shrink it to 1 ns.
            // SAFETY: plain prctl on this thread with an integer argument.
            let slack = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong) } == 0;
            r.warnings.push(format!(
                "SCHED_FIFO priority {priority} refused ({err}); running at normal priority{} (needs CAP_SYS_NICE or root)",
                if slack {
                    " with a timer slack of 1 ns"
                } else {
                    ""
                }
            ));
        }
    }
    r
}

/// Where this user may not run at SCHED_FIFO, lowers the calling thread (and the threads it
/// starts from then on) to nice 10 and says so: the servo and the sensor, refused SCHED_FIFO
/// too, then run at nice 0 beside it, and the normal scheduler weighs them about ten times as
/// heavily (its weights for nice 0 and 10 are 1024 and 110). Not SCHED_IDLE, which favours
/// them further but starves: the estimator pinned beside `afs bench`'s CPU hog at SCHED_IDLE
/// got no CPU to close down, and left its files. The boards that are not real-time (the
/// estimator, the link board) call it at start. None where SCHED_FIFO is permitted: the
/// real-time boards then outrank everything at normal priority anyway.
pub fn make_way_for_realtime() -> Option<String> {
    if fifo_permitted() {
        return None;
    }
    // SAFETY: setpriority on the calling thread (who 0) with a plain integer.
    let rc = unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, 10) };
    Some(if rc == 0 {
        "SCHED_FIFO is refused here, so the real-time boards run at normal priority: this \
         process runs at nice 10 to leave them the CPU"
            .into()
    } else {
        format!(
            "SCHED_FIFO is refused here and nice 10 too ({}); this process competes with the \
             real-time boards",
            io::Error::last_os_error()
        )
    })
}

/// Gives the CPU to the threads of the same class waiting for it (sched_yield), for a board
/// at normal priority that woke late.
pub fn let_peers_run() {
    // SAFETY: plain syscall without arguments.
    unsafe {
        libc::sched_yield();
    }
}

/// Whether this user may run a thread at SCHED_FIFO: tried on a thread of its own, which ends
/// at once.
pub fn fifo_permitted() -> bool {
    std::thread::spawn(|| {
        let param = libc::sched_param { sched_priority: 1 };
        // SAFETY: plain syscall on the calling thread (tid 0) with a valid sched_param.
        unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) == 0 }
    })
    .join()
    .unwrap_or(false)
}

/// Pins the calling thread to `cpu` when it exists, a warning on stderr from `who` otherwise.
pub fn pin_thread(cpu: usize, who: &str) {
    for w in setup(0, false, Some(cpu)).warnings {
        eprintln!("{who}: warning: {w}");
    }
}

/// Number of CPUs online (not this thread's affinity mask: a process pinned to one CPU may
/// still pin a child to another).
pub fn available_cpus() -> usize {
    // SAFETY: sysconf is a plain query.
    let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) };
    if n > 0 {
        n as usize
    } else {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    }
}

/// Keeps the calling thread (and the threads it creates from now on) off the CPUs `avoid`,
/// e.g. the real-time boards' cores. Returns a warning instead when that would leave no CPU or
/// the kernel refuses; the thread then stays where it was.
pub fn avoid_cpus(avoid: &[usize]) -> Option<String> {
    let n = available_cpus();
    let keep: Vec<usize> = (0..n.min(libc::CPU_SETSIZE as usize))
        .filter(|c| !avoid.contains(c))
        .collect();
    if keep.is_empty() {
        return Some(format!(
            "every CPU ({n}) runs a real-time board; the live view shares their cores"
        ));
    }
    // SAFETY: cpu_set_t is plain data; CPU_SET indexes within its size (c < CPU_SETSIZE).
    let rc = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        for &c in &keep {
            libc::CPU_SET(c, &mut set);
        }
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    (rc != 0).then(|| {
        format!(
            "keeping off CPUs {avoid:?} refused ({})",
            io::Error::last_os_error()
        )
    })
}

/// The one CPU process `pid` is pinned to, if it is pinned to exactly one.
pub fn pinned_cpu(pid: i32) -> Option<usize> {
    // SAFETY: cpu_set_t is plain data; sched_getaffinity fills it for `pid`.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        if libc::sched_getaffinity(pid, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
            return None;
        }
        let on: Vec<usize> = (0..libc::CPU_SETSIZE as usize)
            .filter(|&c| libc::CPU_ISSET(c, &set))
            .collect();
        (on.len() == 1).then(|| on[0])
    }
}

/// Makes the calling process receive SIGTERM when its parent dies (so no board keeps running
/// unsupervised), and exits at once if the parent is already gone. For `pre_exec`.
pub fn die_with_parent(parent: libc::pid_t) -> io::Result<()> {
    // SAFETY: prctl with PR_SET_PDEATHSIG and a signal number; getppid is a plain query.
    unsafe {
        if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
            return Err(io::Error::last_os_error());
        }
        if libc::getppid() != parent {
            libc::_exit(0);
        }
    }
    Ok(())
}
