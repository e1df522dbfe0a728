//! afs::ipc

use afs::ipc::*;
use afs_shared::msg::ServoSample;
use afs_shared::msg::service;
use iceoryx2::prelude::ZeroCopySend;

/// The init namespace maps every id to itself; `unshare --map-root-user` maps root to the
/// user who made the namespace; an id the map leaves out has no machine id.
#[test]
fn a_user_namespaces_root_is_the_user_who_made_it() {
    assert_eq!(
        machine_uid("         0          0 4294967295\n", 0),
        Some(0)
    );
    assert_eq!(
        machine_uid("         0          0 4294967295\n", 1000),
        Some(1000)
    );
    assert_eq!(
        machine_uid("         0       1000          1\n", 0),
        Some(1000)
    );
    assert_eq!(machine_uid("         0       1000          1\n", 1), None);
    assert_eq!(
        machine_uid("0 100000 65536\n65536 1000 1\n", 65536),
        Some(1000)
    );
    assert_eq!(machine_uid("0 100000 65536\n", 5), Some(100_005));
    assert_eq!(machine_uid("garbage\n", 0), None);
}

/// A client built for an older layout of a message (here `ServoSample` version 1, 208
/// bytes) is refused when it opens the stream, with both versions named.
#[test]
fn a_client_of_an_older_layout_is_refused_with_both_versions() {
    #[derive(Debug, Clone, Copy, ZeroCopySend)]
    #[type_name("afs::ServoSample")]
    #[repr(C)]
    struct ServoSampleV1 {
        bytes: [u64; 26],
    }
    let prefix = format!("ut_ver_{}", std::process::id());
    let node = node(&prefix, "versions_test").unwrap();
    let current = servo(&node).unwrap();
    let e = stream::<ServoSampleV1>(&node, service::SERVO, TICK_STREAM)
        .expect_err("refused")
        .to_string();
    for needle in [
        "afs::ServoSample.v3 (layout version 3, 232 bytes)",
        "afs::ServoSample (layout version 1, 208 bytes)",
    ] {
        assert!(e.contains(needle), "{e}");
    }
    assert_eq!(layout_mismatch::<ServoSample>(&node, service::SERVO), None);
    assert_eq!(
        (
            layout_version("afs::ServoSample.v2"),
            layout_version("afs::X")
        ),
        (2, 1)
    );
    drop((current, node));
    let _ = release_prefix(&prefix);
}
