//! The `hopper-sim` command-line contract: flags, JSON keys,
//! output files, and clear errors for bad input.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::process::{Command, Output};
use std::sync::OnceLock;

fn sim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
        .args(args)
        .output()
        .expect("run hopper-sim")
}

fn json(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout.clone()).unwrap();
    assert_eq!(
        text.trim().lines().count(),
        1,
        "exactly one JSON line: {text}"
    );
    serde_json::from_str(&text).unwrap()
}

/// `run --params identified --controller passive --start-apex 0.15
/// --duration 2 --json`, simulated once for the tests that share it. 2 s,
/// not the default 5: the 5 s run is canonical run (c) of the
/// software-in-the-loop tests (`tests/tests/passive_hopping.rs`), which
/// snapshot its whole JSON; simulating it here too would be the same run
/// twice.
fn identified_passive_json() -> &'static serde_json::Value {
    static RUN: OnceLock<serde_json::Value> = OnceLock::new();
    RUN.get_or_init(|| {
        json(&sim(&[
            "run",
            "--params",
            "identified",
            "--controller",
            "passive",
            "--start-apex",
            "0.15",
            "--duration",
            "2",
            "--json",
        ]))
    })
}

#[test]
fn run_json_has_the_contract_keys() {
    let v = identified_passive_json();
    for key in [
        "apex_heights_m",
        "hops",
        "steady_apex_m",
        "stance_time_s",
        "stopped_at_s",
        "energy_residual_j",
    ] {
        assert!(v.get(key).is_some(), "missing key {key} in {v}");
    }
    let apexes = v["apex_heights_m"].as_array().unwrap();
    assert!(!apexes.is_empty());
    assert_eq!(v["hops"].as_u64().unwrap() as usize, apexes.len() + 1);
    // Identified friction: hopping stops within a few seconds (thesis: ~1.5 s).
    let stopped = v["stopped_at_s"].as_f64().unwrap();
    assert!((0.5..3.0).contains(&stopped), "stopped at {stopped}");
    assert!(v["steady_apex_m"].is_null());
    let stance = v["stance_time_s"].as_f64().unwrap();
    assert!((0.08..0.12).contains(&stance), "stance {stance}");
    assert!(v["energy_residual_j"].as_f64().unwrap().abs() < 1e-6);
}

#[test]
fn out_dir_gets_csv_and_plot() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = sim(&["run", "--duration", "1", "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("hops") && stdout.contains("steady apex"),
        "{stdout}"
    );
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "time_s,phase,z_m,zd_mps,p_m,pd_mps,toe_height_m,spring_force_n,torque_nm,energy_j,winding_c"
    );
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), 1001, "1 s at 1 kHz plus the start");
    assert!(rows.iter().any(|r| r.contains(",stance,")));
    let png = std::fs::read(out.join("hop.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    assert!(png.len() > 10_000);
}

/// `telemetry.mcap`, read by a reader written from the MCAP specification:
/// every trajectory sample at its time with the CSV's values, the
/// firmware's hop ledgers and its parameters.
#[test]
fn out_dir_gets_an_mcap_recording_that_matches_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = sim(&[
        "run",
        "--duration",
        "3",
        "--json",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json(&o);
    let bytes = std::fs::read(out.join("telemetry.mcap")).unwrap();
    let msgs = hopper_mcap::read::messages(&bytes).unwrap_or_else(|e| panic!("{e}"));
    let on = |topic: &str| msgs.iter().filter(|m| m.topic == topic).collect::<Vec<_>>();
    let (telemetry, hops, params) = (on("/telemetry"), on("/hop"), on("/parameters"));
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    eprintln!(
        "telemetry.mcap: {} bytes, /telemetry {} (CSV rows {}), /hop {}, /parameters {}",
        bytes.len(),
        telemetry.len(),
        rows.len(),
        hops.len(),
        params.len()
    );
    assert_eq!(telemetry.len(), rows.len());
    let ledgers = v["firmware_hops"].as_array().unwrap();
    assert!(ledgers.len() >= 3, "{ledgers:?}");
    assert_eq!(hops.len(), ledgers.len());
    for (m, l) in hops.iter().zip(ledgers) {
        assert_eq!(m.json, *l);
    }
    assert_eq!(params.len(), 1);
    // The firmware's table, every parameter (another controller's: null).
    let p = params[0].json.as_object().unwrap();
    assert_eq!(p.len(), hopper_control::params::TABLE.len());
    assert!(p["target_apex_m"].is_number() && p["controller"].is_number());
    for (row, m) in rows.iter().zip(&telemetry) {
        let cells: Vec<&str> = row.split(',').collect();
        let num = |i: usize| cells[i].parse::<f64>().unwrap();
        let j = |k: &str| m.json[k].as_f64().unwrap();
        // (The CSV's decimals: 6 for the time, 9 for the states.)
        assert!((m.log_time_ns as f64 * 1e-9 - num(0)).abs() < 1e-6, "{row}");
        assert_eq!(m.json["phase"], cells[1], "{row}");
        assert!((j("z_m") - num(2)).abs() < 1e-9, "{row}");
        assert!((j("toe_height_m") - num(6)).abs() < 1e-9, "{row}");
        assert!((j("energy_j") - num(9)).abs() < 1e-9, "{row}");
    }
}

#[test]
fn params_show_prints_toml_that_run_accepts() {
    let o = sim(&["params", "show", "identified"]);
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(text.contains("planarizer_friction_n = 13.0"));
    assert!(text.contains("[model]\n") && text.contains("[plant]\n") && text.contains("kg."));
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("mine.toml");
    std::fs::write(&f, &text).unwrap();
    let a = json(&sim(&[
        "run",
        "--params",
        f.to_str().unwrap(),
        "--duration",
        "2",
        "--json",
    ]));
    let b = identified_passive_json();
    // The robot file holds the firmware's f32 values: the plant's current
    // limit is 33.670033 A, not 33.67003367... A.
    let apexes = |j: &serde_json::Value| -> Vec<f64> {
        j["apex_heights_m"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    assert_eq!(apexes(&a).len(), apexes(b).len());
    for (x, y) in apexes(&a).iter().zip(apexes(b)) {
        assert!((x - y).abs() <= 1e-6 * y, "{x} {y}");
    }
    // `--robot` reads the same file as the same plant.
    let r = json(&sim(&[
        "run",
        "--robot",
        f.to_str().unwrap(),
        "--duration",
        "2",
        "--json",
    ]));
    assert_eq!(apexes(&r), apexes(&a));
}

fn assert_clean_failure(args: &[&str], out_dir: &Path, needle: &str) {
    let mut all: Vec<&str> = args.to_vec();
    let out_s = out_dir.to_str().unwrap().to_string();
    all.extend(["--out", &out_s]);
    let o = sim(&all);
    assert!(!o.status.success(), "{args:?} should fail");
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
fn bad_input_is_one_clear_error_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    assert_clean_failure(&["run", "--params", "moon"], &out, "unknown preset `moon`");
    assert_clean_failure(
        &["run", "--controller", "magic"],
        &out,
        "unknown controller `magic`",
    );
    assert_clean_failure(
        &["run", "--start-apex", "-0.1"],
        &out,
        "start apex -0.1 m is out of range",
    );
    assert_clean_failure(
        &["run", "--start-apex", "5"],
        &out,
        "start apex 5 m is out of range",
    );
    assert_clean_failure(
        &["run", "--duration", "0"],
        &out,
        "duration 0 s is out of range",
    );

    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "base = \"design\"\nbody_mass_kg = [1\n").unwrap();
    assert_clean_failure(
        &["run", "--params", bad.to_str().unwrap()],
        &out,
        "malformed TOML",
    );

    std::fs::write(&bad, "base = \"design\"\n\nbody_mass_kg = -9.0\n").unwrap();
    assert_clean_failure(
        &["run", "--params", bad.to_str().unwrap()],
        &out,
        "bad.toml:3: parameter `body_mass_kg` = -9 is out of range",
    );
    let missing = dir.path().join("missing.toml");
    assert_clean_failure(
        &["run", "--params", missing.to_str().unwrap()],
        &out,
        "cannot read parameter file",
    );

    let o = sim(&["params", "show", "moon"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown preset `moon`"));
}

#[test]
fn inject_estop_latches_and_reports_in_json() {
    let v = json(&sim(&[
        "run",
        "--controller",
        "open-torque",
        "--start-apex",
        "0.10",
        "--duration",
        "1",
        "--inject",
        "estop@0.5",
        "--json",
    ]));
    let faults = v["faults"].as_array().unwrap();
    assert_eq!(faults[0]["name"], "estop", "{faults:?}");
    let t = faults[0]["time_s"].as_f64().unwrap();
    assert!((t - 0.5).abs() < 1e-3, "{t}");
    assert_eq!(v["max_abs_current_after_fault_a"].as_f64(), Some(0.0));
    assert!((v["first_fault_s"].as_f64().unwrap() - 0.5).abs() < 1e-3);
    // Without an injection: no fault, and nothing commanded after one.
    let clean = json(&sim(&["run", "--duration", "0.5", "--json"]));
    assert_eq!(clean["faults"].as_array().map(Vec::len), Some(0));
    assert!(clean["max_abs_current_after_fault_a"].is_null());
}

#[test]
fn bad_inject_spec_is_one_clear_error_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    for (spec, needle) in [
        ("boom@1", "unknown fault kind `boom`"),
        ("estop@soon", "bad fault injection `estop@soon`"),
        ("estop", "bad fault injection `estop`"),
        ("estop@-1", "bad fault injection"),
    ] {
        assert_clean_failure(&["run", "--inject", spec], &out, needle);
        // The message names every accepted kind.
        let o = sim(&["run", "--inject", spec]);
        assert_eq!(o.status.code(), Some(2));
        let err = String::from_utf8_lossy(&o.stderr);
        for kind in hal_sim::inject::INJECT_KINDS {
            assert!(err.contains(kind), "{kind} missing from: {err}");
        }
    }
    assert_clean_failure(
        &["run", "--duration", "1", "--inject", "estop@2"],
        &out,
        "at or after the end of the run",
    );
}

#[test]
fn shaped_with_model_params_and_ledger() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model.toml");
    std::fs::write(
        &model,
        "base = \"design\"\nspring_stiffness_n_per_m = 13200\n",
    )
    .unwrap();
    let m = model.to_str().unwrap();
    let common = [
        "run",
        "--params",
        "design",
        "--model-params",
        m,
        "--controller",
        "shaped",
        "--target-apex",
        "0.15",
        "--start-apex",
        "0.05",
        "--duration",
        "2.5",
    ];
    let v = json(&sim(&[&common[..], &["--json"]].concat()));
    assert_eq!(v["controller"], "shaped");
    let hops = v["hop_ledger"].as_array().unwrap();
    assert!(hops.len() >= 3, "{v}");
    for key in [
        "apex_time_s",
        "apex_m",
        "total_energy_j",
        "motor_work_j",
        "friction_j",
        "touchdown_loss_j",
        "liftoff_loss_j",
        "stop_impact_loss_j",
        "settle_loss_j",
        "actuator_kinetic_j",
        "actuator_spring_j",
        "duration_s",
        "copper_loss_j",
        "stance_copper_loss_j",
        "flight_copper_loss_j",
        "rms_current_a",
    ] {
        assert!(hops[0].get(key).is_some(), "hop_ledger lacks {key}");
        assert!(v["steady_hop"].get(key).is_some(), "steady_hop lacks {key}");
    }
    // The text report with --ledger: one row per hop under a header.
    let o = sim(&[&common[..], &["--ledger"]].concat());
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(text.contains("per-hop energy ledger"), "{text}");
    let rows = text
        .lines()
        .filter(|l| {
            l.split_whitespace().count() == 13 && l.trim_start().starts_with(char::is_numeric)
        })
        .count();
    assert_eq!(rows, hops.len(), "{text}");

    // A bad model file: one clear error naming the flag and the field.
    std::fs::write(&model, "base = \"design\"\nspring_stiffness_n_per_m = -5\n").unwrap();
    let out = dir.path().join("out");
    assert_clean_failure(&common, &out, "spring_stiffness_n_per_m");
    let o = sim(&[&common[..], &["--json"]].concat());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--model-params"));
}

#[test]
fn a_closed_stdout_ends_quietly() {
    // A pipe whose read end is already closed: every write to it fails, as
    // for `hopper-sim run ... | head` once head has exited.
    for args in [
        &["run", "--duration", "0.5", "--ledger"][..],
        &["run", "--duration", "0.5", "--json"],
        &["params", "show", "design"],
    ] {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let o = Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
            .args(args)
            .stdout(writer)
            .stderr(std::process::Stdio::piped())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.is_empty(), "{args:?}: {err}");
        assert_eq!(o.status.code(), Some(0), "{args:?}");
    }
}

#[test]
fn a_failed_plot_leaves_no_partial_output() {
    let dir = tempfile::tempdir().unwrap();
    // One trajectory sample in 0.5 s at 1 Hz: the CSV is written, then the
    // plot fails (it needs two samples).
    let plot_fails = ["run", "--duration", "0.5", "--sample-hz", "1"];
    let out = dir.path().join("new").join("run");
    let o = sim(&[&plot_fails[..], &["--out", out.to_str().unwrap()]].concat());
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("not enough samples to plot"), "{err}");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "left behind: {left:?}");

    // Into an existing result: the old files stay as they were, no staging
    // directory is left, and the new run's CSV does not replace the old one.
    let out = dir.path().join("run");
    let ok = sim(&["run", "--duration", "0.2", "--out", out.to_str().unwrap()]);
    assert!(ok.status.success());
    let before = std::fs::read(out.join("trajectory.csv")).unwrap();
    let o = sim(&[&plot_fails[..], &["--out", out.to_str().unwrap()]].concat());
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(std::fs::read(out.join("trajectory.csv")).unwrap(), before);
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["hop.png", "telemetry.mcap", "trajectory.csv"]);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

/// `--set NAME=VALUE` reaches the firmware's parameter table: a changed
/// value changes the run, a bad name, value or controller is one clear
/// error that writes nothing.
#[test]
fn set_changes_a_firmware_parameter_by_name() {
    let base = [
        "run",
        "--params",
        "design",
        "--controller",
        "energy-apex",
        "--start-apex",
        "0.10",
        "--duration",
        "2",
        "--json",
    ];
    let apexes = |extra: &[&str]| {
        let args: Vec<&str> = base.iter().chain(extra).copied().collect();
        let out = sim(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        json(&out)["apex_heights_m"].clone()
    };
    let default = apexes(&[]);
    // The default value, set explicitly: the same run.
    assert_eq!(apexes(&["--set", "energy_apex.integral_gain=0.6"]), default);
    // A twelfth of the outer loop's integral gain: after the high start the
    // apex climbs back towards the 0.05 m target more slowly (0.0324 m
    // against 0.0351 m after 2 s).
    let slow = apexes(&["--set", "energy_apex.integral_gain=0.05"]);
    let last = |v: &serde_json::Value| {
        v.as_array()
            .and_then(|a| a.last())
            .and_then(serde_json::Value::as_f64)
            .unwrap_or(f64::NAN)
    };
    assert!(last(&slow) < last(&default) - 0.002, "{slow} vs {default}");

    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let out_dir = dir.path().join("set");
    for (set, needle) in [
        ("no.such=1", "no firmware parameter `no.such`"),
        ("energy_apex.integral_gain=20", "must be in 0.001 ..= 9.99"),
        // A parameter with a flag of its own is set there only.
        (
            "flight.kp_a_per_rad=5",
            "set `flight.kp_a_per_rad` with --flight-kp",
        ),
        (
            "shaped.switch_fraction=0.5",
            "applies to the shaped controller, not to the `energy-apex` controller",
        ),
        (
            "energy_apex.measure=kinetic",
            "is one of [\"total\", \"body\"]",
        ),
    ] {
        assert_clean_failure(
            &[
                "run",
                "--controller",
                "energy-apex",
                "--duration",
                "1",
                "--set",
                set,
            ],
            &out_dir,
            needle,
        );
    }
}

/// `--motor` changes the plant's motor and the firmware's thermal data
/// together, and the summary says which.
#[test]
fn a_catalogue_motor_on_the_plant_and_in_the_firmware() {
    let run = |motor: &[&str]| {
        let mut args = vec![
            "run",
            "--controller",
            "shaped",
            "--start-apex",
            "0.05",
            "--duration",
            "2",
            "--json",
        ];
        args.extend_from_slice(motor);
        json(&sim(&args))
    };
    let own = run(&[]);
    let pittman = run(&["--motor", "pittman-14204"]);
    assert_eq!(pittman["params"], "design+pittman-14204");
    // Its no-load speed (24 V / 61.2 mN m/A) and its own winding
    // resistance in the firmware's estimate (1.01 ohm at 25 C).
    let nl = pittman["no_load_speed_rad_s"].as_f64().unwrap();
    assert!((nl - 24.0 / 0.0612).abs() < 0.5, "{nl}");
    // (the plant books the copper at the estimate's R(T)).
    let r = |s: &serde_json::Value| {
        s["ledger"]["copper_loss_j"].as_f64().unwrap()
            / s["ledger"]["current_squared_a2s"].as_f64().unwrap()
    };
    // The winding warms by 15-26 K in 2 s: R(T) 3-10 % above R_25 (the
    // plant's own 0.356 ohm is 19 % above the stand-in's 0.299).
    assert!((1.04..1.11).contains(&r(&pittman)), "{}", r(&pittman));
    assert!((0.305..0.33).contains(&r(&own)), "{}", r(&own));
    assert_eq!(pittman["thermal"]["motor_data"], "configured");
    // Its stall current, under the amplifier's 33.7 A.
    let stall = pittman["thermal"]["amplifier_limit_a"].as_f64().unwrap();
    assert!((stall - 24.0 / 1.01).abs() < 0.01, "{stall}");
    // `--motor design` is the preset as it is.
    let same = run(&["--motor", "design"]);
    assert_eq!(same["apex_heights_m"], own["apex_heights_m"]);
}

/// The firmware books copper only for current the amplifier was told to
/// drive: a robot whose arming is refused heats nothing.
#[test]
fn a_disarmed_robot_books_no_copper() {
    let s = json(&sim(&[
        "run",
        "--params",
        "design",
        "--controller",
        "open-torque",
        "--start-apex",
        "0.10",
        "--duration",
        "1.5",
        "--set",
        "arming.untethered=0",
        "--json",
    ]));
    assert_eq!(s["arm_refused"], "link-down");
    let hops = s["firmware_hops"].as_array().unwrap();
    assert!(hops.len() >= 4, "{hops:?}");
    for h in hops {
        assert_eq!(h["copper_loss_j"].as_f64(), Some(0.0), "{h}");
    }
    assert_eq!(s["ledger"]["copper_loss_j"].as_f64(), Some(0.0));
}

/// Every flag and scenario key of [`hal_sim::names::ALIASES`] is one that
/// `hopper-sim run` and the scenario reader take, so the table of a
/// quantity's other names cannot name one that does not exist.
#[test]
fn every_alias_flag_and_key_exists() {
    let help = String::from_utf8(sim(&["run", "--help"]).stdout).unwrap();
    for a in hal_sim::names::ALIASES {
        if let Some(flag) = a.flag {
            assert!(
                help.split_whitespace().any(|w| w == flag),
                "`hopper-sim run` has no {flag}"
            );
        }
        if let Some(key) = a.key {
            let value = match a.name() {
                "controller" => "\"shaped\"".to_string(),
                "noise_seed" => "1".to_string(),
                n => hopper_control::params::find(n)
                    .map_or(0.1, |p| f64::from(p.default))
                    .to_string(),
            };
            let toml = match key.split_once('.') {
                Some((table, k)) => format!("[{table}]\n{k} = {value}\n"),
                None => format!("{key} = {value}\n"),
            };
            if let Err(e) = hal_sim::scenario::from_toml_str(&toml, "alias test") {
                panic!("scenario key {key}: {e}");
            }
        }
    }
}

/// `serve --help` says what `serve` does with `--start-apex`: it starts
/// standing unless given (the run's help says 0.15 m, `run`'s default).
#[test]
fn serve_help_says_the_real_start() {
    let o = sim(&["serve", "--help"]);
    let text = String::from_utf8_lossy(&o.stdout);
    let line = text
        .lines()
        .skip_while(|l| !l.contains("--start-apex"))
        .take(3)
        .collect::<Vec<_>>()
        .join(" ");
    assert!(line.contains("standing"), "{line}");
    assert!(!line.contains("0.15"), "{line}");
    let o = sim(&["run", "--help"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("[default: 0.15]"));
}

/// What serve does not do it refuses, with the way to do it, instead of
/// ignoring: run's duration and fault injections, from the flags or a
/// scenario file.
#[test]
fn serve_refuses_what_only_run_does() {
    let dir = std::env::temp_dir().join(format!("serve-refuses-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let scenario = dir.join("s.toml");
    std::fs::write(&scenario, "start_apex_m = 0.1\n").unwrap_or_default();
    let scenario = scenario.display().to_string();
    for (args, says) in [
        (vec!["--duration", "0.5"], "--duration is not for serve"),
        (vec!["--inject", "estop@0.3"], "estop press"),
        (
            vec!["--scenario", scenario.as_str()],
            "`start_apex_m` is not for serve",
        ),
    ] {
        let mut all = vec!["serve", "--tcp", "127.0.0.1:0", "--for", "0.01"];
        all.extend(args);
        let o = sim(&all);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{all:?}");
        assert!(err.contains(says), "{all:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
