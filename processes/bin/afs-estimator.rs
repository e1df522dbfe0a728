//! `afs-estimator`: tangent and rotation-centre estimation on request, friction identification.
//!
//! ```text
//! afs-estimator --prefix afs --cpu 0
//! ```

use afs::boards::{Common, Startup, stop_flag};
use clap::Parser;
use std::process::ExitCode;

/// The estimator board.
#[derive(Parser)]
#[command(name = "afs-estimator", version)]
struct Cli {
    #[command(flatten)]
    common: Common,
}

fn main() -> ExitCode {
    let mut startup = Startup::new(afs_shared::msg::Board::Estimator, afs::rt::monotonic_ns());
    let cli = Cli::parse();
    let result = (|| {
        afs::ipc::check_prefix(&cli.common.prefix)?;
        let r = afs::rt::setup(cli.common.priority, false, cli.common.cpu);
        startup.report.rt_ns = Startup::now();
        for w in &r.warnings {
            eprintln!("afs-estimator: warning: {w}");
        }
        if cli.common.priority == 0
            && let Some(n) = afs::rt::make_way_for_realtime()
        {
            eprintln!("afs-estimator: note: {n}");
        }
        let stop = stop_flag()?;
        afs::boards::estimator::run(&cli.common.prefix, startup, &stop)
    })();
    match result {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("afs-estimator: error: {e:#}");
            ExitCode::from(2)
        }
    }
}
