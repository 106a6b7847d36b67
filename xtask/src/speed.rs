//! `cargo xtask speed` (part of `cargo xtask test`): how fast the release
//! simulator runs on this machine, hopping and at rest, side by side: the
//! wall time of `hopper-sim run --json` over 64 simulated seconds, the two
//! cases alternated, best of three. Prints `speed: hopping=Nx at_rest=Mx
//! ratio=R`. A figure, not a test (times on a shared machine are not
//! asserted; `hal-sim/tests/resting_speed.rs` asserts the ratio); below
//! the 400x the simulator is held to it says so on a line of its own.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

/// Simulated seconds per run.
const DURATION_S: f64 = 64.0;

/// The common part of both runs: energy-apex on the design machine,
/// dropped from 0.10 m, holding 0.05 m.
const BASE: [&str; 10] = [
    "run",
    "--params",
    "design",
    "--controller",
    "energy-apex",
    "--start-apex",
    "0.10",
    "--target-apex",
    "0.05",
    "--json",
];

/// Wall seconds of one run with `extra` arguments.
fn time(sim: &Path, extra: &[&str]) -> Result<f64, String> {
    let started = Instant::now();
    let status = Command::new(sim)
        .args(BASE)
        .args(["--duration", &DURATION_S.to_string()])
        .args(extra)
        .stdout(Stdio::null())
        .status()
        .map_err(|e| format!("cannot start hopper-sim: {e}"))?;
    if !status.success() {
        return Err(format!("hopper-sim {}: {status}", extra.join(" ")));
    }
    Ok(started.elapsed().as_secs_f64())
}

/// `cargo xtask speed`.
pub fn run(root: &Path) -> Result<(), String> {
    let sim = crate::release_sim(root, "hopper-sim release build")?;
    eprintln!("xtask: speed");
    let started = Instant::now();
    let (mut hop, mut rest) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..3 {
        // Hopping throughout (no thermal limit); at rest from 2.5 s (the
        // e-stop pressed at 1 s, the amplifier disabled).
        hop = hop.min(time(&sim, &["--set", "thermal.protect=0"])?);
        rest = rest.min(time(&sim, &["--inject", "estop@1"])?);
    }
    crate::took("speed", started);
    let (h, r) = (DURATION_S / hop, DURATION_S / rest);
    println!(
        "speed: hopping={h:.0}x at_rest={r:.0}x ratio={:.2} (one core, {DURATION_S} s simulated, best of 3)",
        rest / hop
    );
    if h < 400.0 || r < 400.0 {
        println!("speed: below the 400x real time the simulator is held to (docs/performance.md); on a loaded machine, measure again");
    }
    Ok(())
}
