//! afs-shared: the pure, deterministic core of afs.
#![warn(missing_docs)]

pub mod friction;
pub mod math;
pub mod arm;
pub mod surface;
pub mod plant;
pub mod sensor;
pub mod dither;
pub mod tuner;
pub mod window;
pub mod hybrid;
pub mod servo;
pub mod sim;
pub mod ident;
pub mod experiments;
