//! Every fault, refusal, disarm reason and saved-calibration load error
//! the robot can report has its entry in the book's troubleshooting page
//! (`docs/troubleshooting.md`): a heading "### `NAME`" by the name
//! `hopper-link` prints. A name added to the vocabulary without one fails
//! here.

use hopper_protocol::vocab::{DisarmReason, Fault, LoadError, Refusal};
use std::path::Path;

fn page() -> String {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/troubleshooting.md");
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// The names without an entry.
fn missing(page: &str, names: impl Iterator<Item = &'static str>) -> Vec<&'static str> {
    let headings: Vec<&str> = page
        .lines()
        .filter_map(|l| l.strip_prefix("### `")?.strip_suffix('`'))
        .collect();
    names.filter(|n| !headings.contains(n)).collect()
}

#[test]
fn every_fault_and_refusal_has_an_entry() {
    let page = page();
    let mut gaps = Vec::new();
    gaps.extend(missing(&page, Fault::ALL.iter().map(|f| f.name())));
    gaps.extend(missing(&page, Refusal::ALL.iter().map(|r| r.name())));
    gaps.extend(missing(&page, DisarmReason::ALL.iter().map(|r| r.name())));
    gaps.extend(missing(&page, LoadError::ALL.iter().map(|e| e.name())));
    assert!(gaps.is_empty(), "no troubleshooting entry for {gaps:?}");
}

#[test]
fn a_missing_entry_is_found() {
    let page = "### `estop`\n### `overrun` and more\n";
    assert_eq!(
        missing(page, ["estop", "overrun", "amp-fault"].into_iter()),
        ["overrun", "amp-fault"]
    );
}
