//! The commands that cut the link and restore it (the stack file's `[chaos]` table), run for
//! the `cut-link` fault without holding up the supervisor's loop.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Most time the restore at the run's end waits for a command.
const RESTORE_WAIT: Duration = Duration::from_secs(5);

/// The cut and restore commands, and those still running.
pub struct LinkCut {
    cut: Vec<String>,
    restore: Vec<String>,
    running: Vec<(bool, Child)>,
}

impl LinkCut {
    /// The commands (program and arguments each; the stack file's check makes them non-empty).
    pub fn new(cut: &[String], restore: &[String]) -> Self {
        Self {
            cut: cut.to_vec(),
            restore: restore.to_vec(),
            running: Vec::new(),
        }
    }

    fn what(cut: bool) -> &'static str {
        if cut {
            "the command that cuts the link"
        } else {
            "the command that restores the link"
        }
    }

    /// Starts the cut (`cut`) or the restore; Err says why it could not start.
    pub fn start(&mut self, cut: bool) -> Result<(), String> {
        let argv = if cut { &self.cut } else { &self.restore };
        let (program, args) = argv
            .split_first()
            .ok_or_else(|| format!("{} is empty", Self::what(cut)))?;
        let child = Command::new(program)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .spawn()
            .map_err(|e| {
                format!(
                    "{} ({}) did not start: {e}",
                    Self::what(cut),
                    argv.join(" ")
                )
            })?;
        self.running.push((cut, child));
        Ok(())
    }

    /// Reaps the commands that ended; returns what went wrong with them.
    pub fn poll(&mut self) -> Vec<String> {
        let mut failed = Vec::new();
        self.running
            .retain_mut(|(cut, child)| match child.try_wait() {
                Ok(None) => true,
                Ok(Some(st)) if st.success() => false,
                Ok(Some(st)) => {
                    failed.push(format!("{} ended with {st}", Self::what(*cut)));
                    false
                }
                Err(e) => {
                    failed.push(format!("{} could not be waited for: {e}", Self::what(*cut)));
                    false
                }
            });
        failed
    }

    /// Restores the link now (the run ends while it is cut): waits for the commands running
    /// and the restore, at most [`RESTORE_WAIT`] each; returns what went wrong.
    pub fn restore_now(&mut self) -> Vec<String> {
        let mut failed = Vec::new();
        if let Err(e) = self.start(false) {
            failed.push(e);
        }
        let t0 = Instant::now();
        while !self.running.is_empty() && t0.elapsed() < RESTORE_WAIT {
            failed.extend(self.poll());
            std::thread::sleep(Duration::from_millis(10));
        }
        for (cut, mut child) in self.running.drain(..) {
            let _ = child.kill();
            let _ = child.wait();
            failed.push(format!(
                "{} did not end within {} s: killed",
                Self::what(cut),
                RESTORE_WAIT.as_secs()
            ));
        }
        failed
    }
}
