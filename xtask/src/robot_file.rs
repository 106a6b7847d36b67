//! `cargo xtask robot-file`: one robot file (tests/robots/heavy.toml: the
//! design machine with a 12 kg body and a 15 kN/m spring) read by the
//! simulator and by a virtual robot alike. `hopper-sim run --robot` hops
//! it; `hopper-sim serve --robot` runs it behind the link, where a
//! hopper-link session sets a machine's constant disarmed (and is refused
//! armed), is refused a file with one bad value (nothing changed), loads
//! back the file `robot show` wrote (nothing changed), and records the
//! hops. Prints `robot-file: hops=N apex_max_diff=P% ...` and fails when
//! any hop of the first eight differs from the host run's by more than 2%.

use crate::session::{host_binaries, numbers_after, shell, spawn_serve};
use std::path::Path;
use std::process::Command;

/// The robot every run here describes.
const ROBOT: &str = "tests/robots/heavy.toml";

/// Released from this toe height: on `serve`, held on the hoist until armed.
const START_APEX_M: &str = "0.1";

/// How many of the first hops are compared, one by one.
const HOPS: usize = 8;

/// The largest difference of one hop's apex between the host run and the
/// virtual robot, as a fraction of the host run's.
const TOLERANCE: f64 = 0.02;

/// The session (`OUT/` is its folder, `BAD` and `HEAVY` the files).
const SESSION: &str = "\
params get model.body_mass_kg
robot show --out OUT/shown.toml
params set model.body_mass_kg 12
! robot load BAD
params get model.body_mass_kg
robot load OUT/shown.toml
robot load HEAVY
arm --retry 5
! params set model.body_mass_kg 13
! robot load HEAVY
record --duration 10 --rate 200 --out OUT/record
disarm
";

/// `cargo xtask robot-file`.
pub fn run(root: &Path) -> Result<(), String> {
    let (link, sim) = host_binaries(root)?;
    let dir = crate::target_dir(root)?.join("robot-file");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let heavy = root.join(ROBOT);
    let text = std::fs::read_to_string(&heavy).map_err(|e| format!("{ROBOT}: {e}"))?;
    // One good change before one bad value: the refusal must undo nothing
    // because nothing was sent.
    let bad = dir.join("bad.toml");
    let bad_text = text
        .replace("body_mass_kg = 12.0", "body_mass_kg = 10.0")
        .replace("stroke_m = 0.05", "stroke_m = 0.9");
    std::fs::write(&bad, bad_text).map_err(|e| format!("{}: {e}", bad.display()))?;
    let script = dir.join("session.txt");
    std::fs::write(
        &script,
        SESSION
            .replace("BAD", &bad.display().to_string())
            .replace("HEAVY", &heavy.display().to_string()),
    )
    .map_err(|e| format!("{}: {e}", script.display()))?;

    // The host run.
    let out = Command::new(&sim)
        .args(["run", "--robot"])
        .arg(&heavy)
        .args([
            "--controller",
            "energy-apex",
            "--start-apex",
            START_APEX_M,
            "--duration",
            "10",
        ])
        .output()
        .map_err(|e| format!("cannot start hopper-sim: {e}"))?;
    let run_text = String::from_utf8_lossy(&out.stdout).to_string();
    if !out.status.success() {
        return Err(format!(
            "hopper-sim run --robot {ROBOT} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let run_lines: Vec<String> = run_text.lines().map(|l| l.trim().to_string()).collect();
    let run_apexes = numbers_after(&run_lines, "apex heights [m]").unwrap_or_default();

    // The virtual robot, driven by hopper-link.
    let mut cmd = Command::new(&sim);
    cmd.args(["serve", "--tcp", "127.0.0.1:0", "--speed", "3", "--robot"])
        .arg(&heavy)
        .args(["--controller", "energy-apex", "--start-apex", START_APEX_M]);
    let (server, addr) = spawn_serve(&mut cmd)?;
    let session = shell(&link, &addr, &script, &dir.join("session"), "robot-file");
    drop(server);
    let (success, out, err) = session?;
    let lines: Vec<String> = out.lines().map(str::to_string).collect();
    let mut problems = Vec::new();
    if !success {
        problems.push(format!("hopper-link failed: {}", err.trim()));
    }
    let shown = dir.join("session").join("shown.toml");
    let mut check = |what: &str, expected: String| {
        if lines.contains(&expected) {
            "ok".to_string()
        } else {
            problems.push(format!("{what}: missing `{expected}`"));
            "FAILED".to_string()
        }
    };
    let set_disarmed = check("set disarmed", "model.body_mass_kg = 12 kg (set)".into());
    let set_armed = check(
        "set armed",
        "failed as expected: set model.body_mass_kg = 13 refused: disarm-first (unchanged: 12 kg)"
            .into(),
    );
    let mut bad_file = check(
        "bad file",
        format!(
            "failed as expected: robot load: {}:27: `model.stroke_m = 0.9` is out of range: allowed 0.001 ..= 0.5 m; nothing changed",
            bad.display()
        ),
    );
    let round_trip = check(
        "round trip",
        format!(
            "loaded {}: 0 of 27 entries changed, the rest already so (not saved: `save` keeps them across a reset)",
            shown.display()
        ),
    );
    // After the refused file, the mass read back is still 12 kg (the
    // get after it is the third line that says so).
    let twelve = lines
        .iter()
        .filter(|l| l.as_str() == "model.body_mass_kg = 12 kg")
        .count();
    if twelve < 2 {
        problems.push("the mass was not read back as 12 kg after the refused file".into());
        bad_file = "FAILED".into();
    }
    let hops_csv = dir.join("session").join("record").join("hops.csv");
    let serve_apexes: Vec<f64> = std::fs::read_to_string(&hops_csv)
        .unwrap_or_default()
        .lines()
        .skip(1)
        .filter_map(|l| l.split(',').nth(1)?.parse().ok())
        .collect();
    let mut worst = 0.0f64;
    if run_apexes.len() < HOPS || serve_apexes.len() < HOPS {
        problems.push(format!(
            "fewer than {HOPS} hops: run {run_apexes:?}, serve {serve_apexes:?}"
        ));
    } else {
        for (a, b) in run_apexes.iter().zip(&serve_apexes).take(HOPS) {
            worst = worst.max((b - a).abs() / a);
        }
        if worst > TOLERANCE {
            problems.push(format!(
                "a hop differs by {:.1}% (at most {:.0}%): run {:?}, serve {:?}",
                worst * 100.0,
                TOLERANCE * 100.0,
                &run_apexes[..HOPS],
                &serve_apexes[..HOPS]
            ));
        }
    }
    let steady = |lines: &[String], prefix: &str| {
        numbers_after(lines, prefix)
            .and_then(|v| v.first().copied())
            .unwrap_or(f64::NAN)
    };
    let (run_steady, serve_steady) = (
        steady(&run_lines, "steady apex"),
        steady(&lines, "steady apex: "),
    );
    let agree = (serve_steady - run_steady).abs() <= TOLERANCE * run_steady;
    if !agree {
        problems.push(format!(
            "steady apex: run {run_steady} m, serve {serve_steady} m"
        ));
    }
    println!(
        "robot-file: robot={ROBOT} hops={} apex_max_diff={:.2}% steady_apex_run={run_steady:.4} steady_apex_serve={serve_steady:.4} set_disarmed={set_disarmed} set_armed_refused={set_armed} bad_file_refused_unchanged={bad_file} round_trip_unchanged={round_trip}",
        HOPS.min(serve_apexes.len()),
        worst * 100.0
    );
    if problems.is_empty() {
        Ok(())
    } else {
        Err(format!("robot-file: {}", problems.join("; ")))
    }
}
