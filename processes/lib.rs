//! Process-side glue for the afs binaries: rendering plots, running experiments and turning
//! their outcomes into files and JSON. No algorithm lives here; it calls `afs_shared`.

pub mod experiment;
pub mod plot;
