//! The least-heat hop at 5 cm (docs/endurance.md): the schedule
//! `examples/heat_bound.rs` found, replayed on the plant, closes its orbit
//! and spends the documented `int i^2 dt`; and a controller's hop costs
//! more than it (the bound bounds).

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hal_sim::heat_bound::{endurance_s, fly, HopPlan};
use hal_sim::Params;
use hopper_control::thermal::ThermalConfig;

/// `cargo run --release -p hal-sim --example heat_bound design 0.05`
/// (8 levels per phase, 4 searches of 8,000 generations), as it printed it.
fn least_heat_hop_at_5_cm() -> HopPlan {
    HopPlan {
        levels: vec![
            -0.13687700917723128,
            -0.1321930689966379,
            -0.09350159959926115,
            -0.04059847826817245,
            -0.01623133819356608,
            0.4891185050449366,
            0.5338434464239751,
            0.5959905028283362,
            0.6205247571968915,
            0.5861191279282377,
            0.5442141303075351,
            0.33486014008049997,
            0.1656290057581735,
            -0.09570123626764247,
            -0.2769007487263406,
            -0.3639993939774471,
            -0.40576101903302353,
            -0.3782758179706214,
            -0.3610390720393056,
            -0.32803302146631513,
            -0.2890113357612794,
            -0.27306679250874566,
            -0.24963369625291654,
            -0.18731816390362627,
        ],
        nut_m: 0.005606360461829963,
        nut_mps: -0.07366103617469538,
    }
}

#[test]
fn the_least_heat_hop_at_5_cm_closes_and_costs_what_the_docs_say() {
    let p = Params::design();
    let plan = least_heat_hop_at_5_cm();
    let o = fly(&p, 0.05, &plan).unwrap();
    assert!(o.miss(0.05, &plan) <= 1.0, "{o:?}");
    assert!((o.current_squared_a2s - 43.61).abs() < 0.01, "{o:?}");
    assert!((o.rms_current_a() - 12.07).abs() < 0.01, "{o:?}");
    // Above the 11.4 A RMS of thermal runaway with the stand-in motor: no
    // steady temperature, so no controller hops 5 cm for ever with it; at
    // best about 104 s to the derating.
    let t = ThermalConfig::default();
    assert_eq!(t.steady_winding_c((o.rms_current_a().powi(2)) as f32), None);
    let best_s = endurance_s(&t, o.rms_current_a()).unwrap();
    assert!((best_s - 104.0).abs() < 1.0, "{best_s} s");
}

#[test]
fn a_current_the_motor_sheds_hops_indefinitely() {
    // 6 A RMS settles at 123 C, under the 135 C derating.
    let t = ThermalConfig::default();
    assert_eq!(endurance_s(&t, 6.0), None);
    assert!(endurance_s(&t, 6.5).is_some());
}
