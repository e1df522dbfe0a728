//! Reaching the robot a stack file's `[robot]` table names (issue 48, docs/franka.md, *Before a
//! run: the robot answers*): afs connects as the FCI client will (franka-rs, FCI server
//! version 10), reads one state and leaves, so that a wrong address, a robot that refuses FCI
//! or one that speaks another version is one line naming it before anything starts.

use super::robot::RobotTable;
use anyhow::{Result, anyhow};
use franka::{FciVersion, FrankaError, RealtimeConfig, Robot, RobotOptions, VersionPolicy};

/// What the robot answered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotAnswer {
    /// The FCI server version it announced.
    pub server_version: u16,
    /// Its joint positions (rad).
    pub q: [f64; 7],
}

/// Connects to the robot of `table` as the servo's client: FCI version 10 exactly (afs drives
/// an FR3 only, no fall-back to a Panda's 5), no real-time kernel asked of franka-rs (the
/// loop's thread asks for its own priority). Gives up after franka-rs's 1-s connect timeout.
///
/// # Errors
/// One line naming `[robot] address`: no answer, another FCI version, or a refusal.
pub fn connect(table: &RobotTable) -> Result<Robot> {
    let options = RobotOptions::new(RealtimeConfig::Ignore)
        .with_version(VersionPolicy::Exact(FciVersion::V10));
    Robot::with_options(&table.address, options).map_err(|e| refusal(&table.address, &e))
}

/// Connects to the robot of `table` ([`connect`]), reads one state and disconnects.
///
/// # Errors
/// [`connect`]'s, or one line saying the robot sent no state.
pub fn preflight(table: &RobotTable) -> Result<RobotAnswer> {
    let address = &table.address;
    let robot = connect(table)?;
    let state = robot.read_once().map_err(|e| {
        anyhow!(
            "[robot] address = \"{address}\": the robot took the connection but sent no state ({e}); check that nothing blocks its UDP packets (a firewall) and that FCI is enabled in Desk"
        )
    })?;
    Ok(RobotAnswer {
        server_version: robot.server_version(),
        q: state.q,
    })
}

/// The line for a connection that failed.
fn refusal(address: &str, e: &FrankaError) -> anyhow::Error {
    match e {
        FrankaError::Network(why) => anyhow!(
            "[robot] address = \"{address}\": the robot does not answer ({why}); check the address, the cable, that the robot is on and that FCI is enabled in Desk"
        ),
        FrankaError::IncompatibleVersion {
            server_version,
            library_version,
        } => anyhow!(
            "[robot] address = \"{address}\": the robot speaks FCI server version {server_version}, and afs's client speaks version {library_version} (an FR3's); a Panda (FER, version 5) is not supported yet"
        ),
        other => anyhow!(
            "[robot] address = \"{address}\": the robot refused the FCI connection ({other}); check in Desk that FCI is enabled and that no other client holds the robot"
        ),
    }
}
