//! The design tools of issue 19 on the command line: `hopper-sim spring`.

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
