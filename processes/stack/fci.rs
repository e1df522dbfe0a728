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

/// Connects to the robot of `table`, reads one state and disconnects. The connection gives up
/// after franka-rs's 1-s connect timeout.
///
/// # Errors
/// One line naming `[robot] address` and what went wrong: no answer, another FCI version, a
/// refusal, or no state.
pub fn preflight(table: &RobotTable) -> Result<RobotAnswer> {
    let address = &table.address;
    // The pre-flight needs no real-time kernel (the servo's loop will ask for one), and afs
    // drives an FR3 only: version 10 exactly, no fall-back to a Panda's 5.
    let options = RobotOptions::new(RealtimeConfig::Ignore)
        .with_version(VersionPolicy::Exact(FciVersion::V10));
    let robot = Robot::with_options(address, options).map_err(|e| refusal(address, &e))?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Read, Write};
    use std::net::TcpListener;

    /// A table naming `address`, otherwise valid.
    fn table(address: &str) -> RobotTable {
        let text = format!(
            "kind = \"franka\"\naddress = \"{address}\"\n[task_frame]\norigin_m = [0.45, 0.0, 0.2]\n\
             x_axis = [1.0, 0.0, 0.0]\nnormal = [0.0, 0.0, 1.0]\n[tool]\nflange_to_tip = [1.0, 0.0, \
             0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.1, 1.0]\nmass_kg = 0.7\n"
        );
        let t: RobotTable = toml::from_str(&text).expect("a valid table");
        t.check().expect("a valid table");
        t
    }

    /// A robot on a loopback port that answers the first Connect request with `status` and
    /// `version` in the official layout (`u8 status, u16 version` after the 12-byte header,
    /// docs/franka.md) and stays until the client leaves; its address.
    fn stub(status: u8, version: u16) -> String {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let address = listener.local_addr().unwrap().to_string();
        std::thread::spawn(move || {
            let Ok((mut s, _)) = listener.accept() else {
                return;
            };
            // The request: u32 command (0), u32 command id, u32 size; then u16 version, u16
            // UDP port.
            let mut request = [0u8; 16];
            if s.read_exact(&mut request).is_err() {
                return;
            }
            let mut reply = Vec::new();
            reply.extend_from_slice(&0u32.to_le_bytes());
            reply.extend_from_slice(&request[4..8]);
            reply.extend_from_slice(&15u32.to_le_bytes());
            reply.push(status);
            reply.extend_from_slice(&version.to_le_bytes());
            let _ = s.write_all(&reply);
            // Open until the client leaves (a close with its bytes unread would reset it).
            let _ = s.read_to_end(&mut Vec::new());
        });
        address
    }

    /// A port where nothing listens: the connection is refused, and the line says the robot
    /// does not answer.
    #[test]
    fn a_robot_that_does_not_answer_is_named() {
        let port = TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let address = format!("127.0.0.1:{port}");
        let e = preflight(&table(&address)).unwrap_err().to_string();
        assert!(e.contains(&address) && e.contains("does not answer"), "{e}");
    }

    /// A robot that answers Connect with "incompatible version" and its own version 5: the line
    /// names both versions.
    #[test]
    fn a_robot_of_another_fci_version_is_named() {
        let address = stub(1, 5);
        let e = preflight(&table(&address)).unwrap_err().to_string();
        assert!(
            e.contains("server version 5") && e.contains("version 10"),
            "{e}"
        );
    }

    /// A robot that answers Connect with a status other than success or an incompatible
    /// version is a refusal.
    #[test]
    fn a_robot_that_refuses_fci_is_named() {
        let address = stub(7, 10);
        let e = preflight(&table(&address)).unwrap_err().to_string();
        assert!(
            e.contains(&address) && e.contains("refused the FCI connection"),
            "{e}"
        );
    }
}
