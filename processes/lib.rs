//! Process-side glue for the afs binaries (`processes/bin/`): the boards' loops, the supervisor,
//! fault injection, the tools, and the plumbing they share. No algorithm lives here; it calls
//! `afs_shared`.
//!
//! | folder | job |
//! |---|---|
//! | `boards/` | the board processes' loops: servo, sensor, estimator, and what they share |
//! | `supervisor/` | `afs run` and `afs status`: children, restart policy, the watch loop, footprint, report |
//! | `chaos/` | `afs chaos`: the fault plan's spans, the injector, the bad samples, the report |
//! | `stack/` | the stack file and its types, a restart's timeline, a stack's footprint: below both the supervisor and chaos |
//! | `tools/` | `afs bench`, `afs experiment`, plots, `afs sensor` |
//! | `observe/` | what watches a running stack: recording and export, the live view, following |
//! | `ipc`, `rt`, `hist`, `procfs` | iceoryx2 services, real-time set-up, latency histograms, `/proc` |

pub mod boards;
pub mod chaos;
pub mod hist;
pub mod ipc;
pub mod observe;
pub mod procfs;
pub mod robot;
pub mod rt;
pub mod stack;
pub mod supervisor;
pub mod tools;
