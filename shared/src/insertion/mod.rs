//! Force-guided insertion (docs/insertion.md): a rectangular peg held by a compliant wrist,
//! a hole with an optional chamfer ([`geometry`], [`plant`]), Whitney's jamming and wedging
//! conditions ([`whitney`]), the insertion controller and its baselines ([`controller`]), the
//! contact state as the controller can know it ([`estimate`]), the three stepped together as a
//! servo runs them ([`rig`]) and measured ([`monitor`]), and the arm with a wrist joint
//! ([`scara`]) that can carry the wrist ([`drive`]), and §5.4's rotation centre on the peg in
//! two-point contact ([`centre`], measured, not used by the controller); the peg in afs's
//! plant or MuJoCo's ([`world`]).

pub mod centre;
pub mod controller;
pub mod drive;
pub mod estimate;
pub mod face;
pub mod geometry;
pub mod monitor;
pub mod options;
pub mod plant;
pub mod rig;
pub mod scara;
pub mod whitney;
pub mod world;
