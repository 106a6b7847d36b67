//! Bad input at the edges: each class of bad configuration,
//! flag or parameter set gives exit status 2, exactly one
//! `hopper-sim: error:` line naming the field, and no output directory.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// A temp dir with `out` (never to be created) and room for input files.
struct Case {
    dir: tempfile::TempDir,
}

impl Case {
    fn new() -> Self {
        Case {
            dir: tempfile::tempdir().unwrap(),
        }
    }

    fn out(&self) -> PathBuf {
        self.dir.path().join("out")
    }

    fn file(&self, name: &str, text: &str) -> String {
        let p = self.dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    }

    /// Runs `args --out OUT` and asserts the clean failure, with `needles`
    /// all in the one error line.
    fn fails(&self, args: &[&str], needles: &[&str]) {
        let out = self.out();
        let o = Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
            .args(args)
            .arg("--out")
            .arg(&out)
            .output()
            .expect("run hopper-sim");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(lines.len(), 1, "{args:?}: one line: {err}");
        assert!(lines[0].starts_with("hopper-sim: error: "), "{err}");
        for n in needles {
            assert!(lines[0].contains(n), "{args:?}: expected `{n}` in: {err}");
        }
        assert!(o.stdout.is_empty(), "{args:?}");
        assert!(!Path::new(&out).exists(), "{args:?}: output written");
    }
}

#[test]
fn zero_or_negative_mass() {
    let c = Case::new();
    let p = c.file("p.toml", "base = \"design\"\nbody_mass_kg = 0\n");
    c.fails(
        &["run", "--params", &p],
        &["p.toml:2", "body_mass_kg", "= 0"],
    );
    let p = c.file("n.toml", "base = \"design\"\nnut_mass_kg = -0.1\n");
    c.fails(
        &["run", "--params", &p],
        &["n.toml:2", "nut_mass_kg", "-0.1"],
    );
    let s = c.file(
        "s.toml",
        "plant = { base = \"design\", unsprung_mass_kg = -1 }\n",
    );
    c.fails(
        &["run", "--scenario", &s],
        &["s.toml:1", "plant.unsprung_mass_kg"],
    );
    c.fails(
        &[
            "sweep",
            "--controller",
            "energy",
            "--param",
            "body_mass_kg=-1:9:2",
        ],
        &["body_mass_kg=-1", "body_mass_kg"],
    );
    // Exactly zero is refused for the lower leg and the nut too: the range
    // printed says so.
    let p = c.file("u.toml", "base = \"design\"\nunsprung_mass_kg = 0\n");
    c.fails(
        &["run", "--params", &p],
        &[
            "u.toml:2",
            "unsprung_mass_kg",
            "= 0",
            "allowed 0.000000001 ..= 100 kg",
        ],
    );
    let s = c.file("m.toml", "[model]\nbase = \"design\"\nnut_mass_kg = 0.0\n");
    c.fails(
        &["run", "--scenario", &s],
        &[
            "m.toml:3",
            "model.nut_mass_kg",
            "allowed 0.000000001 ..= 100 kg",
        ],
    );
    c.fails(
        &["run", "--model-params", &p],
        &[
            "u.toml:2",
            "unsprung_mass_kg",
            "allowed 0.000000001 ..= 100 kg",
        ],
    );
    c.fails(
        &[
            "sweep",
            "--controller",
            "energy",
            "--param",
            "nut_mass_kg=0:0.5:3",
        ],
        &[
            "nut_mass_kg=0",
            "nut_mass_kg",
            "allowed 0.000000001 ..= 100 kg",
        ],
    );
}

#[test]
fn zero_stiffness() {
    let c = Case::new();
    let p = c.file(
        "p.toml",
        "base = \"design\"\nspring_stiffness_n_per_m = 0\n",
    );
    c.fails(
        &["run", "--params", &p],
        &["spring_stiffness_n_per_m", "= 0"],
    );
    let s = c.file(
        "s.toml",
        "[plant]\nbase = \"design\"\nspring_stiffness_n_per_m = 0.0\n",
    );
    c.fails(
        &["run", "--scenario", &s],
        &["s.toml:3", "plant.spring_stiffness_n_per_m"],
    );
}

#[test]
fn negative_lead() {
    let c = Case::new();
    let p = c.file("p.toml", "base = \"design\"\nscrew_lead_m = -0.005\n");
    c.fails(
        &["run", "--params", &p],
        &["p.toml:2", "screw_lead_m", "-0.005"],
    );
    let s = c.file(
        "s.toml",
        "model = { base = \"design\", screw_lead_m = -0.005 }\n",
    );
    c.fails(
        &["run", "--scenario", &s],
        &["s.toml:1", "model.screw_lead_m"],
    );
}

#[test]
fn stroke_above_the_hardware() {
    let c = Case::new();
    let p = c.file("p.toml", "base = \"design\"\nstroke_m = 0.8\n");
    c.fails(&["run", "--params", &p], &["stroke_m", "0.8", "0.5"]);
    // The controller's model may not claim more stroke than the plant has.
    let s = c.file(
        "s.toml",
        "plant = \"design\"\nmodel = { base = \"design\", stroke_m = 0.06 }\ncontroller = \"energy-apex\"\n",
    );
    c.fails(
        &["run", "--scenario", &s],
        &["model.stroke_m = 0.06", "plant.stroke_m = 0.05"],
    );
}

#[test]
fn unstable_flight_pd() {
    let c = Case::new();
    c.fails(
        &[
            "run",
            "--controller",
            "energy-apex",
            "--flight-kp",
            "20.3152",
            "--flight-kd",
            "80",
        ],
        &["--flight-kd", "= 80", "unstable", "..= 50.9"],
    );
    c.fails(
        &["run", "--controller", "energy-apex", "--flight-kd", "0"],
        &["--flight-kd", "= 0", "without damping"],
    );
    let s = c.file(
        "s.toml",
        "[controller]\nname = \"energy\"\nflight_kp_a_per_rad = 20\nflight_kd_a_s_per_rad = 0\n",
    );
    c.fails(
        &["run", "--scenario", &s],
        &["controller.flight_kd_a_s_per_rad", "= 0", "unstable"],
    );
    c.fails(
        &[
            "run",
            "--params",
            "identified",
            "--controller",
            "energy",
            "--control-hz",
            "100",
        ],
        &["--control-hz", "100 Hz", "unstable"],
    );
    c.fails(
        &["run", "--controller", "energy-apex", "--flight-kp", "-1"],
        &["--flight-kp", "-1", "out of range"],
    );
    // Every sweep point is checked before any run.
    c.fails(
        &[
            "sweep",
            "--controller",
            "energy",
            "--param",
            "flight_kd=1:90:3",
        ],
        &["sweep point flight_kd_a_s_per_rad=90", "unstable"],
    );
}

#[test]
fn unknown_key_in_a_params_or_scenario_file() {
    let c = Case::new();
    let p = c.file("p.toml", "base = \"design\"\n\nbody_mas_kg = 9\n");
    c.fails(
        &["run", "--params", &p],
        &["p.toml:3", "unknown parameter `body_mas_kg`"],
    );
    let s = c.file(
        "s.toml",
        "duration_s = 1\n[controller]\nname = \"energy\"\nflight_kd = 1\n",
    );
    c.fails(
        &["run", "--scenario", &s],
        &["s.toml:4", "unknown key `controller.flight_kd`"],
    );
}

#[test]
fn unknown_cli_flag() {
    let c = Case::new();
    c.fails(
        &["run", "--flgiht-kd", "1"],
        &["unexpected argument '--flgiht-kd'", "'--flight-kd'"],
    );
    c.fails(&["run", "--duration", "long"], &["'long'", "--duration"]);
    // Help and version still print and succeed.
    for flag in ["--help", "--version"] {
        let o = Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
            .arg(flag)
            .output()
            .unwrap();
        assert!(o.status.success() && !o.stdout.is_empty(), "{flag}");
    }
}

#[test]
fn a_bound_file_that_is_not_finite_numbers_or_a_run_too_short_to_judge() {
    let c = Case::new();
    let inf = c.file("inf.csv", "apex_m,endurance_s\n0.05,inf\n");
    c.fails(
        &["endurance", "--bound", &inf],
        &["inf.csv:2", "not a finite, non-negative number"],
    );
    let headless = c.file("headless.csv", "0.05,104\n");
    c.fails(
        &["endurance", "--bound", &headless],
        &["headless.csv:1", "apex_m,endurance_s"],
    );
    c.fails(&["endurance", "--duration", "2"], &["8 to 3600 s", "got 2"]);
}

#[test]
fn an_unknown_motor() {
    let c = Case::new();
    c.fails(
        &["run", "--motor", "maxon80"],
        &["unknown motor `maxon80`", "re40", "pittman-14204"],
    );
    let s = c.file("s.toml", "duration_s = 1\nmotor = \"ec45\"\n");
    c.fails(
        &["run", "--scenario", &s],
        &["s.toml:2", "unknown motor `ec45`"],
    );
}

#[test]
fn the_design_motors_bound_is_not_drawn_for_another_motor() {
    let c = Case::new();
    let bound = c.file("bound.csv", "apex_m,endurance_s\n0.05,104\n");
    c.fails(
        &["endurance", "--motor", "re40", "--bound", &bound],
        &["'--motor <NAME>' cannot be used with '--bound <BOUND>'"],
    );
}
