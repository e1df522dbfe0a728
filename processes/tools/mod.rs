//! The tools around the stack: benchmarks, in-process experiments, recordings, plots.

pub mod bench;
pub mod experiment;
pub mod plot;
pub mod record;
