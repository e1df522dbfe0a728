//! `stack::fci`: the pre-flight's refusals, against a closed loopback port and a stub robot
//! that answers the Connect request in the official layout.

use afs::stack::fci::preflight;
use afs::stack::robot::RobotTable;
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
