//! Process-side glue for the afs binaries: real-time plumbing, iceoryx2 wiring, the process
//! shells' loops, the supervisor, recording and plots. No algorithm lives here; it calls
//! `afs_shared`.

pub mod bench;
pub mod board;
pub mod chaos;
pub mod estimator_board;
pub mod experiment;
pub mod hist;
pub mod ipc;
pub mod plot;
pub mod record;
pub mod rt;
pub mod sensor_board;
pub mod servo_board;
pub mod supervisor;
