//! What the stack tests share: the `afs` command, per-test prefixes, waiting for a stack,
//! board pids, and guards that kill children and remove shared memory when a test fails.
#![allow(dead_code)]

use serde_json::Value;
use std::path::PathBuf;
use std::process::{Child, Command, Output};
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

/// Waits (with a watchdog) until `afs status` sees the stack's servo loop running.
pub fn wait_running(prefix: &str, limit: Duration) -> Value {
    let t0 = Instant::now();
    loop {
        let out = afs()
            .args(["status", "--json", "--prefix", prefix])
            .output()
            .unwrap();
        if out.status.success() {
            let v = json_of(&out);
            if v["loop"]["ticks"].as_u64().unwrap_or(0) > 1000 {
                return v;
            }
        }
        assert!(
            t0.elapsed() < limit,
            "the stack '{prefix}' did not come up: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        std::thread::sleep(Duration::from_millis(200));
    }
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

/// Removes a prefix's iceoryx2 files when dropped, also when a failed assertion unwinds (the
/// test's own node leaves the domain's files behind).
pub struct CleanPrefix(pub String);

impl Drop for CleanPrefix {
    fn drop(&mut self) {
        let _ = afs::ipc::remove_leftovers(&self.0);
    }
}

/// The pid of the board `name` of a running stack, from `afs status`.
pub fn board_pid(prefix: &str, name: &str) -> i32 {
    let t0 = Instant::now();
    loop {
        let out = afs()
            .args(["status", "--json", "--prefix", prefix])
            .output()
            .unwrap();
        if out.status.success() {
            let v = json_of(&out);
            if let Some(p) = v["nodes"]
                .as_array()
                .and_then(|a| a.iter().find(|n| n["name"] == name))
                .and_then(|n| n["pid"].as_i64())
            {
                return p as i32;
            }
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "no {name} in '{prefix}'"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}
