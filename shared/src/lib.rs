//! afs-shared: the pure, deterministic core of afs.
#![warn(missing_docs)]

#[macro_use]
pub mod wire;

pub mod arm;
pub mod batch;
pub mod cell;
pub mod check;
pub mod config;
pub mod contact;
pub mod correlation;
pub mod dither;
pub mod error;
pub mod experiments;
pub mod faults;
pub mod friction;
pub mod hybrid;
pub mod ident;
pub mod insertion;
pub mod join;
pub mod live;
pub mod math;
pub mod monitor;
pub mod msg;
pub mod multicontact;
pub mod nan;
pub mod plant;
pub mod probe;
pub mod rdt;
pub mod reach;
pub mod robot_cycle;
pub mod robot_guard;
pub mod scenario;
pub mod sensor;
pub mod servo;
pub mod setups;
pub mod sim;
pub mod surface;
pub mod sweep;
pub mod tangent;
pub mod task_plane;
pub mod tick;
pub mod ticks;
pub mod tuner;
pub mod watchdog;
pub mod window;
pub mod world;
