//! `afs chaos`: a stack run with faults injected into it.
//!
//! [`plan`] builds the fault plan (which kinds the scenario allows, each kind's span from the
//! stack file's policies; `afs_shared::faults::plan` places them); the [`Injector`], in the
//! supervisor's loop, injects them and times the recovery; [`ChaosReport`] is what the run's
//! report adds, with the checks that follow.

mod inject;
mod plan;
mod report;

pub use inject::*;
pub use plan::{MAX_FAULTS, plan};
pub use report::*;
