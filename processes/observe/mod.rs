//! What watches a running stack from outside its boards: the MCAP recording (`record`), the
//! Foxglove live view (`view`, and `view_client`, a client of its protocol for the bench and
//! the tests), and following a stack's streams from another process (`follow`: `afs view`,
//! `afs record`). They share `topics`: what is recorded and shown, under which topic and
//! schema. The supervisor hands them its samples; nothing here imports the supervisor.

pub mod follow;
pub mod record;
pub mod topics;
pub mod view;
pub mod view_client;
