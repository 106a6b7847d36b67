//! Where the closed loop's time goes: a 10 s `energy-apex` run (design
//! parameters, 0.10 m drop, default noise, 10 kHz) timed as a whole, then its
//! parts replayed on their own from what the whole run recorded:
//!
//! * the plant alone (`Plant::advance` with the recorded current commands:
//!   the same trajectory, bit for bit);
//! * the sensor models (`SimHal::sample` on that replayed plant);
//! * the control crate alone (`Hopper::step` on the recorded raw samples);
//! * the amplifier model (`SimHal::mean_current_a`).
//!
//! ```sh
//! cargo run --release -p hal-sim --example breakdown
//! ```
#![allow(missing_docs)]

use hal_sim::controller::{ControllerSpec, FirmwareController, PlantDriver};
use hal_sim::run::{run, RunConfig};
use hal_sim::sim_io::SensorConfig;
use hal_sim::{Params, Plant};
use hopper_control::hal::RawSample;
use std::hint::black_box;
use std::time::Instant;

const DURATION_S: f64 = 10.0;
const DT_S: f64 = 1e-4;
const REPEATS: usize = 7;

fn controller(cfg: &RunConfig) -> FirmwareController {
    let spec = ControllerSpec {
        target_apex_m: 0.05,
        sensors: SensorConfig::DEFAULT,
        ..ControllerSpec::new("energy-apex")
    };
    match spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s) {
        Ok(c) => c,
        Err(e) => panic!("{e}"),
    }
}

fn plant(cfg: &RunConfig) -> Plant {
    match Plant::new(cfg.params, cfg.start_apex_m) {
        Ok(p) => p,
        Err(e) => panic!("{e}"),
    }
}

/// Best wall time of `REPEATS` calls, s.
fn best(mut f: impl FnMut()) -> f64 {
    (0..REPEATS)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let cfg = RunConfig {
        start_apex_m: 0.10,
        duration_s: DURATION_S,
        control_dt_s: DT_S,
        sample_dt_s: 0.0,
        ..RunConfig::new(Params::design())
    };
    let steps = (DURATION_S / DT_S).round() as usize;

    // Record the commands and raw samples of one closed-loop run.
    let mut commands = Vec::with_capacity(steps);
    let mut raws: Vec<RawSample> = Vec::with_capacity(steps);
    {
        let mut ctl = controller(&cfg);
        let mut p = plant(&cfg);
        for _ in 0..steps {
            raws.push(ctl.hal.clone().sample(&p));
            let cmd = ctl.current_command_a(&p);
            commands.push(cmd);
            if let Err(e) = p.advance(DT_S, cmd, &mut |_| {}) {
                panic!("{e}");
            }
        }
    }

    let whole = best(|| {
        let mut ctl = controller(&cfg);
        match run(&cfg, "design", &mut ctl) {
            Ok(r) => {
                black_box(r.summary.hops);
            }
            Err(e) => panic!("{e}"),
        }
    });
    let loop_only = best(|| {
        let mut ctl = controller(&cfg);
        let mut p = plant(&cfg);
        for _ in 0..steps {
            let cmd = ctl.current_command_a(&p);
            if let Err(e) = p.advance(DT_S, cmd, &mut |e| {
                black_box(e);
            }) {
                panic!("{e}");
            }
        }
        black_box(p.time_s());
    });
    let plant_only = best(|| {
        let mut p = plant(&cfg);
        for &cmd in &commands {
            if let Err(e) = p.advance(DT_S, cmd, &mut |e| {
                black_box(e);
            }) {
                panic!("{e}");
            }
        }
        black_box(p.time_s());
    });
    let plant_and_sensors = best(|| {
        let mut hal = controller(&cfg).hal;
        let mut p = plant(&cfg);
        for &cmd in &commands {
            black_box(hal.sample(&p));
            if let Err(e) = p.advance(DT_S, cmd, &mut |e| {
                black_box(e);
            }) {
                panic!("{e}");
            }
        }
        black_box(p.time_s());
    });
    let control_only = best(|| {
        let mut ctl = controller(&cfg);
        let h = ctl.hopper_mut();
        for raw in &raws {
            black_box(h.step(Some(black_box(raw)), DT_S as f32));
        }
    });
    let amplifier = best(|| {
        let mut hal = controller(&cfg).hal;
        for _ in 0..steps {
            black_box(hal.mean_current_a(black_box(DT_S)));
        }
    });

    let ns = |t: f64| t / steps as f64 * 1e9;
    println!("10 s energy-apex run, design, 0.10 m drop, default noise, 10 kHz ({steps} periods); best of {REPEATS}");
    println!(
        "  run() as hopper-sim --json: {:7.2} ms  {:6.1} ns/period  {:6.0}x real time",
        whole * 1e3,
        ns(whole),
        DURATION_S / whole
    );
    println!(
        "  bare closed loop:           {:7.2} ms  {:6.1} ns/period",
        loop_only * 1e3,
        ns(loop_only)
    );
    println!(
        "  plant.advance alone:        {:7.2} ms  {:6.1} ns/period",
        plant_only * 1e3,
        ns(plant_only)
    );
    println!(
        "  sensor sampling (SimHal::sample): {:6.1} ns/period",
        ns(plant_and_sensors - plant_only)
    );
    println!(
        "  Hopper::step alone:         {:7.2} ms  {:6.1} ns/period",
        control_only * 1e3,
        ns(control_only)
    );
    println!(
        "  amplifier (mean_current_a): {:7.2} ms  {:6.1} ns/period",
        amplifier * 1e3,
        ns(amplifier)
    );
    println!(
        "  run() bookkeeping (residual, peaks, events): {:6.1} ns/period",
        ns(whole - loop_only)
    );
    // The two parts no closed-loop run can skip: the plant's integration and
    // the firmware's own control step (the code the board runs, unchanged).
    // Even if the sensor and amplifier models and the bookkeeping cost
    // nothing, a run cannot be faster than these two replayed back to back.
    let floor = plant_only + control_only;
    println!(
        "  floor (plant + Hopper::step, nothing else): {:6.1} ns/period: at most {:.0}x real time (2,000x needs {:.0} ns)",
        ns(floor),
        DURATION_S / floor,
        DT_S / 2000.0 * 1e9
    );
}
