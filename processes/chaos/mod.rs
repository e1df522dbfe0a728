//! `afs chaos`: a stack run with faults injected into it.
//!
//! [`plan`] builds the fault plan (which kinds the scenario allows, each kind's span from the
//! stack file's policies; `afs_shared::faults::plan` places them); the [`Injector`], in the
//! supervisor's loop, injects them and times the recovery ([`BadSampleSender`] sends and
//! counts the bad force samples), and [`LinkCut`] runs the stack
//! file's commands that cut the link and restore it; [`ChaosReport`] is what the run's
//! report adds, with the checks that follow.

mod bad;
#[doc(hidden)]
pub mod cut;
#[doc(hidden)]
pub mod inject;
mod plan;
mod report;

pub use bad::BadSampleSender;
pub use cut::LinkCut;
pub use inject::*;
pub use plan::{MAX_FAULTS, plan};
pub use report::*;
