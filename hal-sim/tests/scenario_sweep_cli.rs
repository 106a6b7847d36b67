//! `hopper-sim run --scenario` and `hopper-sim sweep`: scenario
//! files, flag precedence, sweep output and clean failures on bad input.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
        .args(args)
        .output()
        .expect("run hopper-sim")
}

fn scenario(name: &str) -> String {
    let p: PathBuf = [env!("CARGO_MANIFEST_DIR"), "..", "scenarios", name]
        .iter()
        .collect();
    p.to_str().unwrap().to_string()
}

fn json(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Fails with exit status 2, one error line containing `needle`, nothing on
/// stdout, and `out_dir` not created.
fn assert_clean_failure(args: &[&str], out_dir: &Path, needle: &str) {
    let o = sim(args);
    assert_eq!(o.status.code(), Some(2), "{args:?} should fail with 2");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "one error line: {err}");
    assert!(
        err.contains(needle),
        "{args:?}: expected `{needle}` in: {err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(o.stdout.is_empty());
    assert!(!out_dir.exists(), "no output may be written on bad input");
}

#[test]
fn shipped_scenarios_parse() {
    for name in [
        "energy-apex-design.toml",
        "passive-identified.toml",
        "lead-study.toml",
    ] {
        let s = hal_sim::scenario::load(Path::new(&scenario(name)))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let settings = hal_sim::scenario::Settings::resolve(Some(&s.settings), &Default::default());
        settings.check().unwrap_or_else(|e| panic!("{name}: {e}"));
    }
}

#[test]
fn flags_override_the_scenario_and_defaults_stay() {
    let file = scenario("energy-apex-design.toml");
    let v = json(&sim(&[
        "run",
        "--scenario",
        &file,
        "--duration",
        "1",
        "--target-apex",
        "0.04",
        "--json",
    ]));
    assert_eq!(v["controller"], "energy-apex");
    assert_eq!(v["params"], "design");
    assert_eq!(v["start_apex_m"], 0.1);
    assert_eq!(v["duration_s"], 1.0);
    assert_eq!(v["target_apex_m"], 0.04);
    assert!(v.get("first_stance_motor_work_j").is_some(), "{v}");

    // The file alone, and the same settings as flags, give the same run.
    let a = json(&sim(&[
        "run",
        "--scenario",
        &file,
        "--duration",
        "2",
        "--json",
    ]));
    let b = json(&sim(&[
        "run",
        "--params",
        "design",
        "--controller",
        "energy-apex",
        "--start-apex",
        "0.10",
        "--target-apex",
        "0.05",
        "--duration",
        "2",
        "--json",
    ]));
    assert_eq!(a["apex_heights_m"], b["apex_heights_m"]);

    // No scenario: the documented defaults.
    let d = json(&sim(&["run", "--duration", "0.5", "--json"]));
    assert_eq!(d["controller"], "passive");
    assert_eq!(d["params"], "design");
    assert_eq!(d["start_apex_m"], 0.15);
    assert!(d["target_apex_m"].is_null());
}

#[test]
fn bad_scenario_names_file_line_and_key_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    let out_s = out.to_str().unwrap();
    let bad = dir.path().join("bad.toml");
    let bad_s = bad.to_str().unwrap();

    std::fs::write(
        &bad,
        "duration_s = 2\n[controller]\nname = \"energy\"\ntarget_apex_m = 7\n",
    )
    .unwrap();
    assert_clean_failure(
        &["run", "--scenario", bad_s, "--out", out_s],
        &out,
        "bad.toml:4: `controller.target_apex_m` = 7 is out of range",
    );
    std::fs::write(&bad, "[plant]\nbase = \"design\"\nlead_m = 0.005\n").unwrap();
    assert_clean_failure(
        &["run", "--scenario", bad_s, "--out", out_s],
        &out,
        "bad.toml:3: unknown parameter `plant.lead_m`",
    );
    std::fs::write(&bad, "start_apex_m = 0.1\nstart_apexx_m = 0.1\n").unwrap();
    assert_clean_failure(
        &[
            "sweep",
            "--scenario",
            bad_s,
            "--param",
            "torque=0.5:1:2",
            "--out",
            out_s,
        ],
        &out,
        "bad.toml:2: unknown key `start_apexx_m`",
    );
    let missing = dir.path().join("missing.toml");
    assert_clean_failure(
        &[
            "run",
            "--scenario",
            missing.to_str().unwrap(),
            "--out",
            out_s,
        ],
        &out,
        "cannot read scenario file",
    );
}

#[test]
fn two_by_two_sweep_writes_four_rows_and_a_plot() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sw");
    let o = sim(&[
        "sweep",
        "--controller",
        "open-torque",
        "--noise",
        "off",
        "--duration",
        "0.6",
        "--param",
        "torque=0.5:1:2",
        "--param",
        "spring_stiffness_n_per_m=10000:11000:2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    for col in [
        "torque_nm",
        "spring_stiffness_n_per_m",
        "steady_apex_m",
        "hops_to_converge",
        "last_apex_m",
        "hops",
        "motor_work_j",
        "stop_impact_loss_j",
        "energy_per_stance_j",
        "first_stance_motor_work_j",
        "max_current_a",
        "max_stroke_m",
        "fault_count",
    ] {
        assert!(header.contains(&col), "missing column {col}: {header:?}");
    }
    assert_eq!(&header[..2], &["torque_nm", "spring_stiffness_n_per_m"]);
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 4, "{csv}");
    let swept: Vec<(&str, &str)> = rows.iter().map(|r| (r[0], r[1])).collect();
    assert_eq!(
        swept,
        [
            ("0.5", "10000"),
            ("0.5", "11000"),
            ("1", "10000"),
            ("1", "11000")
        ]
    );
    for r in &rows {
        assert_eq!(r.len(), header.len());
    }
    // More torque adds more energy in the first stance.
    let w = |r: &Vec<&str>| -> f64 { r[9].parse().unwrap() };
    assert_eq!(header[9], "first_stance_motor_work_j");
    assert!(w(&rows[2]) > w(&rows[0]), "{csv}");
    for f in ["sweep.png", "sweep.svg"] {
        assert!(std::fs::metadata(out.join(f)).unwrap().len() > 1000, "{f}");
    }
}

#[test]
fn lead_study_preset_matches_its_scenario_file() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a");
    let b = dir.path().join("b");
    let o = sim(&[
        "sweep",
        "--preset",
        "lead-study",
        "--out",
        a.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = sim(&[
        "sweep",
        "--scenario",
        &scenario("lead-study.toml"),
        "--out",
        b.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(a.join("sweep.csv")).unwrap();
    assert_eq!(csv, std::fs::read_to_string(b.join("sweep.csv")).unwrap());
    let leads: Vec<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap())
        .collect();
    assert_eq!(leads.len(), 9);
    assert_eq!((leads[0], leads[3], leads[8]), ("0.002", "0.005", "0.01"));
}

#[test]
fn bad_sweep_input_is_one_clear_error_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    let o = out.to_str().unwrap();
    let sweep = |param: &str| -> Vec<String> {
        [
            "sweep",
            "--controller",
            "open-torque",
            "--param",
            param,
            "--out",
            o,
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    for (param, needle) in [
        ("torque", "bad --param `torque`: no `=`"),
        ("torque=0.5:1", "is not START:END:N"),
        ("torque=0.5:x:3", "END `x` is not a finite number"),
        ("torque=0.5:1:0", "N `0` is not a count"),
        ("leed=1:2:3", "unknown parameter `leed`"),
        // `lead` is the short name of `screw_lead_m`: its range applies.
        (
            "lead=1:2:3",
            "sweep point screw_lead_m=1: parameter `screw_lead_m` = 1 is out of range",
        ),
        (
            "screw_lead_m=0:0.01:3",
            "sweep point screw_lead_m=0: parameter `screw_lead_m` = 0 is out of range",
        ),
        ("ke=1:2:2", "not by the `open-torque` controller"),
    ] {
        let args = sweep(param);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        assert_clean_failure(&args, &out, needle);
    }
    assert_clean_failure(&["sweep", "--out", o], &out, "nothing to sweep");
    assert_clean_failure(
        &["sweep", "--preset", "moon", "--out", o],
        &out,
        "unknown sweep preset `moon`",
    );
    assert_clean_failure(
        &[
            "sweep",
            "--param",
            "torque=1:1:1",
            "--controller",
            "open-torque",
            "--metric",
            "speed",
            "--out",
            o,
        ],
        &out,
        "unknown --metric `speed`",
    );
}

#[test]
fn seed_sweep_repeats_a_run_under_different_noise() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seeds");
    let o = sim(&[
        "sweep",
        "--controller",
        "energy-apex",
        "--start-apex",
        "0.03",
        "--duration",
        "0.6",
        "--param",
        "seed=1:3:3",
        "--metric",
        "first_stance_motor_work_j",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header[0], "noise_seed");
    let col = header
        .iter()
        .position(|c| *c == "first_stance_motor_work_j")
        .unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let seeds: Vec<&str> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(seeds, ["1", "2", "3"]);
    let work: Vec<f64> = rows.iter().map(|r| r[col].parse().unwrap()).collect();
    // Same scenario, different noise: close but not identical.
    assert!(work[0] != work[1] && work[1] != work[2], "{csv}");
    for w in &work {
        assert!((w - work[0]).abs() < 0.1 * work[0].abs(), "{csv}");
    }
    // With noise off a seed sweep would repeat one run: refused.
    let off = dir.path().join("off");
    assert_clean_failure(
        &[
            "sweep",
            "--noise",
            "off",
            "--param",
            "seed=1:3:3",
            "--out",
            off.to_str().unwrap(),
        ],
        &off,
        "changes nothing with sensor noise off",
    );
}

/// A 1.5 s noise-free `shaped` sweep from 0.05 m to `target` over `params`
/// (each `NAME=START:END:N`): its CSV header and rows.
fn shaped_sweep(
    out: &std::path::Path,
    target: &str,
    params: &[&str],
) -> (Vec<String>, Vec<Vec<String>>) {
    let mut args = vec![
        "sweep",
        "--controller",
        "shaped",
        "--noise",
        "off",
        "--start-apex",
        "0.05",
        "--target-apex",
        target,
        "--duration",
        "1.5",
        "--out",
        out.to_str().unwrap(),
    ];
    for p in params {
        args.extend(["--param", p]);
    }
    let o = sim(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let mut lines = csv
        .lines()
        .map(|l| l.split(',').map(String::from).collect());
    let header = lines.next().unwrap();
    (header, lines.collect())
}

#[test]
fn shaped_law_constants_are_sweepable_and_refused_elsewhere() {
    let dir = tempfile::tempdir().unwrap();
    let (header, rows) = shaped_sweep(
        &dir.path().join("sh"),
        "0.15",
        &["switch=0.5:0.6:2", "level_ki=0.05:0.1:2"],
    );
    assert_eq!(
        &header[..2],
        &["shaped_switch_fraction", "shaped_level_gain_per_j"]
    );
    let work = header.iter().position(|c| c == "motor_work_j").unwrap();
    assert_eq!(rows.len(), 4);
    // The switch time changes what the motor does.
    assert_ne!(rows[0][work], rows[2][work], "{rows:?}");
    // The outer loop's starting integral, near a target where the level
    // is not saturated.
    let (header, rows) = shaped_sweep(
        &dir.path().join("is"),
        "0.06",
        &["integral_start=0.4:0.8:2"],
    );
    assert_eq!(header[0], "shaped_integral_start");
    let work = header.iter().position(|c| c == "motor_work_j").unwrap();
    assert_eq!(rows.len(), 2);
    assert_ne!(rows[0][work], rows[1][work], "{rows:?}");
    let other = dir.path().join("other");
    assert_clean_failure(
        &[
            "sweep",
            "--controller",
            "energy",
            "--param",
            "switch=0.5:0.6:2",
            "--out",
            other.to_str().unwrap(),
        ],
        &other,
        "used by the shaped controller only",
    );
}

/// A sweep whose runs overheat the motor: the table says per point when
/// the current limit derated and which fault latched when, the tally
/// counts them, and sweep.csv has the same in its last columns.
#[test]
fn an_overheating_sweep_marks_derated_and_faulted_points() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("hot");
    let o = sim(&[
        "sweep",
        "--controller",
        "shaped",
        "--params",
        "design",
        "--noise",
        "off",
        "--start-apex",
        "0.05",
        "--target-apex",
        "0.15",
        "--duration",
        "15",
        "--param",
        "spin_up=0.6:1.0:2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[1].ends_with("outcome"), "{text}");
    // Spin-up 0.6 derates late and hops on; 1.0 derates early and trips.
    assert!(lines[2].contains("0.600000"), "{text}");
    assert!(lines[2].contains("not converged; derated from "), "{text}");
    assert!(!lines[2].contains("faulted"), "{text}");
    assert!(lines[3].contains("1.000000"), "{text}");
    assert!(
        lines[3].contains("; faulted: overtemperature at "),
        "{text}"
    );
    assert!(
        text.contains("0 of 2 points converged; 2 derated; 1 faulted (overtemperature 1)"),
        "{text}"
    );

    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let mut rows = csv.lines().map(|l| l.split(',').collect::<Vec<&str>>());
    let header = rows.next().unwrap();
    // The new columns come last, after every older one.
    assert_eq!(
        &header[header.len() - 5..],
        &[
            "first_apex_m",
            "first_derated_s",
            "peak_winding_c",
            "first_fault_s",
            "first_fault"
        ]
    );
    let col = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let rows: Vec<Vec<&str>> = rows.collect();
    let num = |r: &Vec<&str>, name: &str| -> Option<f64> { r[col(name)].parse().ok() };
    let (cool, hot) = (&rows[0], &rows[1]);
    assert_eq!(cool[col("first_fault")], "");
    assert_eq!(num(cool, "first_fault_s"), None);
    assert_eq!(num(cool, "fault_count"), Some(0.0));
    assert_eq!(hot[col("first_fault")], "overtemperature");
    assert_eq!(num(hot, "fault_count"), Some(1.0));
    let derated = num(hot, "first_derated_s").unwrap();
    let tripped = num(hot, "first_fault_s").unwrap();
    assert!(
        0.0 < derated && derated < tripped && tripped < 15.0,
        "{csv}"
    );
    // It trips at the trip temperature (150 C); the cooler run stays under.
    assert!(num(hot, "peak_winding_c").unwrap() >= 150.0, "{csv}");
    assert!(num(cool, "peak_winding_c").unwrap() < 150.0, "{csv}");
    assert!(num(cool, "first_derated_s").unwrap() > derated, "{csv}");
}
