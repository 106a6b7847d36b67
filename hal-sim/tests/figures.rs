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
    Ok(())
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
