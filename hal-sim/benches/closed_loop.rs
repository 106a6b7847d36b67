//! Closed-loop simulation speed: the plant (f64 RK4, 0.1 ms, event location),
//! the sensor/DAC/amplifier models and the firmware's control crate at
//! 10 kHz, i.e. what `hopper-sim run --json` does:
//!
//! ```sh
//! cargo bench -p hal-sim --bench closed_loop
//! ```
//!
//! Besides criterion's time per run it prints the speed in simulated seconds
//! per wall second (one core), hopping and at rest side by side. See `docs/performance.md`.
#![allow(missing_docs)]

use criterion::{BenchmarkId, Criterion};
use hal_sim::controller::{ControllerSpec, Passive, PlantDriver};
use hal_sim::run::{run, RunConfig};
use hal_sim::sim_io::SensorConfig;
use hal_sim::Params;
use std::hint::black_box;
use std::time::{Duration, Instant};

/// Simulated time per run, s.
const DURATION_S: f64 = 10.0;

/// `hopper-sim run --params design --controller energy-apex --start-apex 0.10
/// --duration 10 --json` (default noise, seed 1, no trajectory samples).
fn config() -> RunConfig {
    RunConfig {
        start_apex_m: 0.10,
        duration_s: DURATION_S,
        sample_dt_s: 0.0,
        ..RunConfig::new(Params::design())
    }
}

fn energy_apex_run(seed: u64) -> f64 {
    closed_loop(seed, None)
}

/// The same run with the e-stop pressed at 1 s: the amplifier disabled, the
/// hopper at rest from about 2.5 s (the case that ran at a quarter of the
/// speed while its states decayed through subnormal floats).
fn resting_run() -> f64 {
    closed_loop(1, Some("estop@1"))
}

fn closed_loop(seed: u64, inject: Option<&str>) -> f64 {
    let cfg = config();
    let mut spec = ControllerSpec {
        target_apex_m: 0.05,
        sensors: SensorConfig {
            seed,
            ..SensorConfig::DEFAULT
        },
        ..ControllerSpec::new("energy-apex")
    };
    if let Some(i) = inject {
        match hal_sim::inject::Injection::parse(i) {
            Ok(i) => spec.injections.push(i),
            Err(e) => panic!("{e}"),
        }
    }
    let Ok(mut ctl) = spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s) else {
        panic!("controller build failed");
    };
    match run(&cfg, "design", &mut ctl) {
        Ok(r) => r.summary.apex_heights_m.last().copied().unwrap_or(0.0),
        Err(e) => panic!("{e}"),
    }
}

/// The plant alone: passive hopping on the ideal plant (0 A, no sensors).
fn plant_only_run() -> f64 {
    let cfg = config();
    let mut ctl = Passive;
    let _ = ctl.name();
    match run(&cfg, "design", &mut ctl) {
        Ok(r) => r.summary.final_energy_j,
        Err(e) => panic!("{e}"),
    }
}

fn report(name: &str, f: &dyn Fn() -> f64) {
    // Best of a few batches: the least disturbed by other load on the machine.
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let n = 5;
        let t0 = Instant::now();
        for _ in 0..n {
            black_box(f());
        }
        best = best.min(t0.elapsed().as_secs_f64() / n as f64);
    }
    println!(
        "{name}: {:.2} ms per {DURATION_S} s run = {:.0} simulated s per wall s ({:.0} ns per 0.1 ms period)",
        best * 1e3,
        DURATION_S / best,
        best / (DURATION_S / 1e-4) * 1e9
    );
}

fn main() {
    let mut c = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5))
        .configure_from_args();
    {
        let mut g = c.benchmark_group("closed_loop_10s");
        g.bench_function(BenchmarkId::new("energy-apex", "design/0.10m"), |b| {
            b.iter(|| black_box(energy_apex_run(black_box(1))))
        });
        g.bench_function(
            BenchmarkId::new("energy-apex-at-rest", "design/0.10m/estop@1"),
            |b| b.iter(|| black_box(resting_run())),
        );
        g.bench_function(
            BenchmarkId::new("plant-only-passive", "design/0.10m"),
            |b| b.iter(|| black_box(plant_only_run())),
        );
        g.finish();
    }
    c.final_summary();
    // `cargo test --benches` runs this binary without `--bench`: skip the speed lines.
    if std::env::args().any(|a| a == "--bench") {
        report("energy-apex closed loop", &|| energy_apex_run(1));
        report("the same, at rest from 2.5 s (e-stop at 1 s)", &resting_run);
        report("plant only (passive, 0 A)", &plant_only_run);
    }
}
