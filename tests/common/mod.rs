//! What the stack tests share: the `afs` command, per-test prefixes, waiting for a stack,
//! board pids, and guards that kill children and remove shared memory when a test fails.
#![allow(dead_code)]

use afs::supervisor::{RunReport, StatusReport};
use serde::de::DeserializeOwned;
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Stack tests of one binary run one at a time, and so does a test's CPU-heavy work (an
/// in-process experiment): on 2 cores it would run beside another test's real-time stack and
/// load it (a lockstep agreement of a MuJoCo stack missed one figure once in a full run while
/// `afs experiment fig5.6` ran outside the lock, 2026-12-03).
pub static SERIAL: Mutex<()> = Mutex::new(());

/// The `afs` binary: cargo's own for the root package's tests; for another member's tests (the
/// link board's), the one beside them in the target directory, which `--workspace` builds.
pub fn afs() -> Command {
    Command::new(bin("afs"))
}

/// The path of the workspace binary `name`, in the directory above the running test's.
pub fn bin(name: &str) -> PathBuf {
    if name == "afs"
        && let Some(p) = option_env!("CARGO_BIN_EXE_afs")
    {
        return PathBuf::from(p);
    }
    let test = std::env::current_exe().expect("the test's own path");
    let dir = test
        .parent()
        .and_then(|deps| deps.parent())
        .expect("the target directory");
    let p = dir.join(name);
    assert!(
        p.exists(),
        "{} is missing: build the workspace first (`cargo test --release --workspace` builds it)",
        p.display()
    );
    p
}

/// One line on the test's stderr that the harness does not capture (`writeln!` to stderr is
/// not `eprintln!`): shown by `cargo test`, and by nextest for the tests that
/// .config/nextest.toml names. For what a test could not use here and says instead of failing
/// (namespaces, SCHED_FIFO, mlockall).
pub fn say(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "{line}");
}

/// A prefix no other test or run uses.
pub fn prefix(tag: &str) -> String {
    format!("t{}{tag}", std::process::id())
}

/// Files of a prefix in /dev/shm and the iceoryx2 root.
pub fn leftovers(prefix: &str) -> Vec<PathBuf> {
    afs::ipc::leftovers(prefix)
}

/// The report a command printed with `--json`, read back as its type.
pub fn report_of<T: DeserializeOwned>(out: &Output) -> T {
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout is not the report ({e}); stdout:\n{}\nstderr:\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

/// The report of `afs run --json` or `afs chaos --json`.
pub fn run_report(out: &Output) -> RunReport {
    report_of(out)
}

/// The named process's entry of a run report.
pub fn process<'a>(r: &'a RunReport, name: &str) -> &'a afs::supervisor::ProcessReport {
    r.processes
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("no process {name} in the report"))
}

/// The check identified by `id` of a run report.
pub fn check<'a>(r: &'a RunReport, id: &str) -> &'a afs_shared::check::Check {
    afs_shared::check::find(&r.checks, id)
        .unwrap_or_else(|| panic!("no check '{id}' in {:#?}", r.checks))
}

/// The failed checks of a run report, one line each.
pub fn failed(r: &RunReport) -> String {
    r.checks
        .iter()
        .filter(|c| !c.pass)
        .map(|c| c.line() + "\n")
        .collect()
}

/// Whether a run was correct: every check but the timing targets passed, and it exited with
/// 0, or with 1 because a target was missed (a loaded machine, or no SCHED_FIFO: the targets
/// are the run's report, not the tests' assertions).
pub fn correct(out: &Output, r: &RunReport) -> bool {
    let wrong = r.checks.iter().any(|c| !c.pass && !c.is_target());
    let all_targets_met = r.checks.iter().all(|c| c.pass || !c.is_target());
    let code = out.status.code();
    !wrong && (code == Some(0) || (code == Some(1) && !all_targets_met))
}

/// Asserts `out` is a clear refusal of `what`: exit status 2, `needle` in stderr, no panic.
pub fn assert_refused(out: &Output, what: &dyn std::fmt::Debug, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{what:?}: {err}");
    assert!(
        err.contains(needle),
        "{what:?}: expected '{needle}' in: {err}"
    );
    assert!(!err.contains("panicked"), "{what:?}: {err}");
}

/// examples/mujoco/user-arm.xml: a user's own two-link arm for MuJoCo (docs/mujoco.md).
pub fn user_arm() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/mujoco/user-arm.xml"
    ))
    .expect("examples/mujoco/user-arm.xml")
}

/// examples/stack.toml with `extra` (TOML) appended, written to `dir/stack.toml`: the full
/// process graph on a set-up of a test's own.
pub fn stack_file(dir: &std::path::Path, extra: &str) -> PathBuf {
    let base = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/stack.toml"))
        .unwrap();
    let path = dir.join("stack.toml");
    std::fs::write(&path, format!("{base}\n{extra}")).unwrap();
    path
}

/// `afs run --json --quiet --prefix <prefix> <args>` started in the background, its output
/// piped, killed if the test fails before it ends.
pub fn start_run(prefix: &str, args: &[&str]) -> KillOnDrop {
    let child = afs()
        .args(["run", "--json", "--quiet", "--prefix", prefix])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    KillOnDrop(Some(child))
}

/// Polls `afs status --json` (with a watchdog of `limit`) until `pick` finds what it wants.
fn poll_status<T>(prefix: &str, limit: Duration, pick: impl Fn(&StatusReport) -> Option<T>) -> T {
    let t0 = Instant::now();
    loop {
        let out = afs()
            .args(["status", "--json", "--prefix", prefix])
            .output()
            .unwrap();
        if out.status.success()
            && let Some(x) = pick(&report_of(&out))
        {
            return x;
        }
        assert!(
            t0.elapsed() < limit,
            "stack '{prefix}': not there within {limit:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Waits (with a watchdog) until `afs status` sees the stack's servo loop running.
pub fn wait_running(prefix: &str, limit: Duration) -> StatusReport {
    poll_status(prefix, limit, |v| {
        (v.loop_stats.is_some_and(|l| l.ticks > 1000)).then(|| v.clone())
    })
}

pub fn finish(child: Child, what: &str) -> Output {
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.code().is_some(),
        "{what} was killed by a signal: {:?}",
        out.status
    );
    out
}

/// A child process killed (and reaped) when a failed assertion unwinds past it.
pub struct KillOnDrop(pub Option<Child>);

impl KillOnDrop {
    pub fn id(&self) -> u32 {
        self.0.as_ref().map_or(0, Child::id)
    }

    /// The child, no longer killed on drop.
    pub fn take(mut self) -> Child {
        self.0.take().expect("a child")
    }
}

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        if let Some(c) = &mut self.0
            && let Ok(None) = c.try_wait()
        {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Removes a prefix's iceoryx2 files when dropped, also when a failed assertion unwinds past a
/// killed stack (declare it before the stack's [`KillOnDrop`], so it drops after it).
pub struct CleanPrefix(pub String);

impl Drop for CleanPrefix {
    fn drop(&mut self) {
        // The boards of a killed supervisor follow it (SIGTERM from the kernel) within moments;
        // the prefix is cleared once none of its nodes is alive.
        let t0 = Instant::now();
        while afs::ipc::clear_prefix(&self.0).is_err() && t0.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

/// The pid of the board `name` of a running stack, from `afs status`.
pub fn board_pid(prefix: &str, name: &str) -> i32 {
    poll_status(prefix, Duration::from_secs(30), |v| {
        v.nodes.iter().find(|n| n.name == name).map(|n| n.pid)
    })
}

/// Kills board `name` of the stack on `prefix` (SIGKILL) and waits until its successor runs.
pub fn kill_board_and_wait_restart(prefix: &str, name: &str) {
    let pid = board_pid(prefix, name);
    // SAFETY: signalling a board of our own stack.
    unsafe {
        libc::kill(pid, libc::SIGKILL);
    }
    let t0 = Instant::now();
    while board_pid(prefix, name) == pid {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "{name} not restarted"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Waits for `afs run` (started by [`start_run`]) to end and returns its report, failing with
/// its stderr, failed checks, the lockstep agreement's figures and both sides' tracking figures
/// (ticks, safe ticks, distance travelled, estimates) unless it exited 0.
pub fn finish_passed(child: Child, what: &str) -> RunReport {
    let out = finish(child, what);
    let r = run_report(&out);
    assert!(
        out.status.success(),
        "{}\n{}\n{:#?}\nstack: ticks {}, safe {}, {:?}\nreference: ticks {}, safe {}, {:?}",
        String::from_utf8_lossy(&out.stderr),
        failed(&r),
        r.agreement,
        r.stack.ticks,
        r.stack.safe_ticks,
        r.stack.tracking,
        r.reference.ticks,
        r.reference.safe_ticks,
        r.reference.tracking
    );
    r
}
