//! The loop and stack parts: the servo's wake latency against a bare loop beside it, and the
//! full graph's force age and wake latency without and with a CPU hog.

use super::{BenchOptions, ConstFloor, PartReport, Series, finish_part};
use crate::hist::{self, QuantilesUs};
use crate::stack::{DEFAULT_STACK, StackFile};
use crate::supervisor::RunReport;
use crate::{ipc, rt};
use afs_shared::check::Check;
use afs_shared::msg::Board;
use anyhow::{Context, Result, bail};
use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The servo's process and node name.
const SERVO: &str = Board::Servo.name();

/// The loop part's report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LoopPart {
    /// The servo's CPU (and the bare loop's).
    pub cpu: usize,
    /// Their SCHED_FIFO priority.
    pub priority: u8,
    /// Tick period (µs).
    pub period_us: f64,
    /// Servo ticks that missed their period (none if the stack gave no loop statistics).
    pub servo_misses: Option<u64>,
    /// Series, targets, files.
    #[serde(flatten)]
    pub part: PartReport,
}

/// Sums over the stack runs of one kind.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct RunSums {
    /// Stack runs.
    pub stack_runs: u64,
    /// A hog ran on the other core.
    pub hog_running: bool,
    /// A Foxglove client was attached to the live view.
    #[serde(default)]
    pub viewer: bool,
    /// Servo ticks that missed their period.
    pub misses: u64,
    /// Servo ticks.
    pub ticks: u64,
    /// Safe-state entries.
    pub safe_entries: u64,
    /// Ticks with stale force data.
    pub stale_ticks: u64,
    /// Every run passed its checks.
    pub passed: bool,
}

/// The stack runs without and with the hog, and with a Foxglove client on the live view.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct StackRuns {
    /// Without the hog.
    pub without_hog: RunSums,
    /// With it.
    pub with_hog: RunSums,
    /// With `--foxglove` and a client subscribed to every topic (no hog).
    pub with_viewer: RunSums,
    /// Messages that client received.
    pub viewer_messages: u64,
}

/// The stack part's report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StackPart {
    /// Scenario run.
    pub scenario: String,
    /// The hog's CPU.
    pub hog_cpu: usize,
    /// The floor of the force age (µs).
    pub sensor_period_us: f64,
    /// Run sums.
    pub runs: StackRuns,
    /// Series, targets, files.
    #[serde(flatten)]
    pub part: PartReport,
}

/// A stack run for the benchmark: `afs run` with the servo saving its histograms.
pub(super) struct StackRun {
    pub(super) report: RunReport,
    pub(super) wake: Histogram<u64>,
    pub(super) age: Histogram<u64>,
}

/// Runs the stack of the stack file `text` (`afs run` refuses a prefix in use) while `during`
/// runs beside it; `during` is told through its flag when the stack has ended.
pub(super) fn run_stack<T: Send>(
    text: &str,
    prefix: &str,
    duration_s: f64,
    dir: &Path,
    extra: &[String],
    stop: &AtomicBool,
    during: impl FnOnce(&AtomicBool) -> T + Send,
) -> Result<(StackRun, T)> {
    let mut stack = StackFile::parse(text, "(benchmark)")?;
    stack.prefix = prefix.into();
    stack.scenario = "surface-tracking".into();
    stack.duration_s = duration_s;
    let hist_dir = dir.join(format!("{prefix}-servo"));
    let _ = std::fs::remove_dir_all(&hist_dir);
    for p in stack.process.iter_mut().filter(|p| p.name == SERVO) {
        p.args
            .extend(["--histograms".to_string(), hist_dir.display().to_string()]);
    }
    let file = dir.join(format!("{prefix}.toml"));
    std::fs::write(
        &file,
        toml::to_string(&stack).context("writing the stack file")?,
    )?;
    let child = Command::new(std::env::current_exe().context("locating afs")?)
        .args(["run", "--json", "--quiet", "--config"])
        .arg(&file)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("starting afs run")?;
    let running = AtomicBool::new(true);
    let (out, beside) = std::thread::scope(|sc| {
        let h = sc.spawn(|| during(&running));
        let pid = child.id();
        // Forward a Ctrl-C to the stack.
        let running = &running;
        let watcher = sc.spawn(move || {
            while running.load(Ordering::Relaxed) {
                if stop.load(Ordering::Relaxed) {
                    // SAFETY: signalling our own child.
                    unsafe {
                        libc::kill(pid as i32, libc::SIGINT);
                    }
                    return;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        });
        let out = child.wait_with_output();
        running.store(false, Ordering::Relaxed);
        let _ = watcher.join();
        let beside = h.join();
        (out, beside)
    });
    let out = out.context("waiting for afs run")?;
    let beside = beside.map_err(|_| anyhow::anyhow!("the thread beside the stack panicked"))?;
    let report: RunReport = serde_json::from_slice(&out.stdout).with_context(|| {
        format!(
            "afs run gave no report; its stderr:\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    })?;
    let wake = hist::load(&hist_dir.join("wake.hdr"))
        .context("the servo saved no histograms (did it run?)")?;
    let age = hist::load(&hist_dir.join("force_age.hdr"))?;
    let _ = std::fs::remove_dir_all(&hist_dir);
    let _ = std::fs::remove_file(&file);
    Ok((StackRun { report, wake, age }, beside))
}

/// The bare absolute-time loop at the servo's priority and core, half a period out of phase
/// with the servo's ticks (read from its samples), while `running`.
fn bare_loop(
    prefix: &str,
    cpu: usize,
    priority: u8,
    duration_s: f64,
    running: &AtomicBool,
) -> Result<Histogram<u64>> {
    let mut h = hist::new()?;
    // Join the stack once its servo is up (a node of ours before that would make `afs run`
    // refuse the prefix as taken), then find the servo's tick phase from its samples.
    let t0 = Instant::now();
    loop {
        if !running.load(Ordering::Relaxed) {
            return Ok(h);
        }
        if ipc::census(prefix, false).is_ok_and(|c| c.alive.iter().any(|(n, _)| n == SERVO)) {
            break;
        }
        if t0.elapsed() > Duration::from_secs(30) {
            bail!("the servo did not start within 30 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let node = ipc::node(prefix, "bench-loop")?;
    let sub = ipc::servo(&node)?
        .subscriber_builder()
        .create()
        .context("servo subscriber")?;
    let period = 100_000u64;
    let t0 = Instant::now();
    let (phase, seq0, tick0) = loop {
        if !running.load(Ordering::Relaxed) {
            return Ok(h);
        }
        if let Some(s) = sub.receive().map_err(|e| anyhow::anyhow!("{e:?}"))?
            && s.seq > 100
        {
            break (s.tick_ns % period, s.seq, s.tick_ns);
        }
        if t0.elapsed() > Duration::from_secs(30) {
            bail!("the servo did not start within 30 s");
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    drop(sub);
    drop(node);
    let r = rt::setup(priority, true, Some(cpu));
    for w in &r.warnings {
        eprintln!("afs bench: warning: {w}");
    }
    let now = rt::monotonic_ns();
    // Until 5 ms before the servo's last tick (its ticks are 100 µs of simulated and wall
    // time): the servo's exit (unmapping its locked memory on this core) is not part of the
    // comparison.
    let end = (tick0 + ((duration_s * 1e9) as u64).saturating_sub(seq0 * period))
        .saturating_sub(5_000_000);
    let mut deadline = now - now % period + phase + period / 2 + period;
    while running.load(Ordering::Relaxed) && deadline < end {
        rt::sleep_until(deadline);
        let late = rt::monotonic_ns().saturating_sub(deadline);
        hist::record(&mut h, late);
        deadline += period;
        let now = rt::monotonic_ns();
        if now > deadline + 100 * period {
            deadline = now - now % period + phase + period / 2 + period;
        }
    }
    Ok(h)
}

/// The built-in stack's servo CPU and priority.
fn servo_spec() -> Result<(usize, u8)> {
    let s = StackFile::parse(DEFAULT_STACK, "(built-in)")?;
    let p = s
        .process
        .iter()
        .find(|p| p.name == SERVO)
        .context("the built-in stack has no servo")?;
    Ok((
        p.cpu
            .unwrap_or(1)
            .min(rt::available_cpus().saturating_sub(1)),
        p.priority,
    ))
}

pub(super) fn jitter(opts: &BenchOptions, stop: &AtomicBool) -> Result<LoopPart> {
    let prefix = format!("{}l", opts.prefix);
    let dir = scratch(&prefix)?;
    let (cpu, prio) = servo_spec()?;
    let (run, bare) = run_stack(
        DEFAULT_STACK,
        &prefix,
        opts.duration_s,
        &dir,
        &[],
        stop,
        |running| bare_loop(&prefix, cpu, prio, opts.duration_s, running),
    )?;
    let _ = std::fs::remove_dir_all(&dir);
    let bare = bare.context("the bare loop")?;
    let series = vec![
        Series {
            name: "bare_loop_wake",
            what: "bare clock_nanosleep loop, SCHED_FIFO, servo's core and priority (the floor)",
            floor: None,
            hist: bare,
        },
        Series {
            name: "servo_wake",
            what: "afs servo's wake latency (running surface-tracking with every board)",
            floor: Some("bare_loop_wake"),
            hist: run.wake,
        },
    ];
    let servo = QuantilesUs::of(&series[1].hist);
    let floor = QuantilesUs::of(&series[0].hist);
    let targets = vec![
        Check::at_most(
            "servo_wake_p99_over_bare_loop",
            "servo wake p99 / bare loop p99",
            servo.p99 / floor.p99,
            1.2,
        )
        .target(),
    ];
    let part = finish_part(
        "loop",
        &series,
        &[],
        targets,
        &opts.out,
        "loop: wake latency, servo vs bare loop (same core, priority and time)",
    )?;
    Ok(LoopPart {
        cpu,
        priority: prio,
        period_us: 100.0,
        servo_misses: run.report.loop_stats.map(|l| l.misses),
        part,
    })
}

fn scratch(prefix: &str) -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("afs-bench-{prefix}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok(dir)
}

/// A busy loop on `cpu` at normal priority while `running`.
fn hog(cpu: usize, running: &AtomicBool) {
    rt::pin_thread(cpu, "afs bench");
    let mut x = 0u64;
    while running.load(Ordering::Relaxed) {
        for _ in 0..10_000 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
    }
}

/// Sums of the stack runs of one kind (without or with the hog).
struct StackSums {
    wake: Histogram<u64>,
    age: Histogram<u64>,
    runs: u64,
    misses: u64,
    ticks: u64,
    safe_entries: u64,
    stale_ticks: u64,
    passed: bool,
}

/// The kinds of stack run, alternated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Plain,
    Hog,
    Viewer,
}

/// A client on the live view at `addr`, subscribed to every topic and reading until the
/// stack ends; the messages it received.
fn viewer(addr: &str, cpu: usize, running: &AtomicBool) -> u64 {
    // Where an operator's viewer runs: not on the servo's core.
    rt::pin_thread(cpu, "afs bench");
    use crate::observe::topics::TOPICS;
    use crate::observe::view_client::ViewClient;
    let all: Vec<&str> = TOPICS.iter().map(|t| t.0).collect();
    let url = format!("ws://{addr}");
    let Ok(mut c) = ViewClient::connect(&url, Duration::from_secs(30)) else {
        return 0;
    };
    if c.wait_for(&all, Duration::from_secs(30)).is_err() || c.subscribe(&all).is_err() {
        return 0;
    }
    let mut n = 0;
    while running.load(Ordering::Relaxed) {
        match c.next_message() {
            Ok(Some(_)) => n += 1,
            Ok(None) => {}
            Err(_) => break,
        }
    }
    n
}

/// A loopback port free now.
fn free_port() -> Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")
        .context("finding a free port for the live view")?
        .local_addr()?
        .port())
}

pub(super) fn stack(opts: &BenchOptions, stop: &AtomicBool) -> Result<StackPart> {
    let (cpu, _) = servo_spec()?;
    let other = if cpu == 0 { 1 } else { 0 };
    let can_hog = rt::available_cpus() > 1;
    let kinds = [Kind::Plain, Kind::Hog, Kind::Viewer];
    let (sums, viewer_messages) = alternate(opts, stop, &kinds, other, can_hog)?;
    let sensor_period_us = 1e6 / afs_shared::config::SimConfig::default().sensor.rate_hz;
    let mut series = Vec::new();
    let mut runs = Vec::new();
    for (kind, k) in kinds.into_iter().zip(sums) {
        let (wake, age, wake_what, age_what) = match kind {
            Kind::Plain => (
                "servo_wake",
                "force_age",
                "servo wake latency",
                "force data age at use (sensor sample to servo tick)",
            ),
            Kind::Hog => (
                "servo_wake_hog",
                "force_age_hog",
                "servo wake latency, CPU hog on the other core",
                "force data age at use, CPU hog on the other core",
            ),
            Kind::Viewer => (
                "servo_wake_viewer",
                "force_age_viewer",
                "servo wake latency, a Foxglove client on the live view",
                "force data age at use, a Foxglove client on the live view",
            ),
        };
        runs.push(RunSums {
            stack_runs: k.runs,
            hog_running: kind == Kind::Hog && can_hog,
            viewer: kind == Kind::Viewer,
            misses: k.misses,
            ticks: k.ticks,
            safe_entries: k.safe_entries,
            stale_ticks: k.stale_ticks,
            passed: k.passed,
        });
        series.push(Series {
            name: wake,
            what: wake_what,
            floor: (kind != Kind::Plain).then_some("servo_wake"),
            hist: k.wake,
        });
        series.push(Series {
            name: age,
            what: age_what,
            floor: Some("sensor period"),
            hist: k.age,
        });
    }
    let consts = [ConstFloor {
        name: "sensor period",
        value_us: sensor_period_us,
    }];
    let mut targets = Vec::new();
    if let Some(s) = series.iter().find(|s| s.name == "force_age") {
        targets.push(
            Check::at_most(
                "force_age_p99_us",
                "force age p99 without hog (µs) ≤ sensor period + 20 µs",
                QuantilesUs::of(&s.hist).p99,
                sensor_period_us + 20.0,
            )
            .target(),
        );
    }
    let p99 = |name: &str| {
        series
            .iter()
            .find(|s| s.name == name)
            .map(|s| QuantilesUs::of(&s.hist).p99)
    };
    if let (Some(with), Some(without)) = (p99("servo_wake_viewer"), p99("servo_wake")) {
        targets.push(
            Check::at_most(
                "servo_wake_p99_with_viewer_over_without",
                "servo wake p99 with a Foxglove client / without",
                with / without,
                1.1,
            )
            .target(),
        );
    }
    let part = finish_part(
        "stack",
        &series,
        &consts,
        targets,
        &opts.out,
        "stack: servo wake latency and force age at use, without and with a CPU hog or a Foxglove client",
    )?;
    let [without_hog, with_hog, with_viewer]: [RunSums; 3] = runs
        .try_into()
        .map_err(|_| anyhow::anyhow!("three kinds of stack run"))?;
    Ok(StackPart {
        scenario: "surface-tracking".into(),
        hog_cpu: other,
        sensor_period_us,
        runs: StackRuns {
            without_hog,
            with_hog,
            with_viewer,
            viewer_messages,
        },
        part,
    })
}

/// Two stack runs of each kind, alternating (A B C A B C) so that a noisy stretch of the
/// machine falls on every kind; their histograms and counts summed by kind, and the messages
/// the Foxglove client saw.
fn alternate(
    opts: &BenchOptions,
    stop: &AtomicBool,
    kinds: &[Kind; 3],
    other: usize,
    can_hog: bool,
) -> Result<(Vec<StackSums>, u64)> {
    let mut sums: Vec<StackSums> = kinds
        .iter()
        .map(|_| {
            Ok(StackSums {
                wake: hist::new()?,
                age: hist::new()?,
                runs: 0,
                misses: 0,
                ticks: 0,
                safe_entries: 0,
                stale_ticks: 0,
                passed: true,
            })
        })
        .collect::<Result<_>>()?;
    let mut viewer_messages = 0;
    for i in 0..2 * kinds.len() {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let kind = kinds[i % kinds.len()];
        let prefix = format!("{}s{i}", opts.prefix);
        let dir = scratch(&prefix)?;
        let addr = format!("127.0.0.1:{}", free_port()?);
        let extra: Vec<String> = if kind == Kind::Viewer {
            vec!["--foxglove".into(), addr.clone()]
        } else {
            Vec::new()
        };
        let (r, seen) = run_stack(
            DEFAULT_STACK,
            &prefix,
            opts.duration_s / 2.0,
            &dir,
            &extra,
            stop,
            |running| match kind {
                Kind::Hog if can_hog => {
                    hog(other, running);
                    0
                }
                Kind::Viewer => viewer(&addr, other, running),
                _ => 0,
            },
        )?;
        viewer_messages += seen;
        let _ = std::fs::remove_dir_all(&dir);
        let k = &mut sums[i % kinds.len()];
        k.wake.add(&r.wake).context("adding histograms")?;
        k.age.add(&r.age).context("adding histograms")?;
        let l = r.report.loop_stats.unwrap_or_default();
        k.runs += 1;
        k.misses += l.misses;
        k.ticks += l.ticks;
        k.safe_entries += l.safe_entries;
        k.stale_ticks += l.stale_ticks;
        k.passed &= r.report.passed;
    }
    Ok((sums, viewer_messages))
}
