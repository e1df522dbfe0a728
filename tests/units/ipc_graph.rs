//! afs::ipc::graph

use afs::ipc::graph::*;
use afs_shared::msg::service;

/// Every service name the messages declare is in the graph once, and no edge is drawn from
/// or to nobody.
#[test]
fn every_service_is_drawn_once() {
    let declared = [
        service::PLANT,
        service::WRENCH,
        service::SENSOR_STATS,
        service::SERVO,
        service::LOOP_STATS,
        service::TANGENT,
        service::ROTATION,
        service::FRICTION,
        service::SUPERVISOR,
        service::STARTUP,
        service::COMMAND,
        service::LINK_SERVO,
        service::TANGENT_REQUEST,
        service::TANGENT_RESPONSE,
        service::ROTATION_REQUEST,
        service::ROTATION_RESPONSE,
        service::PEG,
        service::WORLD,
    ];
    assert_eq!(declared.len(), EDGES.len());
    for s in declared {
        assert_eq!(EDGES.iter().filter(|e| e.service == s).count(), 1, "{s}");
    }
    for e in EDGES {
        assert!(!e.from.is_empty() && !e.to.is_empty(), "{}", e.service);
    }
    assert!(edge_of("afs/nothing").is_none());
}
