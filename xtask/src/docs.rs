//! The docs' examples, run and compared with what the docs print: a
//! command shown with a figure beside it is a contract, so a change of model
//! or default that moves the figure fails CI until the doc says the new one.
//!
//! Why examples in the docs rather than docs generated from runs: the pages
//! explain their numbers in prose around the output, which a generator would
//! have to own; a checked example keeps the prose where the author wrote it
//! and pins the numbers it talks about. The format is `trycmd`'s (its
//! matching is `snapbox`'s, used here): in README.md and docs/*.md every
//! fenced block marked `console` is a session of `$ COMMAND` lines, each
//! followed by the output it must print (stdout and stderr as one stream):
//!
//! * a line `...` stands for any number of lines (output not shown);
//! * `[..]` within a line stands for any text (wall-clock times, speeds);
//! * a command ends with a line ending in `\`'s continuation;
//! * `cargo run --release -p hal-sim --bin hopper-sim -- ARGS` and
//!   `hopper-sim ARGS` run the release `hopper-sim` just built, from the
//!   workspace root, and must exit 0 unless the block says otherwise: a
//!   `$ ` line whose output starts with `? failed` expects a failure (never
//!   a panic); the output compared is its stdout followed by its stderr;
//!   an example running over two minutes is killed and stale.
//!
//! A block marked `text` or `sh` is not run: commands that need a robot,
//! a board or minutes of time are shown that way. After the run the
//! figures the examples regenerate in `docs/img/` must match the committed
//! ones byte for byte (PNG drawing is deterministic for one font); changes
//! there from before the run are not the examples' and are not reported.
//!
//! The last line is `docs: N commands checked, M stale`.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// One example: where it is, the command, the output it must print.
#[derive(Debug, Clone, PartialEq)]
pub struct Example {
    /// `FILE:LINE` of its `$ ` line.
    pub at: String,
    /// The command as the doc shows it (continuations joined).
    pub command: String,
    /// The output the doc shows.
    pub expected: String,
    /// Whether the doc expects it to fail (`? failed`).
    pub fails: bool,
}

/// Every `console` example in `text` (the file `name`), or what is wrong
/// with a block: a `console` block must start with a `$ ` line. A block
/// indented (in a list item) has its fence's indentation taken off every
/// line.
pub fn examples(name: &str, text: &str) -> Result<Vec<Example>, String> {
    let mut out = Vec::new();
    // The fence's indentation while in a `console` block.
    let mut console: Option<usize> = None;
    let mut in_other = false;
    let mut current: Option<Example> = None;
    let mut continuing = false;
    let finish = |cur: &mut Option<Example>, out: &mut Vec<Example>| {
        if let Some(mut e) = cur.take() {
            if let Some(rest) = e.expected.strip_prefix("? failed\n") {
                e.expected = rest.to_string();
                e.fails = true;
            }
            out.push(e);
        }
    };
    for (i, raw) in text.lines().enumerate() {
        let trimmed = raw.trim_start();
        let indent = raw.len() - trimmed.len();
        if let Some(fence) = trimmed.strip_prefix("```") {
            if console.is_some() {
                finish(&mut current, &mut out);
                console = None;
            } else if in_other {
                in_other = false;
            } else if fence.trim() == "console" {
                console = Some(indent);
            } else {
                in_other = true;
            }
            continuing = false;
            continue;
        }
        let Some(fence_indent) = console else {
            continue;
        };
        let line = raw.get(fence_indent.min(indent)..).unwrap_or("");
        if continuing {
            if let Some(e) = current.as_mut() {
                let part = line.trim();
                continuing = part.ends_with('\\');
                e.command.push(' ');
                e.command.push_str(part.trim_end_matches('\\').trim());
            }
            continue;
        }
        if let Some(cmd) = line.strip_prefix("$ ") {
            finish(&mut current, &mut out);
            continuing = cmd.trim_end().ends_with('\\');
            current = Some(Example {
                at: format!("{name}:{}", i + 1),
                command: cmd.trim_end().trim_end_matches('\\').trim().to_string(),
                expected: String::new(),
                fails: false,
            });
        } else if let Some(e) = current.as_mut() {
            e.expected.push_str(line);
            e.expected.push('\n');
        } else {
            return Err(format!(
                "{name}:{}: a `console` block must start with a `$ ` command line (show other text in a `text` block)",
                i + 1
            ));
        }
    }
    Ok(out)
}

/// The arguments of `command` for the `hopper-sim` binary, or why it is
/// not a command this check runs.
fn hopper_sim_args(command: &str) -> Result<Vec<String>, String> {
    let words = shell_words(command)?;
    let prefix: &[&str] = &[
        "cargo",
        "run",
        "--release",
        "-p",
        "hal-sim",
        "--bin",
        "hopper-sim",
        "--",
    ];
    if words.len() >= prefix.len() && words.iter().zip(prefix).all(|(w, p)| w == p) {
        return Ok(words[prefix.len()..].to_vec());
    }
    if words.first().map(String::as_str) == Some("hopper-sim") {
        return Ok(words[1..].to_vec());
    }
    Err(format!(
        "`{command}`: a console example runs `hopper-sim` (or its `cargo run --release -p hal-sim --bin hopper-sim --` form); show other commands in a `sh` or `text` block"
    ))
}

/// Splits `s` into words as a POSIX shell would for the quoting docs use:
/// single and double quotes, no expansions.
fn shell_words(s: &str) -> Result<Vec<String>, String> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut in_word = false;
    let mut quote: Option<char> = None;
    for c in s.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => word.push(c),
            (None, '\'' | '"') => {
                quote = Some(c);
                in_word = true;
            }
            (None, c) if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut word));
                    in_word = false;
                }
            }
            (None, '|' | '>' | '<' | '&' | ';' | '$' | '`') => {
                return Err(format!(
                    "`{s}`: shell syntax `{c}` is not run by the docs check"
                ));
            }
            (None, c) => {
                word.push(c);
                in_word = true;
            }
        }
    }
    if quote.is_some() {
        return Err(format!("`{s}`: unterminated quote"));
    }
    if in_word {
        words.push(word);
    }
    Ok(words)
}

/// Longest an example may run before it is killed and counted stale, s
/// (the docs' examples take under 5 s each; a hang must not hang CI).
const EXAMPLE_TIMEOUT_S: u64 = 120;

/// Runs `sim ARGS` from `root`: its exit status and its stdout followed by
/// its stderr; killed after [`EXAMPLE_TIMEOUT_S`].
fn run_example(
    sim: &Path,
    args: &[String],
    root: &Path,
) -> Result<(std::process::ExitStatus, String), String> {
    let mut child = Command::new(sim)
        .args(args)
        .current_dir(root)
        .env("NO_COLOR", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| e.to_string())?;
    // Drained on threads: a pipe that fills would block the child.
    let drain = |r: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut buf = Vec::new();
            if let Some(mut r) = r {
                let _ = r.read_to_end(&mut buf);
            }
            buf
        })
    };
    let out = drain(
        child
            .stdout
            .take()
            .map(|r| Box::new(r) as Box<dyn Read + Send>),
    );
    let err = drain(
        child
            .stderr
            .take()
            .map(|r| Box::new(r) as Box<dyn Read + Send>),
    );
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(EXAMPLE_TIMEOUT_S);
    let status = loop {
        if let Some(s) = child.try_wait().map_err(|e| e.to_string())? {
            break s;
        }
        if std::time::Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("killed after {EXAMPLE_TIMEOUT_S} s"));
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    };
    let mut text = String::from_utf8_lossy(&out.join().unwrap_or_default()).into_owned();
    text.push_str(&String::from_utf8_lossy(&err.join().unwrap_or_default()));
    Ok((status, text))
}

/// `git status --porcelain` of docs/img (the figures the examples write).
fn img_status(root: &Path) -> Result<String, String> {
    let out = Command::new("git")
        .args(["status", "--porcelain", "--", "docs/img"])
        .current_dir(root)
        .output()
        .map_err(|e| format!("git status: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "git status of docs/img failed (the figure check needs a git checkout): {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The markdown files whose examples are checked: README.md and docs/*.md.
fn doc_files(root: &Path) -> Result<Vec<PathBuf>, String> {
    let mut files = vec![root.join("README.md")];
    let dir = root.join("docs");
    let mut pages: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    pages.sort();
    files.extend(pages);
    Ok(files)
}

/// Runs every example against `sim` (the release `hopper-sim`) from
/// `root`, then checks the figures they wrote into `docs/img` are the
/// committed ones. Prints `docs: N commands checked, M stale`. `only`
/// (paths from the root) limits the examples to those files.
pub fn check(root: &Path, sim: &Path, only: &[String]) -> Result<(), String> {
    let started = std::time::Instant::now();
    let mut all = Vec::new();
    let files: Vec<PathBuf> = match only {
        [] => doc_files(root)?,
        some => some.iter().map(|f| root.join(f)).collect(),
    };
    for file in files {
        let text =
            std::fs::read_to_string(&file).map_err(|e| format!("{}: {e}", file.display()))?;
        let name = file
            .strip_prefix(root)
            .unwrap_or(&file)
            .display()
            .to_string();
        all.extend(examples(&name, &text)?);
    }
    // Every command is one this check runs, before any runs.
    let runs: Vec<(&Example, Vec<String>)> = all
        .iter()
        .map(|e| {
            hopper_sim_args(&e.command)
                .map(|a| (e, a))
                .map_err(|m| format!("{}: {m}", e.at))
        })
        .collect::<Result<_, _>>()?;
    // Only what the examples change under docs/img is theirs to answer for.
    let before = img_status(root)?;
    let assert = snapbox::Assert::new();
    let mut stale = Vec::new();
    for (e, args) in runs {
        let t0 = std::time::Instant::now();
        let (status, actual) = run_example(sim, &args, root)
            .map_err(|err| format!("{}: cannot run {}: {err}", e.at, sim.display()))?;
        // A panic is never the expected failure: bad input is one error line.
        let panicked = actual.contains("panicked at") || status.code() == Some(101);
        let status_ok = status.success() != e.fails && !panicked;
        let matched = assert.try_eq(
            None,
            snapbox::Data::text(actual.clone()),
            snapbox::Data::text(e.expected.clone()),
        );
        let secs = t0.elapsed().as_secs_f64();
        match (status_ok, matched) {
            (true, Ok(())) => eprintln!("docs: ok    {} ({secs:.1} s) {}", e.at, e.command),
            (ok, m) => {
                eprintln!("docs: STALE {} {}", e.at, e.command);
                if !ok {
                    eprintln!(
                        "      exit status {status} (the doc expects {})",
                        if e.fails {
                            "a failure without a panic"
                        } else {
                            "success"
                        }
                    );
                }
                if let Err(diff) = m {
                    eprintln!("{diff}");
                }
                eprintln!("      it printed:\n{actual}");
                stale.push(e.at.clone());
            }
        }
    }
    // Figures the examples regenerated into the docs must be the
    // committed ones.
    let after = img_status(root)?;
    for line in after.lines().filter(|l| !before.lines().any(|b| b == *l)) {
        eprintln!(
            "docs: STALE figure {line} (an example wrote it differently from the committed file: look at it and commit it; PNG text is drawn with the font hopper-sim found, HOPPER_SIM_FONT or DejaVu Sans)"
        );
        stale.push(line.to_string());
    }
    crate::took("docs check", started);
    println!(
        "docs: {} commands checked, {} stale",
        all.len(),
        stale.len()
    );
    if stale.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "{} stale doc example(s): {}",
            stale.len(),
            stale.join(", ")
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn examples_are_console_blocks_with_continuations() {
        let md = "text\n```console\n$ hopper-sim run \\\n    --ledger\nline 1\n...\n$ hopper-sim bad\n? failed\nerror\n```\n```sh\n$ hopper-sim not-run\n```\n";
        let ex = examples("X.md", md).unwrap_or_default();
        assert_eq!(ex.len(), 2);
        assert_eq!(ex[0].at, "X.md:3");
        assert_eq!(ex[0].command, "hopper-sim run --ledger");
        assert_eq!(ex[0].expected, "line 1\n...\n");
        assert!(!ex[0].fails);
        assert_eq!(ex[1].command, "hopper-sim bad");
        assert_eq!(ex[1].expected, "error\n");
        assert!(ex[1].fails);
    }

    #[test]
    fn indented_blocks_are_read_and_stray_text_is_refused() {
        let md = "1. item\n   ```console\n   $ hopper-sim a\n   out\n   ```\n";
        let ex = examples("X.md", md).unwrap_or_default();
        assert_eq!(ex.len(), 1);
        assert_eq!(ex[0].expected, "out\n");
        let bad = "```console\nsome text\n$ hopper-sim a\n```\n";
        assert!(examples("X.md", bad).is_err_and(|e| e.contains("X.md:2")));
    }

    /// The words `issue N` (a tracker number a reader cannot open) in `text`.
    fn issue_numbers(text: &str) -> Vec<String> {
        let lower = text.to_ascii_lowercase();
        let mut found = Vec::new();
        for (i, _) in lower.match_indices("issue") {
            let before = lower[..i].chars().next_back();
            if before.is_some_and(|c| c.is_ascii_alphanumeric()) {
                continue;
            }
            let rest = lower[i + 5..].trim_start_matches('s');
            // A line break is a space in the rendered page.
            let rest = rest
                .strip_prefix(' ')
                .or_else(|| rest.strip_prefix('\n'))
                .unwrap_or("x");
            let rest = rest.strip_prefix('#').unwrap_or(rest);
            if rest.starts_with(|c: char| c.is_ascii_digit()) {
                let end = (i + 16).min(text.len());
                found.push(text.get(i..end).unwrap_or("").to_string());
            }
        }
        found
    }

    /// The pages a reader reads carry no tracker numbers: what happened
    /// when is the history page's (docs/history.md).
    #[test]
    fn no_issue_numbers_outside_the_history_page() {
        assert_eq!(
            issue_numbers("since issue 16 and Issue #5, issues 15, after issue\n17").len(),
            4
        );
        assert!(issue_numbers("the issue is 5 mm; tissue 3").is_empty());
        let root = crate::workspace_root();
        let mut pages = vec![root.join("README.md"), root.join("tests/link-session.txt")];
        for e in std::fs::read_dir(root.join("docs"))
            .into_iter()
            .flatten()
            .flatten()
        {
            let p = e.path();
            if p.extension().is_some_and(|x| x == "md") && !p.ends_with("history.md") {
                pages.push(p);
            }
        }
        let mut stale = Vec::new();
        for p in &pages {
            let text = std::fs::read_to_string(p).unwrap_or_default();
            for n in issue_numbers(&text) {
                stale.push(format!("{}: {n}", p.display()));
            }
        }
        assert!(stale.is_empty(), "{stale:#?}");
    }

    #[test]
    fn commands_map_to_hopper_sim_or_are_refused() {
        let a =
            hopper_sim_args("cargo run --release -p hal-sim --bin hopper-sim -- run --set 'a b=1'");
        assert_eq!(a, Ok(vec!["run".into(), "--set".into(), "a b=1".into()]));
        assert_eq!(
            hopper_sim_args("hopper-sim figures"),
            Ok(vec!["figures".to_string()])
        );
        assert!(hopper_sim_args("hopper-link status").is_err());
        assert!(hopper_sim_args("hopper-sim run | head").is_err());
    }

    #[test]
    fn elisions_match_and_figures_do_not() {
        let a = snapbox::Assert::new();
        let expected = "a [..] s\n...\nz 0.150\n";
        let ok = a.try_eq(
            None,
            snapbox::Data::text("a 1.23 s\nb\nc\nz 0.150\n"),
            snapbox::Data::text(expected),
        );
        assert!(ok.is_ok());
        let stale = a.try_eq(
            None,
            snapbox::Data::text("a 1.23 s\nz 0.151\n"),
            snapbox::Data::text(expected),
        );
        assert!(stale.is_err());
    }
}
