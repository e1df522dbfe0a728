//! afs::chaos::cut

use afs::chaos::cut::*;
use std::time::{Duration, Instant};

/// A command that fails or cannot start is reported, one that succeeds is not, and the
/// restore at the end waits for the commands still running.
#[test]
fn commands_are_run_and_their_failures_reported() {
    let dir = std::env::temp_dir().join(format!("afs-cut-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let flag = dir.join("restored");
    let sh = |script: String| vec!["sh".to_string(), "-c".into(), script];
    let mut c = LinkCut::new(
        &sh("exit 3".into()),
        &sh(format!("sleep 0.2; touch {}", flag.display())),
    );
    c.start(true).unwrap();
    let t0 = Instant::now();
    let mut failed = Vec::new();
    while failed.is_empty() && t0.elapsed() < Duration::from_secs(20) {
        failed = c.poll();
        std::thread::sleep(Duration::from_millis(5));
    }
    assert_eq!(failed.len(), 1, "{failed:?}");
    assert!(failed[0].contains("cuts the link") && failed[0].contains('3'));
    assert!(c.restore_now().is_empty());
    assert!(flag.exists(), "the restore ran to its end");
    let mut missing = LinkCut::new(&["/nonexistent/afs-cut".into()], &["true".into()]);
    let e = missing.start(true).unwrap_err();
    assert!(e.contains("did not start"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
