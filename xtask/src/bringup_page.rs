//! The book's bring-up page (`docs/bring-up.md`) followed as written: the
//! `hopper-sim serve` line it gives started (only its port changed, to a
//! free one), then every `> COMMAND` of its `text session` blocks typed
//! into `hopper-link ... shell --stop-on-error`, and what the shell
//! printed compared with what the page shows (`...` and `[..]` as in the
//! docs' examples: a robot in real time is not bit-repeatable). The page
//! must end with the save accepted and the robot hopping at its target.
//!
//! Prints `bring-up-page: commands=N save=accepted steady_apex_m=A
//! target_m=T`.

use std::path::Path;
use std::process::Command;

use crate::session::{host_binaries, shell, spawn_serve};

/// The page.
const PAGE: &str = "docs/bring-up.md";

/// How close the recorded steady apex must be to the target, fraction.
const APEX_TOLERANCE: f64 = 0.02;

/// What the page says to run: the server's arguments (after
/// `hopper-sim`), the shell's commands, the output it shows.
#[derive(Debug, PartialEq)]
pub struct Page {
    /// `serve ...` as the page's `hopper-sim serve` line gives it.
    pub serve: Vec<String>,
    /// The `> ` lines, in order.
    pub commands: Vec<String>,
    /// The blocks' text, `...` between blocks.
    pub expected: String,
}

/// Reads the page: exactly one `hopper-sim serve` command (in a `sh`
/// block; continued lines joined, a trailing `&` dropped) and its `text
/// session` blocks.
pub fn read(text: &str) -> Result<Page, String> {
    let mut serve = None;
    let mut commands = Vec::new();
    let mut expected = String::from("...\n");
    let mut block: Option<&str> = None;
    let mut pending = String::new();
    for (n, line) in text.lines().enumerate() {
        let at = format!("{PAGE}:{}", n + 1);
        let t = line.trim_start();
        if let Some(info) = t.strip_prefix("```") {
            block = match block {
                Some(_) => {
                    if info.is_empty() {
                        None
                    } else {
                        return Err(format!("{at}: a fence inside a block"));
                    }
                }
                None => Some(if info.trim() == "text session" {
                    "session"
                } else if info.trim() == "sh" {
                    "sh"
                } else {
                    "other"
                }),
            };
            if block.is_none() && expected.ends_with('\n') && !expected.ends_with("...\n") {
                expected.push_str("...\n");
            }
            continue;
        }
        match block {
            Some("sh") => {
                // A command continued with `\` is one line.
                if let Some(head) = t.strip_suffix('\\') {
                    pending.push_str(head);
                    continue;
                }
                let joined = std::mem::take(&mut pending) + t;
                let t = joined.as_str();
                if let Some(rest) = t.strip_prefix("hopper-sim serve ") {
                    if serve.is_some() {
                        return Err(format!("{at}: a second `hopper-sim serve` line"));
                    }
                    let rest = rest.trim_end().trim_end_matches('&').trim_end();
                    let mut args = vec!["serve".to_string()];
                    args.extend(rest.split_whitespace().map(str::to_string));
                    serve = Some(args);
                }
            }
            Some("session") => {
                if let Some(c) = t.strip_prefix("> ") {
                    commands.push(c.to_string());
                }
                expected.push_str(t);
                expected.push('\n');
            }
            _ => {}
        }
    }
    let serve = serve.ok_or(format!("{PAGE}: no `hopper-sim serve` line"))?;
    if commands.is_empty() {
        return Err(format!("{PAGE}: no `text session` block"));
    }
    Ok(Page {
        serve,
        commands,
        expected,
    })
}

/// `serve`'s arguments with its `--tcp` address made a free port.
fn free_port(args: &[String]) -> Vec<String> {
    let mut out = args.to_vec();
    if let Some(i) = out.iter().position(|a| a == "--tcp") {
        if let Some(a) = out.get_mut(i + 1) {
            *a = "127.0.0.1:0".into();
        }
    }
    out
}

/// Runs the page against the virtual robot it names.
pub fn run(root: &Path) -> Result<(), String> {
    let text = std::fs::read_to_string(root.join(PAGE)).map_err(|e| format!("{PAGE}: {e}"))?;
    let page = read(&text)?;
    let (link, sim) = host_binaries(root)?;
    let out_dir = crate::target_dir(root)?.join("bring-up-page");
    let _ = std::fs::remove_dir_all(&out_dir);
    std::fs::create_dir_all(&out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    let script = out_dir.join("script.txt");
    std::fs::write(&script, page.commands.join("\n") + "\n").map_err(|e| e.to_string())?;
    let (server, addr) = spawn_serve(
        Command::new(&sim)
            .args(free_port(&page.serve))
            .current_dir(root),
    )?;
    // The page's relative paths (`--out run1`) land in the run's folder.
    let (ok, out, err) = shell(
        &link,
        &addr,
        &script,
        &out_dir.join("files"),
        "bring-up-page",
    )?;
    drop(server);
    let mut problems = Vec::new();
    if !ok {
        problems.push(format!(
            "hopper-link stopped at a command that did not go as the page says: {}",
            err.trim()
        ));
    }
    if let Err(diff) = snapbox::Assert::new().try_eq(
        None,
        snapbox::Data::text(out.clone()),
        snapbox::Data::text(page.expected.clone()),
    ) {
        problems.push(format!(
            "the shell printed other than the page shows:\n{diff}"
        ));
    }
    let saved = out.lines().any(|l| l.starts_with("saved: "));
    if !saved {
        problems.push("no accepted save".into());
    }
    // `steady apex: A m (target T m, ...)`.
    let apex = out.lines().rev().find_map(|l| {
        let rest = l.strip_prefix("steady apex: ")?;
        let (a, rest) = rest.split_once(" m (target ")?;
        let t = rest.split_once(" m")?.0;
        Some((a.parse::<f64>().ok()?, t.parse::<f64>().ok()?))
    });
    match apex {
        Some((a, t)) if (a - t).abs() <= APEX_TOLERANCE * t => {}
        Some((a, t)) => problems.push(format!(
            "the steady apex {a} m is not within {}% of the target {t} m",
            APEX_TOLERANCE * 100.0
        )),
        None => problems.push("no steady apex recorded: the robot did not hop".into()),
    }
    println!(
        "bring-up-page: commands={} save={} steady_apex_m={} target_m={}",
        page.commands.len(),
        if saved { "accepted" } else { "none" },
        apex.map_or("-".into(), |(a, _)| format!("{a:.4}")),
        apex.map_or("-".into(), |(_, t)| format!("{t:.4}")),
    );
    if problems.is_empty() {
        Ok(())
    } else {
        eprintln!("xtask: bring-up-page: the shell printed:\n{out}");
        Err(format!("{PAGE} as written: {}", problems.join("; ")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_gives_one_server_and_its_sessions() {
        let md = "Start:\n\n```sh\nhopper-sim serve --tcp 127.0.0.1:7300 \\\n    --speed 3 &\nhopper-link --tcp 127.0.0.1:7300 shell\n```\n\n```text session\n> status\nstate: [..]\n```\n\ntext\n\n```text session\n> save\nsaved: [..]\n```\n";
        let p = read(md).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            p.serve,
            ["serve", "--tcp", "127.0.0.1:7300", "--speed", "3"]
        );
        assert_eq!(free_port(&p.serve)[2], "127.0.0.1:0");
        assert_eq!(p.commands, ["status", "save"]);
        assert_eq!(
            p.expected,
            "...\n> status\nstate: [..]\n...\n> save\nsaved: [..]\n...\n"
        );
        assert!(read("no server\n```text session\n> x\n```\n").is_err());
    }

    /// The page's server is mis-calibrated as the CI's session robot is
    /// (`Miscalibration::SESSION`, which `cargo xtask link-session` and the
    /// QEMU link image use), so the page's figures and CI's agree.
    #[test]
    fn the_pages_miscalibration_is_the_sessions() {
        let text =
            std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(PAGE))
                .unwrap_or_else(|e| panic!("{PAGE}: {e}"));
        let page = read(&text).unwrap_or_else(|e| panic!("{e}"));
        let flag = |name: &str| {
            let at = page.serve.iter().position(|a| a == name);
            at.and_then(|i| page.serve.get(i + 1))
                .and_then(|v| v.parse::<f64>().ok())
                .unwrap_or_else(|| panic!("{PAGE}: no {name} N on the serve line"))
        };
        let m = hopper_sil::robot::Miscalibration::SESSION;
        for (name, want) in [
            ("--loadcell-bias-n", m.loadcell_bias_n),
            ("--pot-bias-m", m.pot_bias_m),
            ("--nut-start-m", m.nut_start_m),
            ("--spring-rate-error", m.spring_rate_error),
            ("--height-zero-error-m", m.height_zero_error_m),
            ("--loadcell-gain-error", m.loadcell_gain_error),
        ] {
            assert_eq!(flag(name), want, "{name}");
        }
    }
}
