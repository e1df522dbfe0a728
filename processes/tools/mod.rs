//! The tools around the stack: benchmarks, in-process experiments, recordings, plots, a
//! real sensor's stream (`afs sensor`), the live view. The recording, the live view and the
//! follower of a running stack share `topics` (what is recorded and shown, under which
//! topic and schema); `record` and `view` both follow a stack with `follow`.

pub mod bench;
pub mod experiment;
pub mod follow;
pub mod plot;
pub mod record;
pub mod sensor;
pub mod topics;
pub mod view;
pub mod view_client;
