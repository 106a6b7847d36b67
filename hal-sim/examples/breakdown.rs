//! Where the closed loop's time goes, hopping and at rest, side by side in
//! one run: two 10 s `energy-apex` runs (design parameters, 0.10 m drop,
//! default noise, 10 kHz), one hopping throughout, one with the e-stop
//! pressed at 1 s (the amplifier disabled; the hopper at rest from about
//! 2.5 s), each timed as a whole, then its parts replayed on their own from
//! what the whole run recorded:
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

/// The two runs: hopping, and the e-stop pressed at 1 s.
#[derive(Clone, Copy)]
enum Case {
    Hopping,
    Resting,
}

fn controller(cfg: &RunConfig, case: Case) -> FirmwareController {
    let mut spec = ControllerSpec {
        target_apex_m: 0.05,
        sensors: SensorConfig::DEFAULT,
        ..ControllerSpec::new("energy-apex")
    };
    if let Case::Resting = case {
        match hal_sim::inject::Injection::parse("estop@1") {
            Ok(i) => spec.injections.push(i),
            Err(e) => panic!("{e}"),
        }
    }
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

/// ns per period of: the whole run, the bare loop, the plant, the sensor
/// models, the control step, the amplifier, the bookkeeping, the floor.
fn measure(case: Case) -> [f64; 8] {
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
        let mut ctl = controller(&cfg, case);
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
        let mut ctl = controller(&cfg, case);
        match run(&cfg, "design", &mut ctl) {
            Ok(r) => {
                black_box(r.summary.hops);
            }
            Err(e) => panic!("{e}"),
        }
    });
    let loop_only = best(|| {
        let mut ctl = controller(&cfg, case);
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
        let mut hal = controller(&cfg, case).hal;
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
        let mut ctl = controller(&cfg, case);
        let h = ctl.hopper_mut();
        for raw in &raws {
            black_box(h.step(Some(black_box(raw)), DT_S as f32));
        }
    });
    let amplifier = best(|| {
        let mut hal = controller(&cfg, case).hal;
        for _ in 0..steps {
            black_box(hal.mean_current_a(black_box(DT_S)));
        }
    });

    let ns = |t: f64| t / steps as f64 * 1e9;
    [
        ns(whole),
        ns(loop_only),
        ns(plant_only),
        ns(plant_and_sensors - plant_only),
        ns(control_only),
        ns(amplifier),
        ns(whole - loop_only),
        // The two parts no closed-loop run can skip: the plant's
        // integration and the firmware's own control step (the code the
        // board runs, unchanged). Even if the sensor and amplifier models
        // and the bookkeeping cost nothing, a run cannot be faster than
        // these two replayed back to back.
        ns(plant_only + control_only),
    ]
}

fn main() {
    // Alternated, so that both cases see the same load on the machine.
    let (mut hop, mut rest) = ([f64::INFINITY; 8], [f64::INFINITY; 8]);
    for _ in 0..3 {
        for (case, best) in [(Case::Hopping, &mut hop), (Case::Resting, &mut rest)] {
            for (b, v) in best.iter_mut().zip(measure(case)) {
                *b = b.min(v);
            }
        }
    }
    let periods = (DURATION_S / DT_S).round();
    println!(
        "10 s energy-apex runs, design, 0.10 m drop, default noise, 10 kHz ({periods} periods); ns per period, best of {}",
        3 * REPEATS
    );
    println!("  {:<46} {:>9} {:>9}", "", "hopping", "at rest");
    let rows = [
        "run() as hopper-sim --json",
        "bare closed loop",
        "plant.advance alone",
        "sensor sampling (SimHal::sample)",
        "Hopper::step alone",
        "amplifier (mean_current_a)",
        "run() bookkeeping (residual, peaks, events)",
        "floor (plant + Hopper::step, nothing else)",
    ];
    for (k, name) in rows.iter().enumerate() {
        println!("  {name:<46} {:>9.1} {:>9.1}", hop[k], rest[k]);
    }
    let x = |ns: f64| DT_S * 1e9 / ns;
    println!(
        "  real time (whole run):                         {:>8.0}x {:>8.0}x",
        x(hop[0]),
        x(rest[0])
    );
    println!(
        "  at rest / hopping, whole run: {:.2}; floor at most {:.0}x real time hopping (2,000x needs {:.0} ns)",
        rest[0] / hop[0],
        x(hop[7]),
        DT_S / 2000.0 * 1e9
    );
}
