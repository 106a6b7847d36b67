//! The least copper loss per hop that holds an apex, and the longest
//! endurance it allows with the stand-in motor (`hal_sim::heat_bound`;
//! docs/endurance.md has the table this prints).
//!
//! ```sh
//! cargo run --release -p hal-sim --example heat_bound [PARAMS] [H1,H2,...]
//! ```
//!
//! `PARAMS`: `design` (default) or `identified`. `SEG` (levels per phase,
//! default 8), `RUNS` (independent searches, default 4) and `GENERATIONS`
//! (default 8,000: about a minute per apex on 2 cores) from the
//! environment. It prints each apex's best closed
//! hop and its schedule (levels as fractions of the current limit), which
//! `tests/heat_bound.rs` replays.
#![allow(missing_docs)]

use hal_sim::heat_bound::{endurance_s, fly_watched, search};
use hal_sim::Params;
use hopper_control::thermal::ThermalConfig;

fn env(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .filter(|&n| n > 0)
        .unwrap_or(default)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map_or("design", String::as_str);
    let Some(p) = Params::preset(name) else {
        panic!("unknown preset {name}: design or identified")
    };
    let heights: Vec<f64> = args
        .get(2)
        .map(|s| s.split(',').filter_map(|h| h.parse().ok()).collect())
        .unwrap_or_else(|| vec![0.03, 0.05, 0.08, 0.10, 0.15]);
    let (seg, runs, generations) = (env("SEG", 8), env("RUNS", 4), env("GENERATIONS", 8000));
    let thermal = ThermalConfig::default();
    println!(
        "least int i^2 dt per hop holding an apex ({name} parameters, {seg} levels per phase, best of {runs} searches of {generations} generations)"
    );
    println!("| apex | i^2 t per hop | hop | RMS | copper per hop at 25 C / 135 C | motor work | stop impacts | steady winding | endurance (to 135 C) | searches (A^2 s) |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for &h in &heights {
        let b = search(&p, h, seg, runs as u64, generations);
        let spread: Vec<String> = b.runs_a2s.iter().map(|v| format!("{v:.2}")).collect();
        let (Some(o), Some(plan)) = (b.outcome, b.plan) else {
            println!(
                "| {h:.2} m | none closed | | | | | | | | {} |",
                spread.join(", ")
            );
            continue;
        };
        let rms = o.rms_current_a();
        let r = |t: f32| f64::from(thermal.resistance_at_ohm(t));
        let steady = thermal.steady_winding_c((rms * rms) as f32);
        let endurance = match endurance_s(&thermal, rms) {
            None => "indefinitely".to_string(),
            Some(t) => format!("{t:.0} s"),
        };
        println!(
            "| {h:.2} m | {:.2} A^2 s | {:.3} s | {rms:.2} A | {:.2} / {:.2} J | {:.2} J | {:.2} J | {} | {endurance} | {} |",
            o.current_squared_a2s,
            o.duration_s,
            o.current_squared_a2s * r(25.0),
            o.current_squared_a2s * r(135.0),
            o.motor_work_j,
            o.stop_impact_j,
            steady.map_or("none (runaway)".to_string(), |t| format!("{t:.0} C")),
            spread.join(", ")
        );
        let levels: Vec<String> = plan.levels.iter().map(|v| format!("{v}")).collect();
        if std::env::var_os("TRACE").is_some() {
            let mut k = 0;
            let _ = fly_watched(&p, h, &plan, &mut |pl, cmd| {
                k += 1;
                if k % 50 == 0 {
                    let s = pl.state();
                    eprintln!(
                        "  t {:.3} s {:8} toe {:+.4} m  p {:+.2} mm  pd {:+.3} m/s  i {:+.1} A",
                        pl.time_s(),
                        pl.mode().name(),
                        pl.toe_height_m(),
                        1e3 * s.p_m,
                        s.pd_mps,
                        cmd
                    );
                }
            });
        }
        eprintln!(
            "apex {h}: nut {} m, {} m/s; levels [{}]",
            plan.nut_m,
            plan.nut_mps,
            levels.join(", ")
        );
    }
}
