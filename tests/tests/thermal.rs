//! The motor's thermal protection in closed loop
//! (`hopper_control::thermal`): the two overloads it guards against (a law
//! driving current while standing on the ground, the nut held on its stop)
//! trip when the model says they must, derating first and with 0 A after
//! the fault; hopping within the motor's thermal budget never derates; and
//! a load the derated limit can carry settles instead of tripping.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hal_sim::controller::ControllerSpec;
use hal_sim::run::{run, RunConfig, RunResult};
use hal_sim::Params;
use hopper_control::laws::ControllerKind;
use hopper_control::thermal::{MotorThermal, ThermalConfig};

fn sim(
    name: &str,
    params: Params,
    start: f64,
    target: f64,
    secs: f64,
    set: &[(&'static hopper_control::params::Param, f32)],
) -> RunResult {
    let mut cfg = RunConfig::new(params);
    cfg.start_apex_m = start;
    cfg.duration_s = secs;
    cfg.sample_dt_s = 1.0e-3;
    let spec = ControllerSpec {
        target_apex_m: target,
        params: set.to_vec(),
        ..ControllerSpec::new(name)
    };
    let mut c = spec.build(&params, start, cfg.control_dt_s).unwrap();
    run(&cfg, "test", &mut c).unwrap()
}

/// RMS motor current from the start to `until_s`, A (the plant's torque
/// over the torque constant).
fn rms_current_a(r: &RunResult, kt_nm_per_a: f64, until_s: f64) -> f64 {
    let i2: Vec<f64> = r
        .samples
        .iter()
        .filter(|s| s.t_s < until_s)
        .map(|s| (s.torque_nm / kt_nm_per_a).powi(2))
        .collect();
    (i2.iter().sum::<f64>() / i2.len() as f64).sqrt()
}

/// When the thermal model trips under a constant `current_a`, s.
fn model_trip_s(current_a: f64) -> f64 {
    let mut m = MotorThermal::new(ThermalConfig::default()).unwrap();
    let dt = 1.0e-3;
    let mut t = 0.0;
    while !m.tripped() && t < 600.0 {
        m.add(current_a as f32, dt as f32);
        t += dt;
    }
    t
}

/// The overload trips within 2% of the time the model gives for its RMS
/// current (the pulsed current heats the winding as its RMS does: the
/// winding's 41.6 s time constant averages it), derates before, and
/// commands 0 A from the fault on (`derates`: it derated first). Returns
/// (trip time, RMS current).
fn trips_as_the_model_says(r: &RunResult, kt: f64, derates: bool) -> (f64, f64) {
    let s = &r.summary;
    let trip = s
        .faults
        .iter()
        .find(|f| f.name == "overtemperature")
        .unwrap_or_else(|| panic!("no trip: {:?} {:?}", s.faults, s.thermal));
    assert_eq!(s.faults.len(), 1, "{:?}", s.faults);
    let rms = rms_current_a(r, kt, trip.time_s);
    let model = model_trip_s(rms);
    eprintln!(
        "overtemperature at {:.3} s, {rms:.2} A RMS until then, the model says {model:.3} s; derating from {:?} s",
        trip.time_s,
        s.thermal.and_then(|t| t.first_derated_s)
    );
    assert!(
        (trip.time_s - model).abs() <= 0.02 * model,
        "tripped at {} s with {rms:.2} A RMS; the model says {model:.2} s",
        trip.time_s
    );
    let th = s.thermal.unwrap();
    if derates {
        let derated = th.first_derated_s.unwrap();
        assert!(derated < trip.time_s, "{th:?}");
    }
    assert!((th.peak_winding_c - 150.0).abs() < 0.5, "{th:?}");
    assert_eq!(s.max_abs_current_after_fault_a, Some(0.0));
    (trip.time_s, rms)
}

#[test]
fn standing_on_the_ground_trips_within_the_models_time() {
    // The first overload: energy-apex standing on the ground (toe 1 mm up at
    // the start) drives about 32 A RMS without hopping.
    let p = Params::design();
    let r = sim("energy-apex", p, 0.001, 0.05, 12.0, &[]);
    let (t, rms) = trips_as_the_model_says(&r, p.torque_constant_nm_per_a, true);
    assert!((30.5..33.7).contains(&rms), "{rms} A RMS");
    assert!((7.0..8.6).contains(&t), "{t} s");
}

#[test]
fn nut_held_on_its_stop_derates_and_without_derating_trips_within_the_models_time() {
    // The second overload: modified torque on the identified machine
    // holds the nut on its stop at about 20.9 A from 2.25 s. The derating
    // brings it down to what the winding carries, just under the trip.
    let p = Params::identified();
    let r = sim("modified-torque", p, 0.15, 0.05, 40.0, &[]);
    let s = &r.summary;
    let th = s.thermal.unwrap();
    assert!(s.faults.is_empty(), "{:?}", s.faults);
    assert!(
        (17.5..19.5).contains(&th.first_derated_s.unwrap()),
        "{th:?}"
    );
    assert!(
        th.peak_winding_c > 145.0 && th.peak_winding_c < 150.0,
        "{th:?}"
    );
    // Without the derating (the limit stays the amplifier's), it trips.
    let full = [(&hopper_control::params::THERMAL_DERATED_FRACTION, 1.0)];
    let r = sim("modified-torque", p, 0.15, 0.05, 40.0, &full);
    let (t, rms) = trips_as_the_model_says(&r, p.torque_constant_nm_per_a, false);
    assert!((18.0..21.5).contains(&rms), "{rms} A RMS");
    assert!((18.0..30.0).contains(&t), "{t} s");
}

#[test]
fn hopping_within_the_thermal_budget_never_derates() {
    // Every law on the design machine, 8 s from a 5 cm drop toward the
    // thesis's 15 cm: the shortest time to derating is 8.4 s (energy-apex
    // and modified-torque; docs/safety.md has the table).
    for &kind in ControllerKind::ALL {
        if kind == ControllerKind::Passive {
            continue;
        }
        let r = sim(kind.name(), Params::design(), 0.05, 0.15, 8.0, &[]);
        let s = &r.summary;
        let th = s.thermal.unwrap();
        assert!(s.faults.is_empty(), "{kind}: {:?}", s.faults);
        assert_eq!(th.first_derated_s, None, "{kind}: {th:?}");
        assert!(
            th.peak_winding_c > 60.0 && th.peak_winding_c < 135.0,
            "{kind}: {th:?}"
        );
    }
}

#[test]
fn a_load_the_derated_limit_carries_settles_without_a_trip() {
    // Energy-apex on the identified machine (which does not hop) derates
    // from about 18.6 s and then holds just under the trip temperature.
    let r = sim("energy-apex", Params::identified(), 0.05, 0.05, 60.0, &[]);
    let s = &r.summary;
    let th = s.thermal.unwrap();
    assert!(s.faults.is_empty(), "{:?}", s.faults);
    let derated = th.first_derated_s.unwrap();
    assert!((17.5..19.5).contains(&derated), "{th:?}");
    assert!(
        th.peak_winding_c > 145.0 && th.peak_winding_c < 150.0,
        "{th:?}"
    );
}

#[test]
fn copper_loss_is_booked_hop_by_hop_and_split_between_stance_and_flight() {
    // Shaped holding 5 cm on the design machine, 10 s.
    let r = sim("shaped", Params::design(), 0.05, 0.05, 10.0, &[]);
    let s = &r.summary;
    let hops = &s.hop_ledger;
    // The hops are consecutive: together they are the run's copper loss
    // up to the last apex.
    let booked: f64 = hops.iter().map(|h| h.copper_loss_j).sum();
    let after_last_apex = s.ledger.copper_loss_j - booked;
    assert!(
        (0.0..60.0).contains(&after_last_apex),
        "{booked} of {} J",
        s.ledger.copper_loss_j
    );
    for h in hops {
        let split = h.stance_copper_loss_j + h.flight_copper_loss_j;
        assert!(
            (split - h.copper_loss_j).abs() < 1e-9 * h.copper_loss_j.max(1.0),
            "{h:?}"
        );
    }
    // The firmware books each hop's copper too (commanded current, its own
    // apex), and agrees with the plant's books hop by hop.
    let fw = &s.firmware_hops;
    assert_eq!(fw.len(), hops.len());
    for (f, h) in fw.iter().zip(hops) {
        let ratio = f64::from(f.copper_loss_j) / h.copper_loss_j;
        assert!((0.97..1.03).contains(&ratio), "{f:?} {h:?}");
        let ratio = f64::from(f.stance_copper_loss_j) / h.stance_copper_loss_j;
        assert!((0.97..1.03).contains(&ratio), "{f:?} {h:?}");
    }
    let fw_total: f64 = fw.iter().map(|f| f64::from(f.copper_loss_j)).sum();
    assert!(
        (fw_total / booked - 1.0).abs() < 0.01,
        "{fw_total} {booked}"
    );
    // A steady hop: 34 times the motor's net work (1.84 J) leaves as heat, more of
    // it in flight (returning the nut) than in stance.
    let h = s.steady_hop.unwrap();
    let within = |got: f64, want: f64| (got - want).abs() < 0.05 * want;
    assert!(within(h.copper_loss_j, 62.5), "{h:?}");
    assert!(within(h.stance_copper_loss_j, 23.1), "{h:?}");
    assert!(within(h.flight_copper_loss_j, 39.4), "{h:?}");
    assert!(within(h.rms_current_a, 23.4), "{h:?}");
    // That current has no steady temperature: the winding heats on.
    let th = s.thermal.unwrap();
    assert_eq!(th.steady_winding_c, None);
    assert!(!th.indefinite);
}

#[test]
fn the_heat_aware_shaped_hops_at_5_cm_more_than_twice_as_long() {
    use hopper_control::params as p;
    let heat_aware = hal_sim::endurance::heat_aware_settings();
    // Time to the derating, RMS current over the hops from 5 to 10 s and
    // `int i^2 dt` per hop from 3 to 8 s (the endurance table's hops).
    let endurance = |set: &[(&'static p::Param, f32)], secs: f64| {
        let r = sim("shaped", Params::design(), 0.05, 0.05, secs, set);
        let s = r.summary;
        // It holds the apex while it can: every apex from 5 to 10 s within
        // 2 % of the target.
        let held = s
            .hop_ledger
            .iter()
            .filter(|h| (5.0..10.0).contains(&h.apex_time_s))
            .all(|h| (h.apex_m - 0.05).abs() < 0.001);
        assert!(held, "{:?}", s.apex_heights_m);
        let a2s = |from: f64, to: f64| {
            let hops: Vec<_> = s
                .hop_ledger
                .iter()
                .filter(|h| (from..to).contains(&h.apex_time_s))
                .collect();
            let t_s: f64 = hops.iter().map(|h| h.duration_s).sum();
            let a2s: f64 = hops
                .iter()
                .map(|h| h.rms_current_a.powi(2) * h.duration_s)
                .sum();
            (a2s, t_s, hops.len() as f64)
        };
        let (a2s_5_10, t_s, _) = a2s(5.0, 10.0);
        let (a2s_3_8, _, n) = a2s(3.0, 8.0);
        (
            s.thermal.unwrap().endurance_s.unwrap(),
            (a2s_5_10 / t_s).sqrt(),
            a2s_3_8 / n,
        )
    };
    let (before, before_rms, _) = endurance(&[], 20.0);
    let (after, after_rms, per_hop) = endurance(&heat_aware, 65.0);
    // 23.4 and 13.3 A RMS; the least-heat hop at 5 cm (tests/heat_bound.rs
    // in hal-sim) is 12.07 A, 43.61 A^2 s per 0.30 s hop, and the
    // heat-aware mode's 53.0 is within 25 % of it.
    assert!((before_rms - 23.4).abs() < 0.05 * 23.4, "{before_rms} A");
    assert!((after_rms - 13.3).abs() < 0.05 * 13.3, "{after_rms} A");
    assert!(after_rms > 12.07);
    assert!((per_hop - 53.0).abs() < 0.05 * 53.0, "{per_hop} A^2 s");
    assert!(per_hop < 1.25 * 43.61, "{per_hop} A^2 s per hop");
    assert!((before - 13.92).abs() < 0.05 * 13.92, "{before} s");
    assert!((after - 58.5).abs() < 0.05 * 58.5, "{after} s");
    assert!(after > 2.0 * before, "{after} s against {before} s");
}
