//! System-level checks of the simulated hopper against what the thesis
//! reports for passive hopping (sections 4.4.1 and 4.5.1), through the same
//! runner `hopper-sim run` uses.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hal_sim::run::Summary;
use hal_sim::{Event, Params};
use sil_tests::{snapshot_text, CliRun};
use std::sync::OnceLock;

fn energy_at_events(params: Params, start: f64, duration: f64) -> Vec<(&'static str, f64, f64)> {
    // (event, time, total energy right after the control step holding it)
    let mut plant = hal_sim::Plant::new(params, start).unwrap();
    let mut out = Vec::new();
    let steps = (duration / 1e-4) as usize;
    for _ in 0..steps {
        let mut seen = None;
        plant
            .advance(1e-4, 0.0, &mut |e| {
                seen = match e {
                    Event::Touchdown { .. } => Some("td"),
                    Event::Liftoff { .. } => Some("lo"),
                    _ => seen,
                }
            })
            .unwrap();
        if let Some(kind) = seen {
            out.push((kind, plant.time_s(), plant.energy_j()));
        }
    }
    out
}

/// Canonical run (c): `hopper-sim run --params identified --start-apex 0.15
/// --json` (passive, 5 s), the README's first run: the firmware's passive
/// strategy on the simulated sensors, as the command runs it. Simulated once
/// per test binary; the tests below share it.
fn identified_passive() -> &'static Summary {
    static RUN: OnceLock<Summary> = OnceLock::new();
    RUN.get_or_init(|| {
        CliRun {
            params: Some("identified"),
            start_apex_m: Some(0.15),
            ..CliRun::default()
        }
        .run()
        .unwrap()
    })
}

#[test]
fn identified_passive_hopper_stops_within_a_few_seconds() {
    let s = identified_passive();
    assert_eq!(s.controller, "passive");
    // Thesis Fig 4.7: stationary after about 1.5 s; this plant stops at
    // 1.015 s from 0.15 m. Pinned within 5% so that friction or contact
    // that moves the decay by more fails here, not only in the snapshot.
    let stopped = s.stopped_at_s.unwrap();
    assert!(
        (1.015_f64 * 0.95..1.015 * 1.05).contains(&stopped),
        "stopped at {stopped} s"
    );
    assert!(s.apex_heights_m.windows(2).all(|w| w[1] < w[0]));
    // ~100 ms stance (section 4.4.2).
    let stance = s.stance_time_s.unwrap();
    assert!((0.09..0.115).contains(&stance), "{stance}");
    assert!(s.energy_residual_j.abs() < 1e-6);
    assert_eq!(s.ledger.motor_work_j, 0.0);
    assert!(s.faults.is_empty(), "{:?}", s.faults);
}

/// The snapshot of canonical run (c) pins every figure of its JSON.
#[test]
fn identified_passive_run_matches_its_snapshot() {
    insta::assert_snapshot!(
        "passive_identified",
        snapshot_text(identified_passive()).unwrap()
    );
}

#[test]
fn identified_friction_costs_joules_per_phase_like_the_thesis() {
    // Thesis 4.4.1: about 4 J lost in the first stance and about 4 J in the
    // first flight (its own drop height is not given; 0.15 m here). The
    // identified plant loses 3.48 J and 2.37 J from 0.15 m: pinned within
    // 5%, so a change to the friction model that moves either fails.
    let ev = energy_at_events(Params::identified(), 0.15, 1.0);
    let td1 = ev.iter().find(|e| e.0 == "td").unwrap();
    let lo1 = ev.iter().find(|e| e.0 == "lo").unwrap();
    let td2 = ev.iter().filter(|e| e.0 == "td").nth(1).unwrap();
    let stance_loss = td1.2 - lo1.2;
    let flight_loss = lo1.2 - td2.2;
    assert!(
        (3.48 * 0.95..3.48 * 1.05).contains(&stance_loss),
        "first stance lost {stance_loss} J"
    );
    assert!(
        (2.365 * 0.95..2.365 * 1.05).contains(&flight_loss),
        "first flight lost {flight_loss} J"
    );
}

#[test]
fn design_friction_decays_slower_than_identified() {
    // The design plant, otherwise as canonical run (c).
    let d = CliRun {
        params: Some("design"),
        start_apex_m: Some(0.15),
        ..CliRun::default()
    }
    .run()
    .unwrap();
    let i = identified_passive();
    assert!(d.hops > i.hops, "{} vs {}", d.hops, i.hops);
    assert!(d.apex_heights_m[0] > i.apex_heights_m[0]);
}
