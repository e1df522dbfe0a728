//! The tools around the stack: benchmarks (`bench`), in-process experiments (`experiment`),
//! plots (`plot`), a real sensor's stream (`sensor`, `afs sensor`). They sit above the
//! supervisor (the benchmarks run stacks); what watches a stack is in `observe`.

pub mod bench;
pub mod experiment;
pub mod graph;
pub mod plot;
pub mod progress;
pub mod sensor;
