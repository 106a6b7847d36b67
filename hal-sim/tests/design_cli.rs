//! The design tools on the command line: `hopper-sim spring`,
//! `hopper-sim sweep --shard` and `sweep merge`, `hopper-sim design`.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::process::{Command, Output};

fn sim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
        .args(args)
        .output()
        .expect("run hopper-sim")
}

/// The thesis's worked example by default, with the shaped controller's
/// 0.15 m hop on a spring of its whole coils' rate: the loads within what
/// it allows, the peak force that of 67 mm of deflection.
#[test]
fn spring_json_has_the_worked_example_and_the_hop_check() {
    let out = sim(&["spring", "--json", "--check-hop", "0.15"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let d = &v["design"];
    assert_eq!(d["active_coils"], 10);
    assert_eq!(d["total_coils"], 12);
    let pitch = d["pitch_m"].as_f64().unwrap();
    assert!((pitch - 0.0224).abs() < 5e-5, "{pitch}");
    let h = &v["hop_check"];
    assert_eq!(h["within"], true, "{h}");
    let peak = h["peak_spring_force_n"].as_f64().unwrap();
    assert!((peak - 625.0).abs() < 0.05 * 625.0, "{h}");
    let apex = h["steady_apex_m"].as_f64().unwrap();
    assert!((apex - 0.15).abs() < 0.02 * 0.15, "{h}");
}

/// A wire too thick for the coil: one error line naming the problem.
#[test]
fn spring_refuses_an_impossible_coil() {
    let out = sim(&["spring", "--wire-mm", "40"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("spring index"), "{err}");
    assert!(out.stdout.is_empty());
}

const GRID: [&str; 10] = [
    "--params",
    "identified",
    "--controller",
    "open-torque",
    "--param",
    "k=8000:20000:5",
    "--param",
    "torque=0.4:1.0:3",
    "--duration",
    "1",
];

fn sweep(extra: &[&str]) -> Output {
    let mut args = vec!["sweep"];
    args.extend_from_slice(&GRID);
    args.extend_from_slice(extra);
    let o = sim(&args);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// A 15-run grid in three shards, merged in another order: the same
/// sweep.csv, sweep.svg and sweep.png, byte for byte, as the unsharded run.
#[test]
fn sharded_and_merged_is_the_unsharded_sweep() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    sweep(&["--out", &p("whole")]);
    for k in 1..=3 {
        let o = sweep(&[
            "--shard",
            &format!("{k}/3"),
            "--out",
            &p(&format!("part{k}")),
        ]);
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            text.contains(&format!("shard {k}/3: 5 of 15 runs")),
            "{text}"
        );
    }
    let o = sim(&[
        "sweep",
        "merge",
        &p("part3"),
        &p("part1"),
        &p("part2"),
        "--out",
        &p("merged"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["sweep.csv", "sweep.svg", "sweep.png"] {
        let a = std::fs::read(dir.path().join("whole").join(f)).unwrap();
        let b = std::fs::read(dir.path().join("merged").join(f)).unwrap();
        assert!(a == b, "{f} differs");
    }
    // The first shard of another grid (1.5 s runs).
    let mut args = vec!["sweep"];
    args.extend_from_slice(&GRID[..9]);
    args.extend_from_slice(&["1.5", "--shard", "1/3", "--out"]);
    let other = p("other");
    args.push(&other);
    assert!(sim(&args).status.success());
    // One part missing, one twice, a part of another grid, or no part at
    // all: refused, nothing written.
    for (parts, needle) in [
        (
            vec![p("other"), p("part2"), p("part3")],
            "a slice of another sweep",
        ),
        (
            vec![p("part1"), p("part2")],
            "1 of 3 shards missing: 3 (give every sweep-part directory",
        ),
        (vec![p("part1"), p("part1"), p("part2")], "given twice"),
        (
            vec![p("part1"), p("whole")],
            "not a `hopper-sim sweep --shard` output",
        ),
    ] {
        let mut args = vec!["sweep".to_string(), "merge".to_string()];
        args.extend(parts);
        args.extend(["--out".to_string(), p("bad")]);
        let o = sim(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert_eq!(o.status.code(), Some(2));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(needle), "{err}");
        assert!(!dir.path().join("bad").exists());
    }
    let mut args = vec!["sweep"];
    args.extend_from_slice(&GRID);
    args.extend_from_slice(&["--shard", "4/3", "--out", "unused"]);
    let o = sim(&args);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("1 <= K <= N"));
}

/// `design motors --json`: Table 3.1's four rows and the two catalogue
/// motors; `design leads --out`: the nine leads and both plots.
#[test]
fn design_motors_and_leads() {
    let out = sim(&["design", "motors", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = v["table_3_1"].as_array().unwrap();
    assert_eq!(rows.len(), 4);
    let e: Vec<f64> = rows
        .iter()
        .map(|r| r["first_stance"]["motor_work_j"].as_f64().unwrap())
        .collect();
    assert!((e[2] / 25.67 - 1.0).abs() < 0.02, "{e:?}");
    assert!(e[0] < e[1] && e[1] < e[2], "{e:?}");
    assert_eq!(v["catalogue"].as_array().unwrap().len(), 2);
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().join("leads");
    let out = sim(&["design", "leads", "--json", "--out", d.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v.as_array().unwrap().len(), 9);
    for f in ["lead-study.png", "lead-study.svg"] {
        assert!(std::fs::metadata(d.join(f)).unwrap().len() > 1000, "{f}");
    }
}

/// Section 4.5 on simulated logs (default sensor noise, the identified
/// machine): from a passive drop the frictions come back from the design
/// preset's 5 N and 5 N to within 5% of 13 N and 15 N; then, with those,
/// an open-torque hop's effective stance torque (0.62 N m, as
/// current_limit_a = 20.87 A) within 5%, from 26.9 A (the design's 33.67 A
/// capped where it binds the 1 N m command).
#[test]
fn identify_recovers_the_frictions_and_the_stance_torque() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    for (name, controller, duration) in [
        ("passive", "passive", "2"),
        ("torque", "open-torque", "1.5"),
    ] {
        let o = sim(&[
            "run",
            "--params",
            "identified",
            "--controller",
            controller,
            "--start-apex",
            "0.15",
            "--duration",
            duration,
            "--out",
            &p(name),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let out = sim(&[
        "identify",
        "--log",
        &p("passive"),
        "--params",
        "design",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let fp = v["planarizer_friction_n"].as_f64().unwrap();
    let fl = v["leg_friction_n"].as_f64().unwrap();
    eprintln!("passive: {v}");
    assert!((fp / 13.0 - 1.0).abs() < 0.05, "planarizer {fp}");
    assert!((fl / 15.0 - 1.0).abs() < 0.05, "leg {fl}");
    let toml = dir.path().join("known.toml");
    std::fs::write(
        &toml,
        format!("base = \"design\"\nplanarizer_friction_n = {fp}\nleg_friction_n = {fl}\n"),
    )
    .unwrap();
    let out = sim(&[
        "identify",
        "--log",
        &p("torque"),
        "--experiment",
        "open-torque",
        "--params",
        toml.to_str().unwrap(),
        "--json",
        "--out",
        &p("plot"),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    eprintln!("open-torque: {v}");
    let t = v["stance_torque_nm"].as_f64().unwrap();
    assert!((t / 0.62 - 1.0).abs() < 0.05, "stance torque {t}");
    assert!(dir.path().join("plot").join("identify.png").is_file());
}

/// `planar run --json`: 2 m/s passive for 5 s keeps its apexes
/// within 2 cm of the design's; 4 m/s passive falls within 5 s.
#[test]
fn planar_run_json() {
    let run = |args: &[&str]| -> serde_json::Value {
        let mut a = vec!["planar", "run", "--json", "--duration", "5"];
        a.extend_from_slice(args);
        let o = sim(&a);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let v = run(&["--speed", "2"]);
    assert_eq!(v["fell"], false, "{v}");
    assert!(v["apex_drift_m"].as_f64().unwrap() < 0.02, "{v}");
    assert!(v["touchdowns"].as_u64().unwrap() >= 9, "{v}");
    let v = run(&["--speed", "4"]);
    assert_eq!(v["fell"], true, "{v}");
    let o = sim(&["planar", "run", "--speed", "-1"]);
    assert_eq!(o.status.code(), Some(2));
}

/// `planar stability --json`: the 4 m/s fixed points, passive
/// and with K_c = 1000, their growth per hop (5.51 and 1.230), and
/// `planar run --start fixed-point` holding the stabilised gait for 30 s
/// (the design's apex falls within 10 s) with the stabiliser's force at
/// 9.3% of the leg's; bad lists are refused.
#[test]
fn planar_stability_json() {
    let o = sim(&[
        "planar",
        "stability",
        "--speeds",
        "4",
        "--kc",
        "0,1000",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let row = &v["speeds"][0];
    let growth = |k: usize| row["points"][k]["growth"].as_f64().unwrap();
    assert!((growth(0) / 5.510 - 1.0).abs() < 0.02, "{row}");
    assert!((growth(1) / 1.230 - 1.0).abs() < 0.02, "{row}");
    assert_eq!(row["best_gain_ns_per_m"], 1000.0);
    assert!(row["attracts_ns_per_m"].is_null());
    // Negative gains as typed: at 2 m/s -500 lowers the growth (1.134
    // against 1.168).
    let o = sim(&[
        "planar",
        "stability",
        "--speeds",
        "2",
        "--kc",
        "-500,0",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["speeds"][0]["best_gain_ns_per_m"], -500.0, "{v}");
    let run = |start: &str| -> serde_json::Value {
        let o = sim(&[
            "planar",
            "run",
            "--speed",
            "4",
            "--kc",
            "1000",
            "--duration",
            "30",
            "--start",
            start,
            "--json",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let fixed = run("fixed-point");
    assert_eq!(fixed["fell"], false, "{fixed}");
    assert!(fixed["apex_drift_m"].as_f64().unwrap() < 1e-3, "{fixed}");
    // The thesis's choice of K_c: its force below a tenth of the largest
    // ground force; on the fixed point 184 N against 1975 N.
    let ratio = fixed["max_stabiliser_force_n"].as_f64().unwrap()
        / fixed["max_leg_force_n"].as_f64().unwrap();
    assert!((ratio / 0.0932 - 1.0).abs() < 0.03, "{ratio}");
    assert_eq!(run("design")["fell"], true);
    for (bad, names) in [
        (&["planar", "stability", "--speeds", "0"][..], "--speeds 0"),
        (&["planar", "stability", "--kc", "NaN"][..], "--kc NaN"),
        (&["planar", "run", "--start", "apex"][..], "'--start"),
    ] {
        let o = sim(bad);
        assert_eq!(o.status.code(), Some(2), "{bad:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(names), "{err}");
    }
}

/// `planar run --model appendix-a`: with no Appendix A terms it
/// gives the section 2.2 runner's apexes (1e-9 m); a 0.5 kg toe mass
/// makes the touchdowns and the liftoffs' pick-up take energy; terms are
/// refused by their flag out of range or without the model.
#[test]
fn planar_run_appendix_a() {
    let run = |args: &[&str]| -> serde_json::Value {
        let mut a = vec!["planar", "run", "--json", "--duration", "3"];
        a.extend_from_slice(args);
        let o = sim(&a);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let simple = run(&[]);
    let general = run(&["--model", "appendix-a"]);
    assert_eq!(general["model"], "appendix-a");
    assert_eq!(simple["model"], "section-2-2");
    let (a, b) = (
        simple["apex_heights_m"].as_array().unwrap(),
        general["apex_heights_m"].as_array().unwrap(),
    );
    assert_eq!(a.len(), b.len());
    assert!(a.len() >= 5);
    for (x, y) in a.iter().zip(b) {
        assert!(
            (x.as_f64().unwrap() - y.as_f64().unwrap()).abs() < 1e-9,
            "{a:?} {b:?}"
        );
    }
    // The toe mass's impacts: 6.66 J at the two touchdowns, 4.09 J at the
    // pick-ups, before it falls (the design assumes no toe mass).
    let toe = run(&["--model", "appendix-a", "--toe-mass", "0.5"]);
    let near = |k: &str, v: f64| (toe[k].as_f64().unwrap() / v - 1.0).abs() < 0.02;
    assert!(near("touchdown_loss_j", 6.656), "{toe}");
    assert!(near("liftoff_loss_j", 4.094), "{toe}");
    assert_eq!(toe["fell"], true);
    for (bad, says) in [
        (&["--toe-mass", "1"][..], "--toe-mass is an Appendix A term"),
        (
            &["--model", "appendix-a", "--leg-com", "0.9"][..],
            "--leg-com 0.9 must be within 0 ..= 0.65 m",
        ),
        (
            &["--model", "appendix-a", "--hip-friction=-1"][..],
            "--hip-friction -1 must be within 0 ..= 1 N m",
        ),
        (
            &["--model", "appendix-a", "--trunk-offset-x", "2"][..],
            "--trunk-offset-x 2 must be within -1 ..= 1 m",
        ),
        (
            &["--model", "appendix-a", "--start", "fixed-point"][..],
            "--start fixed-point",
        ),
    ] {
        let mut a = vec!["planar", "run"];
        a.extend_from_slice(bad);
        let o = sim(&a);
        assert_eq!(o.status.code(), Some(2), "{bad:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(says), "{err}");
    }
}

/// `planar run --out DIR`: trajectory.csv every millisecond (1 s: 1001
/// rows after the header) with the hip, the angles, their rates, the leg
/// and the phase, and run.png.
#[test]
fn planar_run_writes_its_trajectory() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = sim(&[
        "planar",
        "run",
        "--duration",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("t_s,x_m,z_m,phi_rad,theta_rad,x_dot_mps,z_dot_mps,phi_dot_rad_s,theta_dot_rad_s,leg_length_m,stance")
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 1001);
    // Two stances in the first second (0.5 s steps), the leg shorter in them.
    let stance: Vec<&Vec<f64>> = rows.iter().filter(|r| r[10] == 1.0).collect();
    assert!((100..=140).contains(&stance.len()), "{}", stance.len());
    assert!(stance.iter().all(|r| r[9] <= 0.65 + 1e-12));
    assert!((rows[1000][0] - 1.0).abs() < 1e-9);
    assert!(out.join("run.png").is_file() && out.join("run.svg").is_file());
}

/// `planar run --controller raibert` drives the leg by default as on the
/// vertical hopper, through its ball screw under the energy-apex law (the
/// JSON's `leg` says so); `--thrust force` is Raibert's own thrust (no
/// `leg`); `--thrust` without raibert, or an unknown law, is refused.
#[test]
fn planar_raibert_drives_the_leg_through_its_screw_by_default() {
    let run = |extra: &[&str]| -> serde_json::Value {
        let mut a = vec![
            "planar",
            "run",
            "--controller",
            "raibert",
            "--duration",
            "5",
            "--json",
        ];
        a.extend_from_slice(extra);
        let o = sim(&a);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let default = run(&[]);
    assert_eq!(default["leg"]["law"], "energy-apex", "{default}");
    assert!(default["leg"]["motor_work_j"].as_f64().unwrap() > 0.0);
    assert_eq!(run(&["--thrust", "energy-apex"]), default);
    let force = run(&["--thrust", "force"]);
    assert!(force["leg"].is_null(), "{force}");
    for bad in [
        &["planar", "run", "--thrust", "force"][..],
        &[
            "planar",
            "run",
            "--controller",
            "raibert",
            "--thrust",
            "jump",
        ][..],
    ] {
        let o = sim(bad);
        assert!(!o.status.success(), "{bad:?}");
        assert!(
            String::from_utf8_lossy(&o.stderr).contains("--thrust"),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
}
