//! Force-guided insertion (docs/insertion.md): a rectangular peg held by a compliant wrist,
//! a hole with an optional chamfer, and Whitney's jamming and wedging conditions.

pub mod controller;
pub mod geometry;
pub mod plant;
pub mod whitney;
