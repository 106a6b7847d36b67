//! Tuning runs of the `shaped` law: one closed-loop run (firmware on the
//! simulated sensors, default noise) with the law's constants from the
//! command line, printing the apex sequence and the summary.
//!
//! `cargo run --release -p hal-sim --example shaped_tune -- PLANT KI KP SPIN SWITCH BRAKE TARGET START SECONDS MARGIN TRACK_S CURRENT_LIMIT_A INITIAL_LEVEL INTEGRAL_START`
//! with PLANT 0 (design) or 1 (identified); omitted values take the defaults.
use hal_sim::controller::ControllerSpec;
use hal_sim::run::{run, RunConfig};
use hal_sim::sim_io::SensorConfig;
use hal_sim::Params;
use hopper_control::hopper::Strategy;
use hopper_control::laws::shaped;

fn main() -> Result<(), String> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let get = |i: usize, d: f64| a.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let plant = if get(0, 0.0) == 1.0 {
        Params::identified()
    } else {
        Params::design()
    };
    let mut plant = plant;
    if let Some(i) = a.get(11).and_then(|s| s.parse::<f64>().ok()) {
        plant.current_limit_a = i;
    }
    let mut c = shaped::Config::default();
    c.level_gain_per_j = get(1, c.level_gain_per_j as f64) as f32;
    c.level_proportional_per_j = get(2, c.level_proportional_per_j as f64) as f32;
    c.spin_up_fraction = get(3, c.spin_up_fraction as f64) as f32;
    c.switch_fraction = get(4, c.switch_fraction as f64) as f32;
    c.brake_fraction = get(5, c.brake_fraction as f64) as f32;
    c.braking_margin = get(9, c.braking_margin as f64) as f32;
    c.tracking_time_s = get(10, c.tracking_time_s as f64) as f32;
    c.initial_level = get(12, c.initial_level as f64) as f32;
    c.integral_start = get(13, c.integral_start as f64) as f32;
    let target = get(6, 0.15);
    let start = get(7, 0.05);
    let dur = get(8, 15.0);
    let mut spec = ControllerSpec::new("shaped");
    spec.strategy_override = Some(Strategy::Shaped(c));
    spec.target_apex_m = target;
    spec.sensors = SensorConfig::DEFAULT;
    let cfg = RunConfig {
        start_apex_m: start,
        duration_s: dur,
        sample_dt_s: 0.0,
        ..RunConfig::new(plant)
    };
    let mut ctl = spec.build(&plant, start, cfg.control_dt_s)?;
    let r = run(&cfg, "x", &mut ctl)?;
    let s = &r.summary;
    let ap: Vec<f64> = s
        .apex_heights_m
        .iter()
        .map(|x| (x * 1000.0).round() / 1000.0)
        .collect();
    println!("{:?}", &ap[..ap.len().min(40)]);
    println!(
        "steady {:?} conv {:?} hops {} W {:.1} stop {:.2} faults {} Imax {:.1} stroke {:.4}",
        s.steady_apex_m,
        s.hops_to_converge,
        s.hops,
        s.ledger.motor_work_j,
        s.ledger.stop_impact_loss_j,
        s.faults.len(),
        s.max_current_a,
        s.max_stroke_m
    );
    Ok(())
}
