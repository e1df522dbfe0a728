//! afs::tools::progress

use afs::tools::progress::*;
use afs_shared::check::Check;

fn check(id: &str, pass: bool) -> Check {
    Check::at_most(id, id, if pass { 0.5 } else { 2.0 }, 1.0)
}

/// The plain line counts the runs, names each failed check with its count, and estimates
/// the time left from the rate; the failures are those of the runs reported.
#[test]
fn the_plain_line_counts_runs_and_failures_by_check() {
    let p = Progress::with_bar("fig5.6 over seeds 1..=4", 4, "runs", false);
    p.run_done(&[check("tangent_error", true), check("peak_force", false)]);
    p.run_done(&[check("tangent_error", false), check("peak_force", false)]);
    assert_eq!(p.done(), 2);
    let line = p.plain_line();
    assert!(
        line.starts_with("afs: fig5.6 over seeds 1..=4: 2/4 runs, "),
        "{line}"
    );
    assert!(line.contains("left"), "{line}");
    assert!(
        line.ends_with("failed: peak_force 2, tangent_error 1"),
        "{line}"
    );
    p.run_done(&[check("tangent_error", true)]);
    p.run_done(&[]);
    let line = p.plain_line();
    assert!(line.contains("4/4 runs") && line.contains("done"), "{line}");
}

/// A run without a failure leaves the tally empty, and the line says so.
#[test]
fn no_failure_is_said_as_such() {
    let p = Progress::with_bar("x", 1, "runs", false);
    p.run_done(&[check("a", true)]);
    let line = p.plain_line();
    assert!(line.ends_with("no check failed"), "{line}");
    assert_eq!(seconds(42.0), "42 s");
    assert_eq!(seconds(600.0), "10 min");
    assert_eq!(seconds(9000.0), "2.5 h");
}
