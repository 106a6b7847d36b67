//! Output directories that are written whole or not at all.
//!
//! A run, sweep or figure set writes several files (CSV, plots). Written in
//! place, a failure part-way (a plot error, a full disk) would leave a
//! directory that looks like a result but is half of one. Here the files
//! are written into a fresh staging directory (next to the target, or inside
//! it when it exists) and moved into place only once every one of them is
//! written.

use std::path::{Path, PathBuf};

/// Writes output files into `dir` through `write`, which gets a staging
/// directory to write into and returns the names of the files it wrote
/// there. Returns their final paths.
///
/// On any error (from `write` or from creating the directories), nothing
/// is left behind: no staging directory, no `dir` if it did not exist, no
/// parent directories this call created. If `dir` already exists its other
/// files stay, and the new files replace the old ones of the same name only
/// after all of them were written (one rename each; a rename within one
/// directory tree does not fail in practice, and a destination that is a
/// directory is refused before the first one).
pub fn write_whole(
    dir: &Path,
    write: impl FnOnce(&Path) -> Result<Vec<String>, String>,
) -> Result<Vec<PathBuf>, String> {
    if dir.exists() && !dir.is_dir() {
        return Err(format!("output path {} is not a directory", dir.display()));
    }
    let existed = dir.is_dir();
    // The process id keeps two runs writing the same target apart; a leftover
    // of a killed process that had the same id is stale and goes.
    let tag = format!("partial-{}", std::process::id());
    // An existing directory stages inside itself (which also serves `--out .`,
    // whose parent and name are no use); a new one next to where it goes, so
    // that one rename puts it in place.
    let (staging, created) = if existed {
        (dir.join(format!(".{tag}")), Vec::new())
    } else {
        let name = dir
            .file_name()
            .ok_or_else(|| format!("output path {} has no directory name", dir.display()))?
            .to_string_lossy()
            .into_owned();
        let parent = match dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        // The ancestors this call creates, deepest first, to remove on failure.
        let created: Vec<PathBuf> = parent
            .ancestors()
            .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
            .map(Path::to_path_buf)
            .collect();
        (parent.join(format!(".{name}.{tag}")), created)
    };
    let fail = |e: String| {
        let _ = std::fs::remove_dir_all(&staging);
        for a in &created {
            let _ = std::fs::remove_dir(a);
        }
        e
    };
    let _ = std::fs::remove_dir_all(&staging);
    std::fs::create_dir_all(&staging).map_err(|e| {
        fail(format!(
            "cannot create output directory {}: {e}",
            dir.display()
        ))
    })?;
    let names = write(&staging).map_err(fail)?;
    let finals: Vec<PathBuf> = names.iter().map(|n| dir.join(n)).collect();
    if !existed {
        std::fs::rename(&staging, dir).map_err(|e| {
            fail(format!(
                "cannot create output directory {}: {e}",
                dir.display()
            ))
        })?;
        return Ok(finals);
    }
    if let Some(d) = finals.iter().find(|p| p.is_dir()) {
        return Err(fail(format!(
            "cannot write {}: it is a directory",
            d.display()
        )));
    }
    for (n, to) in names.iter().zip(&finals) {
        std::fs::rename(staging.join(n), to)
            .map_err(|e| fail(format!("cannot write {}: {e}", to.display())))?;
    }
    let _ = std::fs::remove_dir(&staging);
    Ok(finals)
}

#[cfg(test)]
mod tests {
    // Test helpers may panic on impossible setup errors: that is a failed test.
    #![allow(clippy::unwrap_used, clippy::expect_used)]

    use super::*;

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_failure_leaves_no_directory_and_no_created_parent() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("a").join("b").join("out");
        let r = write_whole(&dir, |s| {
            std::fs::write(s.join("one.csv"), "x").unwrap();
            Err("plot failed".into())
        });
        assert_eq!(r, Err("plot failed".to_string()));
        assert!(entries(tmp.path()).is_empty(), "{:?}", entries(tmp.path()));
    }

    #[test]
    fn success_moves_the_files_into_a_new_or_existing_directory() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("out");
        let write = |s: &Path| {
            std::fs::write(s.join("one.csv"), "new").unwrap();
            Ok(vec!["one.csv".to_string()])
        };
        assert_eq!(write_whole(&dir, write), Ok(vec![dir.join("one.csv")]));
        assert_eq!(entries(tmp.path()), ["out"]);
        // Again into the existing directory, which has a file of its own.
        std::fs::write(dir.join("mine.txt"), "keep").unwrap();
        std::fs::write(dir.join("one.csv"), "old").unwrap();
        write_whole(&dir, write).unwrap();
        assert_eq!(entries(&dir), ["mine.txt", "one.csv"]);
        assert_eq!(std::fs::read_to_string(dir.join("one.csv")).unwrap(), "new");
        assert_eq!(entries(tmp.path()), ["out"]);
        // A failure there keeps the old files as they were.
        let r = write_whole(&dir, |s| {
            std::fs::write(s.join("one.csv"), "half").unwrap();
            Err("disk full".into())
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read_to_string(dir.join("one.csv")).unwrap(), "new");
        assert_eq!(entries(tmp.path()), ["out"]);
    }

    #[test]
    fn a_file_in_the_way_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("out");
        std::fs::write(&file, "").unwrap();
        let r = write_whole(&file, |_| Ok(vec![]));
        assert!(r.unwrap_err().contains("is not a directory"));
    }
}
