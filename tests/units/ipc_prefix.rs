//! afs::ipc::prefix

use afs::ipc::file_prefix;
use afs::ipc::prefix::*;
use std::path::PathBuf;

/// A port id is a `UniqueSystemId` whose bits 64–95 are the creating pid; a resizable
/// segment's `__<n>` and `__mgmt` suffixes name the same port as the plain segment.
#[test]
fn data_segments_name_the_process_of_their_port() {
    let port: u128 = (4242u128 << 64) | 77;
    let fp = file_prefix("ut");
    for suffix in ["", "__0", "__3", "__mgmt"] {
        let f = PathBuf::from(format!("/dev/shm/{fp}0354a2_{port}{suffix}.data"));
        assert_eq!(file_pids(&f, "ut"), [4242], "{}", f.display());
    }
    let c = PathBuf::from(format!(
        "/dev/shm/{fp}0354a2_{port}_{}.connection",
        9u128 << 64
    ));
    assert_eq!(file_pids(&c, "ut"), [4242, 9]);
    assert_eq!(segment_owner("svc_12__mgmt"), "svc_12");
    assert_eq!(segment_owner("svc_12"), "svc_12");
}
