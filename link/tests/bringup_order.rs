//! One bring-up order: every place that states it says the order of
//! `hopper_link::bringup::STEPS` (the cockpit builds its guided sequence
//! from it): `hopper-link calibrate --help`, the book's bring-up page
//! (which CI runs as written), and the scripted sessions CI runs against
//! the virtual robot and the QEMU image.

use hopper_link::bringup::{routines, STEPS};
use std::path::Path;
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap_or(Path::new("."))
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The bring-up's commands in a script's lines (`calibrate X`, `mount
/// release`, `save`; the `!` lines, refusals on purpose, left out).
fn bringup_commands<'a>(lines: impl Iterator<Item = &'a str>) -> Vec<String> {
    lines
        .map(str::trim)
        .filter(|l| l.starts_with("calibrate ") || *l == "mount release" || *l == "save")
        .map(|l| {
            // `calibrate tare --seconds 1` is still the tare.
            l.split_whitespace().take(2).collect::<Vec<_>>().join(" ")
        })
        .collect()
}

fn steps() -> Vec<String> {
    STEPS.iter().map(|s| s.command.to_string()).collect()
}

#[test]
fn the_sessions_ci_runs_follow_the_order() {
    for script in ["tests/link-session.txt", "tests/link-session-bringup.txt"] {
        let text = read(script);
        let got = bringup_commands(text.lines().filter(|l| !l.starts_with('#')));
        assert_eq!(got, steps(), "{script}");
    }
}

#[test]
fn the_books_bring_up_page_follows_the_order() {
    let text = read("docs/bring-up.md");
    let typed = text
        .lines()
        .filter_map(|l| l.trim_start().strip_prefix("> "))
        .filter(|l| !l.starts_with('!'));
    assert_eq!(bringup_commands(typed), steps());
}

#[test]
fn calibrate_help_lists_the_order() {
    let out = Command::new(env!("CARGO_BIN_EXE_hopper-link"))
        .args(["calibrate", "--help"])
        .output()
        .unwrap_or_else(|e| panic!("hopper-link: {e}"));
    let help = String::from_utf8_lossy(&out.stdout).replace('\n', " ");
    // The routine names in backticks, up to the save.
    let mut named = Vec::new();
    for word in help.split('`').skip(1).step_by(2) {
        named.push(word.to_string());
        if word == "save" {
            break;
        }
    }
    assert_eq!(named, routines().collect::<Vec<_>>(), "{help}");
}

#[test]
fn the_cockpit_reads_the_order() {
    let page = read("link/src/cmd/ui.html");
    assert!(page.contains("const STEPS = /*BRINGUP_STEPS*/[];"));
}

/// The pages that used to list the order point at the bring-up page
/// instead: no other page lists the standing routines before the hoisted
/// ones.
#[test]
fn no_other_page_states_another_order() {
    let mut pages = vec![root().join("README.md")];
    for e in std::fs::read_dir(root().join("docs"))
        .into_iter()
        .flatten()
        .flatten()
    {
        let p = e.path();
        if p.extension().is_some_and(|x| x == "md") && !p.ends_with("history.md") {
            pages.push(p);
        }
    }
    for p in pages {
        let text = std::fs::read_to_string(&p).unwrap_or_default();
        let first = |what: &str| text.find(what);
        if let (Some(height), Some(direction)) =
            (first("calibrate height"), first("calibrate direction"))
        {
            assert!(
                direction < height,
                "{} names `calibrate height` before `calibrate direction`",
                p.display()
            );
        }
    }
}
