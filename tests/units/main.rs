//! The process library's own unit tests, outside the library: `afs` is built once, not again
//! as a test harness (docs/testing.md, *The build*). What they reach is public for them, marked
//! `#[doc(hidden)]` where it is not part of the library's use.

mod chaos_cut;
mod chaos_inject;
mod hist;
mod ipc;
mod ipc_graph;
mod ipc_prefix;
mod observe_record;
mod observe_topics;
mod observe_view;
mod rt;
mod stack;
mod stack_fci;
mod stack_robot;
mod supervisor_policy;
mod tools_experiment;
mod tools_graph;
mod tools_progress;
