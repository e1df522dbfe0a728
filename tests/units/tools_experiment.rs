use afs::tools::experiment::*;

#[test]
fn seed_ranges_are_inclusive_and_checked() {
    assert_eq!(parse_seeds("1..100").unwrap(), 1..=100);
    assert_eq!(parse_seeds("3..=3").unwrap(), 3..=3);
    for bad in ["1-100", "5..2", "a..3", "1..1000000"] {
        assert!(parse_seeds(bad).is_err(), "{bad}");
    }
}
