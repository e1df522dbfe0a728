//! afs::tools::graph

use afs::ipc::graph::{EDGES, Party};
use afs::tools::graph::*;

/// Every service of the table is on an arrow but those a party both writes and reads; the
/// picture is written and names every party and service.
#[test]
fn every_service_is_on_an_arrow_and_in_the_picture() {
    let arrows = arrows();
    for e in EDGES {
        let drawn = arrows
            .values()
            .any(|es| es.iter().any(|x| x.service == e.service));
        let only_self = e.from.iter().all(|a| e.to.iter().all(|b| a == b));
        let clients =
            e.from.iter().chain(e.to).all(|&p| p == Party::Clients) || e.from == [Party::Clients];
        assert!(
            drawn || only_self || clients,
            "{} is on no arrow",
            e.service
        );
    }
    let file = std::env::temp_dir().join(format!("afs-graph-{}.svg", std::process::id()));
    render(&file).unwrap();
    let svg = std::fs::read_to_string(&file).unwrap();
    let _ = std::fs::remove_file(&file);
    for p in Party::ALL {
        assert!(svg.contains(p.label()), "{}", p.label());
    }
    for e in arrows.values().flatten() {
        let short = e.service.trim_start_matches("afs/");
        assert!(svg.contains(short), "{}", e.service);
    }
}
