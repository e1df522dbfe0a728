//! What the stack tests share: the `afs` command, per-test prefixes, waiting for a stack,
//! board pids, and guards that kill children and remove shared memory when a test fails.
#![allow(dead_code)]

use serde_json::Value;
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Stack tests of one binary run one at a time.
pub static SERIAL: Mutex<()> = Mutex::new(());

pub fn afs() -> Command {
    Command::new(env!("CARGO_BIN_EXE_afs"))
}

/// A prefix no other test or run uses.
pub fn prefix(tag: &str) -> String {
    format!("t{}{tag}", std::process::id())
}

/// Files of a prefix in /dev/shm and the iceoryx2 root.
pub fn leftovers(prefix: &str) -> Vec<PathBuf> {
    afs::ipc::leftovers(prefix)
}

pub fn json_of(out: &Output) -> Value {
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout is not JSON ({e}); stderr:\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
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
fn poll_status<T>(prefix: &str, limit: Duration, pick: impl Fn(&Value) -> Option<T>) -> T {
    let t0 = Instant::now();
    loop {
        let out = afs()
            .args(["status", "--json", "--prefix", prefix])
            .output()
            .unwrap();
        if out.status.success()
            && let Some(x) = pick(&json_of(&out))
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
pub fn wait_running(prefix: &str, limit: Duration) -> Value {
    poll_status(prefix, limit, |v| {
        (v["loop"]["ticks"].as_u64().unwrap_or(0) > 1000).then(|| v.clone())
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
        v["nodes"].as_array()?.iter().find(|n| n["name"] == name)?["pid"]
            .as_i64()
            .map(|p| p as i32)
    })
}
