//! Property tests of the closed loop (control crate + simulated hardware + plant):
//! over random laws, gains, targets and start heights, the current command
//! never leaves the configured range and the ball-screw stroke never leaves
//! its stops.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use hal_sim::controller::{ControllerSpec, PlantDriver, CONTROLLER_NAMES};
use hal_sim::{Params, Plant};
use hopper_control::hopper::{ApexLoop, Strategy};
use hopper_control::laws::{energy, flight_pd, open_torque, velocity, StanceLaw};
use hopper_control::pd_design::PdGains;
use proptest::prelude::*;

fn strategy_for(law: usize, gain: f32, torque: f32) -> Option<Strategy> {
    Some(match law {
        0 => Strategy::Thesis(StanceLaw::OpenTorque(open_torque::Config {
            torque_nm: torque,
        })),
        1 => Strategy::Thesis(StanceLaw::Energy(energy::Config {
            gain_nm_per_j: gain,
            allow_negative: true,
        })),
        2 => Strategy::Thesis(StanceLaw::Velocity(velocity::Config {
            gain_mps_per_j: gain * 0.1,
            ..velocity::Config::default()
        })),
        3 => Strategy::EnergyApex(ApexLoop {
            law: energy::Config {
                gain_nm_per_j: gain,
                allow_negative: gain > 2.0,
            },
            ..ApexLoop::default()
        }),
        _ => return None,
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn command_and_stroke_stay_in_range(
        name in 0..CONTROLLER_NAMES.len(),
        law in 0usize..6,
        gain in 0.0f32..5.0,
        torque in -2.0f32..2.0,
        target in 0.0f64..0.3,
        start in 0.005f64..0.3,
        kp in 0.0f32..200.0,
        kd in 0.0f32..5.0,
        identified in any::<bool>(),
        seed in any::<u64>(),
    ) {
        let params = if identified { Params::identified() } else { Params::design() };
        let mut spec = ControllerSpec::new(CONTROLLER_NAMES[name]);
        spec.target_apex_m = target;
        spec.sensors.seed = seed;
        spec.strategy_override = strategy_for(law, gain, torque);
        spec.flight_override = Some(flight_pd::Config {
            gains: PdGains { kp, kd },
            start_position_m: 0.0,
        });
        let mut ctl = spec.build(&params, start, 1e-4).unwrap();
        let mut plant = Plant::new(params, start).unwrap();
        let limit = params.current_limit_a;
        // Half a DAC code of rounding above the limit at most.
        let dac_quantum = 40.0 / 2048.0;
        for _ in 0..15_000 {
            let i = ctl.current_command_a(&plant);
            prop_assert!(ctl.hal.commanded_current_a().abs() <= limit + dac_quantum);
            prop_assert!(i.is_finite() && i.abs() <= limit + dac_quantum);
            plant.advance(1e-4, i, &mut |_| {}).unwrap();
            let p = plant.state().p_m;
            prop_assert!((0.0..=params.stroke_m).contains(&p), "p = {}", p);
            prop_assert!(plant.motor_current_a().abs() <= limit + 1e-9);
        }
    }
}
