//! afs::observe::topics

use afs::observe::topics::{TOPICS, json_schema};
use afs_shared::live::{ContactLive, InsertionLive, LiveSample};

/// Every topic's schema lists exactly the fields its JSON carries, typed as they serialise.
#[test]
fn every_schema_types_the_fields_its_messages_carry() {
    let live = serde_json::to_value(LiveSample::default()).unwrap();
    for (topic, ty) in TOPICS {
        let schema: serde_json::Value = serde_json::from_str(&json_schema(ty)).unwrap();
        let props = schema["properties"].as_object();
        assert!(props.is_some_and(|p| !p.is_empty()), "{topic}: {schema}");
    }
    let schema: serde_json::Value = serde_json::from_str(&json_schema("afs::LiveSample")).unwrap();
    let props = schema["properties"].as_object().unwrap();
    assert_eq!(props.len(), live.as_object().unwrap().len());
    assert_eq!(props["seq"]["type"], "integer");
    assert_eq!(props["tangent_error_deg"]["type"], "number");
    assert_eq!(props["safe"]["type"], "boolean");
    let insertion = serde_json::to_value(InsertionLive::default()).unwrap();
    let schema: serde_json::Value =
        serde_json::from_str(&json_schema("afs::InsertionLive")).unwrap();
    let props = schema["properties"].as_object().unwrap();
    assert_eq!(props.len(), insertion.as_object().unwrap().len());
    assert_eq!(props["phase"]["type"], "integer");
    assert_eq!(props["depth_mm"]["type"], "number");
    assert_eq!(props["force_valid"]["type"], "boolean");
    let contact = serde_json::to_value(ContactLive::default()).unwrap();
    let schema: serde_json::Value = serde_json::from_str(&json_schema("afs::ContactLive")).unwrap();
    let props = schema["properties"].as_object().unwrap();
    assert_eq!(props.len(), contact.as_object().unwrap().len());
    assert_eq!(props["stiffness_in_use_n_per_m"]["type"], "number");
    assert_eq!(props["adoptions"]["type"], "integer");
    assert_eq!(props["provisional"]["type"], "boolean");
}

/// Each topic's type name is its message's iceoryx2 type name (with its version).
#[test]
fn topics_name_their_messages_as_iceoryx2_does() {
    let layouts = afs_shared::msg::layouts();
    for (topic, ty) in TOPICS
        .iter()
        .filter(|t| !["/live", "/insertion", "/contact"].contains(&t.0))
    {
        assert!(
            layouts
                .iter()
                .any(|l| l.type_name == *ty && l.version.is_some()),
            "{topic}: {ty} is not a message's type name"
        );
    }
}

/// The recorder's queue holds `Rec`s by value and touches every slot when it starts
/// (observe/record.rs, `QUEUE`): the rare, large samples are boxed so that a slot stays at
/// the size of the largest per-tick one, the servo's sample.
#[test]
fn a_recorded_sample_is_no_larger_than_the_servo_s_with_its_tag() {
    let servo = std::mem::size_of::<afs_shared::msg::ServoSample>();
    assert!(std::mem::size_of::<afs::observe::topics::Rec>() <= servo + 8);
}
