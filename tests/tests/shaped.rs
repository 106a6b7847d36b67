//! The `shaped` controller in the closed loop: the firmware's
//! control crate on the simulated hardware (quantisation, default noise, amplifier
//! lag) against the plant. Convergence to the thesis's 0.15 m (70 J) apex,
//! no stop impacts, robustness to a 20 % error between the controller's
//! model and the plant, and the per-hop energy ledger's bookkeeping.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hal_sim::controller::ControllerSpec;
use hal_sim::run::{run, RunConfig, Summary};
use hal_sim::Params;
use hopper_control::laws::ControllerKind;
use sil_tests::{snapshot_text, CliRun, NO_THERMAL_LIMIT};

const TARGET_M: f64 = 0.15;

fn sim(name: &str, plant: Params, model: Option<Params>, start: f64, secs: f64) -> Summary {
    let mut cfg = RunConfig::new(plant);
    cfg.start_apex_m = start;
    cfg.duration_s = secs;
    cfg.sample_dt_s = 0.0;
    // The motor's thermal protection off: these runs study the law for
    // 15 s, past the 11.7 s from which it derates at 0.15 m.
    let spec = ControllerSpec {
        target_apex_m: TARGET_M,
        model,
        params: NO_THERMAL_LIMIT.to_vec(),
        ..ControllerSpec::new(name)
    };
    let mut c = sil_tests::firmware(&spec, &plant, start, cfg.control_dt_s).unwrap();
    run(&cfg, "test", &mut *c).unwrap().summary
}

/// The last `n` apexes all within 2 % of the target.
fn holds_target(s: &Summary, n: usize) -> bool {
    let a = &s.apex_heights_m;
    a.len() >= n
        && a[a.len() - n..]
            .iter()
            .all(|h| (h - TARGET_M).abs() <= 0.02 * TARGET_M)
}

/// Canonical run (b): `hopper-sim run --params design --controller shaped
/// --start-apex 0.05 --target-apex 0.15 --duration 15 --json`, the README's
/// run to the thesis's target. One simulation feeds the bands and the
/// snapshot, which pins every figure of the JSON.
#[test]
fn shaped_reaches_and_holds_the_thesis_target_without_stop_impacts() {
    let s = CliRun {
        params: Some("design"),
        controller: Some(ControllerKind::Shaped),
        start_apex_m: Some(0.05),
        target_apex_m: Some(TARGET_M),
        duration_s: Some(15.0),
        // Protection on, shaped derates from 11.7 s at 0.15 m and trips
        // at 15.1 s (tests/thermal.rs).
        set: &NO_THERMAL_LIMIT,
    }
    .run()
    .unwrap();
    assert!(holds_target(&s, 10), "{:?}", s.apex_heights_m);
    let htc = s.hops_to_converge.unwrap();
    // 9 with the design preset (no preload, predicted contact); the
    // requirement is at most 10.
    assert!(htc <= 10, "converged at hop {htc}");
    assert!(s.faults.is_empty(), "{:?}", s.faults);
    // Within the actuator's limits: current limit, stroke.
    let p = Params::design();
    assert!(s.max_current_a <= p.current_limit_a + 1e-9);
    assert!(s.max_stroke_m < p.stroke_m - 0.01, "{}", s.max_stroke_m);
    // The braking-curve back-drive lands the nut at creep speed: under
    // 0.1 J of stop impacts per hop, against several J for the thesis laws
    // (below).
    let steady = s.steady_hop.unwrap();
    assert!(steady.stop_impact_loss_j < 0.1, "{steady:?}");
    // A tripwire for docs/beat-the-thesis.md: the best one-hop schedule the
    // example `one_hop_bound` finds, with the plant's exact state, rises
    // 0.0220 m at most (0.0127 m with the old 5 mm preload). A closed-loop
    // hop rising more (the release's 0.05 m counted, so hop 1 too) would
    // mean that the plant changed or that the search missed better
    // schedules. The climb rises at most 0.0162 m.
    let apexes: Vec<f64> = std::iter::once(0.05)
        .chain(s.apex_heights_m.iter().copied())
        .collect();
    let rise = apexes
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(rise <= 0.0220 + 2e-4, "a hop rose {rise} m: {apexes:?}");
    insta::assert_snapshot!("shaped_design", snapshot_text(&s).unwrap());
}

#[test]
fn thesis_laws_lose_their_energy_in_stop_impacts() {
    // Same start and target: the thesis's modified torque (full torque,
    // eq 4.13 flight PD) throws several J per hop into the upper stop.
    let s = sim("modified-torque", Params::design(), None, 0.05, 4.0);
    let h = s.steady_hop.unwrap();
    assert!(h.stop_impact_loss_j > 5.0, "{h:?}");
    assert!(h.stop_impact_loss_j > 0.5 * h.motor_work_j, "{h:?}");
}

#[test]
fn shaped_is_robust_to_twenty_percent_model_error() {
    let d = Params::design();
    let scaled = |f: fn(&mut Params, f64), x: f64| {
        let mut p = d;
        f(&mut p, x);
        p
    };
    // (plant, controller's model): the model's k and M off by 20 % either
    // way, and the plant's friction off by 20 % from the model's.
    let cases = [
        (
            "k model -20%",
            d,
            scaled(|p, x| p.spring_stiffness_n_per_m *= x, 0.8),
        ),
        (
            "k model +20%",
            d,
            scaled(|p, x| p.spring_stiffness_n_per_m *= x, 1.2),
        ),
        ("M model -20%", d, scaled(|p, x| p.body_mass_kg *= x, 0.8)),
        ("M model +20%", d, scaled(|p, x| p.body_mass_kg *= x, 1.2)),
        (
            "friction plant -20%",
            scaled(
                |p, x| {
                    p.planarizer_friction_n *= x;
                    p.leg_friction_n *= x;
                },
                0.8,
            ),
            d,
        ),
        (
            "friction plant +20%",
            scaled(
                |p, x| {
                    p.planarizer_friction_n *= x;
                    p.leg_friction_n *= x;
                },
                1.2,
            ),
            d,
        ),
    ];
    for (name, plant, model) in cases {
        let s = sim("shaped", plant, Some(model), 0.05, 15.0);
        assert!(holds_target(&s, 5), "{name}: {:?}", s.apex_heights_m);
        // 9-18 hops (18: the model's M +20 %).
        let htc = s.hops_to_converge.unwrap_or(usize::MAX);
        assert!(htc <= 20, "{name}: converged at hop {htc}");
        assert!(s.faults.is_empty(), "{name}: {:?}", s.faults);
        let h = s.steady_hop.unwrap();
        assert!(h.stop_impact_loss_j < 0.1, "{name}: {h:?}");
    }
}

#[test]
fn hop_ledger_balances_the_plant_energy_hop_by_hop() {
    for name in ["shaped", "modified-torque", "open-torque"] {
        let s = sim(name, Params::design(), None, 0.05, 3.0);
        assert!(s.hop_ledger.len() >= 5, "{name}");
        // From the release (the plant's initial energy) to every apex.
        let mut energy_before_j = s.initial_energy_j;
        let mut t_before_s = 0.0;
        for b in &s.hop_ledger {
            let losses = b.friction_j
                + b.touchdown_loss_j
                + b.liftoff_loss_j
                + b.stop_impact_loss_j
                + b.settle_loss_j;
            let balance = b.total_energy_j - energy_before_j - (b.motor_work_j - losses);
            assert!(balance.abs() < 1e-3, "{name}: {balance} J at {b:?}");
            assert!(b.apex_time_s > t_before_s);
            (energy_before_j, t_before_s) = (b.total_energy_j, b.apex_time_s);
        }
        // The hops add up to the run's ledger up to the last apex.
        let stops: f64 = s.hop_ledger.iter().map(|h| h.stop_impact_loss_j).sum();
        assert!(stops <= s.ledger.stop_impact_loss_j + 1e-9, "{name}");
        // Every apex the summary lists has its ledger entry.
        assert_eq!(s.hop_ledger.len(), s.apex_heights_m.len(), "{name}");
    }
}

#[test]
fn shaped_leaves_the_nut_alone_once_hopping_dies() {
    // The identified plant cannot keep hopping under any law here; once it
    // stands on its extended leg (which the estimator reads as a flight of
    // zero height) the spin-up must not pump the nut into its stops. It did
    // before `spin_up_min_apex_m`: 13 J of stop impacts and the nut on the
    // lower stop (50 mm) in 30 s.
    let p = Params::identified();
    let s = sim("shaped", p, None, 0.15, 30.0);
    assert!(s.stopped_at_s.is_some(), "{:?}", s.apex_heights_m);
    assert!(s.faults.is_empty(), "{:?}", s.faults);
    assert!(s.ledger.stop_impact_loss_j < 1.0, "{:?}", s.ledger);
    assert!(s.max_stroke_m < 0.03, "{}", s.max_stroke_m);
}
