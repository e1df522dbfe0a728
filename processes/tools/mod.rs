//! The tools around the stack: benchmarks, in-process experiments, recordings, plots, a
//! real sensor's stream (`afs sensor`).

pub mod bench;
pub mod experiment;
pub mod follow;
pub mod plot;
pub mod record;
pub mod sensor;
pub mod view;
pub mod view_client;
