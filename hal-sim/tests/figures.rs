//! `hopper-sim figures`: every expected file is written, and a bad output
//! directory fails cleanly.

use hal_sim::figures::{expected_files, write_all, FigureOptions};
use std::process::Command;

#[test]
fn figures_writes_every_expected_file() -> Result<(), String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    // A directory that does not exist yet: write_all creates it.
    let out = dir.path().join("figs");
    let report = write_all(&out, &FigureOptions { quick: true })?;
    let expected = expected_files();
    assert_eq!(expected.len(), 32, "16 figures, PNG and SVG each");
    for name in &expected {
        let path = out.join(name);
        let len = std::fs::metadata(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?
            .len();
        assert!(len > 1000, "{} is only {len} bytes", path.display());
    }
    assert_eq!(report.files.len(), expected.len());
    // One note per hopping run (5 laws + 3 chapter 4 runs) and per step response (3).
    assert_eq!(report.notes.len(), 11, "{:#?}", report.notes);
    // What the figures show, within 5% of the values measured when they
    // were last drawn: a file's size says nothing about its curves, and a
    // change that moves a law's stance or work, or the flight PD's step
    // response, by more than that must be looked at (and the figures in
    // the docs redrawn).
    let hops = [
        // (figure, stance ms, motor work J)
        ("fig-2-4/fig-2-5 step-open", 102.979, 0.95),
        ("fig-2-6/fig-2-7 step-closed", 102.973, 1.09),
        ("fig-2-8/fig-2-9 open-torque", 98.498, 4.34),
        ("fig-2-10/fig-2-11 energy", 98.828, 3.11),
        ("fig-2-12/fig-2-13 velocity", 99.574, 2.49),
        ("fig-4-8 open-torque", 100.379, 2.25),
        ("fig-4-9 modified-torque", 100.379, 2.25),
    ];
    for (figure, stance_ms, work_j) in hops {
        let note = note_of(&report.notes, figure)?;
        within(figure, number_after(note, "stance ")?, stance_ms)?;
        within(figure, number_after(note, "motor work ")?, work_j)?;
    }
    let passive = note_of(&report.notes, "fig-4-7 passive")?;
    within("fig-4-7", number_after(passive, "stance ")?, 102.578)?;
    within("fig-4-7", number_after(passive, "stance dE [J] ")?, -4.28)?;
    within("fig-4-7", number_after(passive, "flight dE [J] ")?, -1.93)?;
    let steps = [
        // (figure, settling s and overshoot % without and with the limit)
        ("fig-4-4", [0.062, 4.3, 0.076, 3.9]),
        ("fig-4-5", [0.218, 15.7, 0.218, 15.7]),
        ("fig-4-6", [0.218, 15.7, 0.249, 13.4]),
    ];
    for (figure, want) in steps {
        let note = note_of(&report.notes, figure)?;
        let (free, limited) = note
            .split_once("with ")
            .ok_or_else(|| format!("{figure}: no limited response in {note}"))?;
        let got = [
            number_after(free, "at ")?,
            number_after(free, "overshoot ")?,
            number_after(limited, "at ")?,
            number_after(limited, "overshoot ")?,
        ];
        for (g, w) in got.into_iter().zip(want) {
            within(figure, g, w)?;
        }
    }
    Ok(())
}

/// The note of `figure`.
fn note_of<'a>(notes: &'a [String], figure: &str) -> Result<&'a str, String> {
    notes
        .iter()
        .find(|n| n.starts_with(figure))
        .map(String::as_str)
        .ok_or_else(|| format!("no note for {figure}: {notes:#?}"))
}

/// The number that follows the first `label` in `text`.
fn number_after(text: &str, label: &str) -> Result<f64, String> {
    let rest = text
        .split_once(label)
        .map(|(_, r)| r)
        .ok_or_else(|| format!("no '{label}' in {text}"))?;
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
        .unwrap_or(rest.len());
    rest[..end]
        .parse()
        .map_err(|e| format!("'{label}' in {text}: {e}"))
}

/// `got` within 5% of `want`.
fn within(figure: &str, got: f64, want: f64) -> Result<(), String> {
    if (got - want).abs() <= 0.05 * want.abs() {
        Ok(())
    } else {
        Err(format!("{figure}: {got}, not within 5% of {want}"))
    }
}

#[test]
fn figures_rejects_an_output_path_under_a_regular_file() -> Result<(), String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let file = dir.path().join("not-a-dir");
    std::fs::write(&file, "x").map_err(|e| e.to_string())?;
    let bad = file.join("figs");

    // The library names the directory it could not create.
    let err = match write_all(&bad, &FigureOptions { quick: true }) {
        Ok(_) => return Err("write_all accepted a path under a regular file".into()),
        Err(e) => e,
    };
    assert!(err.contains("cannot create output directory"), "{err}");
    assert!(err.contains("not-a-dir"), "{err}");

    // The CLI prints one error line and exits with status 2.
    let out = Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
        .args(["figures", "--out"])
        .arg(&bad)
        .output()
        .map_err(|e| e.to_string())?;
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.starts_with("hopper-sim: error: cannot create output directory"),
        "{stderr}"
    );
    assert!(out.stdout.is_empty());
    Ok(())
}
