//! Physics invariants of the plant model (MODEL.md / thesis ch. 2.1).

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hal_sim::{Event, Mode, NutStop, Params, Plant, State};
use proptest::prelude::*;

const DT: f64 = 1e-4;

fn frictionless(mut p: Params) -> Params {
    p.planarizer_friction_n = 0.0;
    p.leg_friction_n = 0.0;
    p.spring_damping_ns_per_m = 0.0;
    p
}

/// Run with a command schedule, checking `check` after every control step.
fn simulate(
    plant: &mut Plant,
    duration_s: f64,
    mut cmd: impl FnMut(f64) -> f64,
    mut check: impl FnMut(&Plant),
) -> Vec<Event> {
    let mut events = Vec::new();
    let steps = (duration_s / DT).round() as usize;
    for _ in 0..steps {
        let c = cmd(plant.time_s());
        plant.advance(DT, c, &mut |e| events.push(e)).unwrap();
        check(plant);
    }
    events
}

#[test]
fn energy_is_conserved_without_friction_damping_impacts_or_torque() {
    let mut p = frictionless(Params::design());
    // A microgram lower leg: touchdown and liftoff impacts cost ~1e-9 J per
    // hop, far below the tolerance (a massless one is refused as input).
    p.unsprung_mass_kg = 1e-9;
    let mut plant = Plant::new(p, 0.15).unwrap();
    let e0 = plant.energy_j();
    let mut worst: f64 = 0.0;
    let events = simulate(
        &mut plant,
        10.0,
        |_| 0.0,
        |pl| {
            worst = worst.max(((pl.energy_j() - e0) / e0).abs());
        },
    );
    let hops = events
        .iter()
        .filter(|e| matches!(e, Event::Touchdown { .. }))
        .count();
    assert!(hops >= 20, "expected sustained hopping, got {hops} hops");
    assert!(worst < 1e-6, "relative energy drift {worst:e}");
    // Every apex returns to the start height.
    for e in &events {
        if let Event::Apex { toe_height_m, .. } = e {
            assert!((toe_height_m - 0.15).abs() < 1e-6, "apex {toe_height_m}");
        }
    }
}

#[test]
fn ledger_closes_with_the_nut_moving_under_torque() {
    // Constant torque balancing the spring near mid-stroke: the nut moves in
    // every phase; motor work in and out must match the energy change.
    let mut p = frictionless(Params::design());
    p.unsprung_mass_kg = 1e-9;
    let r = p.screw_m_per_rad();
    let torque = 0.25;
    let cmd = torque / p.torque_constant_nm_per_a;
    let p_eq = p.efficiency * torque / r / p.spring_stiffness_n_per_m - p.spring_preload_m;
    let z0 = p.leg_length_m + 0.1;
    let state = State {
        z_m: z0,
        zd_mps: 0.0,
        p_m: p_eq,
        pd_mps: 0.0,
    };
    let mut plant = Plant::with_state(p, Mode::Flight, state).unwrap();
    let e0 = plant.energy_j();
    let mut worst: f64 = 0.0;
    let mut moved: f64 = 0.0;
    let mut work: f64 = 0.0;
    let events = simulate(
        &mut plant,
        10.0,
        |_| cmd,
        |pl| {
            worst = worst.max(pl.energy_residual_j().abs() / e0);
            moved = moved.max((pl.state().p_m - p_eq).abs());
            work = work.max(pl.ledger().motor_work_j.abs());
        },
    );
    assert!(
        !events.iter().any(|e| matches!(e, Event::StopImpact { .. })),
        "nut hit a stop"
    );
    assert!(moved > 1e-3, "nut should move, moved {moved}");
    assert!(work > 0.1, "motor work swing {work} J");
    assert!(worst < 1e-6, "relative ledger residual {worst:e}");
}

#[test]
fn touchdown_loses_half_mu_v_squared_at_the_exact_time() {
    let p = frictionless(Params::design());
    let h = 0.15;
    let mut plant = Plant::new(p, h).unwrap();
    let events = simulate(&mut plant, 0.3, |_| 0.0, |_| {});
    let (t, zd, loss) = events
        .iter()
        .find_map(|e| match *e {
            Event::Touchdown {
                t_s,
                zd_mps,
                loss_j,
            } => Some((t_s, zd_mps, loss_j)),
            _ => None,
        })
        .unwrap();
    let g = p.gravity_mps2;
    assert!((t - (2.0 * h / g).sqrt()).abs() < 1e-9, "touchdown at {t}");
    assert!(
        (zd + (2.0 * g * h).sqrt()).abs() < 1e-9,
        "touchdown speed {zd}"
    );
    let expected = 0.5 * p.unsprung_mass_kg * zd * zd;
    assert!((loss - expected).abs() < 1e-12);
    assert!((plant.ledger().touchdown_loss_j - expected).abs() < 1e-12);
}

#[test]
fn liftoff_conserves_momentum_and_loses_the_pickup_energy() {
    // A preload keeps the nut pressed on its stop through liftoff, so it is
    // at rest there as eq 2.40 assumes; with none the spring force, and so
    // the stop's, is zero at liftoff and the nut may creep off the stop at
    // 1e-4 m/s, which changes the momentum balance by 2e-5 kg m/s.
    let p = Params {
        spring_preload_m: 0.005,
        ..frictionless(Params::design())
    };
    let mut plant = Plant::new(p, 0.2).unwrap();
    let events = simulate(&mut plant, 0.6, |_| 0.0, |_| {});
    let (before, after, loss) = events
        .iter()
        .find_map(|e| match *e {
            Event::Liftoff {
                zd_before_mps,
                zd_after_mps,
                loss_j,
                ..
            } => Some((zd_before_mps, zd_after_mps, loss_j)),
            _ => None,
        })
        .unwrap();
    let m_bs = p.body_mass_kg + p.nut_mass_kg;
    let m_t = m_bs + p.unsprung_mass_kg;
    // eq 2.39-2.41: (M + m_s) zd- = m_t zd+ with the nut at rest.
    assert!(
        (m_bs * before - m_t * after).abs() < 1e-12,
        "{before} {after}"
    );
    // MODEL.md erratum: the loss is 0.5 (M+m_s) m_u / m_t zd^2, not 75 mJ.
    let expected = 0.5 * m_bs * p.unsprung_mass_kg / m_t * before * before;
    assert!((loss - expected).abs() < 1e-9, "{loss} vs {expected}");
    let at_2mps = 0.5 * m_bs * p.unsprung_mass_kg / m_t * 4.0;
    assert!((at_2mps - 1.13).abs() < 0.01);
}

fn stance_times(events: &[Event]) -> Vec<f64> {
    let mut out = Vec::new();
    let mut td = None;
    for e in events {
        match *e {
            Event::Touchdown { t_s, .. } => td = Some(t_s),
            Event::Liftoff { t_s, .. } => {
                if let Some(t0) = td.take() {
                    out.push(t_s - t0);
                }
            }
            _ => {}
        }
    }
    out
}

#[test]
fn stance_with_held_actuator_is_the_spring_mass_half_period() {
    // With the preload equal to the weight, the static equilibrium is at
    // touchdown and stance lasts exactly half a period of sqrt(k / (M+m_s)).
    let mut p = frictionless(Params::design());
    let m = p.body_mass_kg + p.nut_mass_kg;
    p.spring_preload_m = m * p.gravity_mps2 / p.spring_stiffness_n_per_m;
    let mut plant = Plant::new(p, 0.15).unwrap();
    let events = simulate(
        &mut plant,
        1.0,
        |_| 0.0,
        |pl| assert_eq!(pl.nut_stop(), NutStop::Top),
    );
    let half = std::f64::consts::PI * (m / p.spring_stiffness_n_per_m).sqrt();
    let ts = stance_times(&events);
    assert!(ts.len() >= 2);
    for t in ts {
        assert!(
            ((t - half) / half).abs() < 0.02,
            "stance {t} vs half period {half}"
        );
    }
}

#[test]
fn stance_time_matches_the_gravity_offset_spring_mass_solution() {
    // Default preload: equilibrium x0 below touchdown, so stance lasts
    // (pi + 2 atan(w x0 / v)) / w, a few % more than the half period.
    let p = frictionless(Params::design());
    let m = p.body_mass_kg + p.nut_mass_kg;
    let k = p.spring_stiffness_n_per_m;
    let w = (k / m).sqrt();
    let h = 0.15;
    let v = (2.0 * p.gravity_mps2 * h).sqrt();
    let x0 = m * p.gravity_mps2 / k - p.spring_preload_m;
    let analytic = (std::f64::consts::PI + 2.0 * (w * x0 / v).atan()) / w;
    let mut plant = Plant::new(p, h).unwrap();
    let events = simulate(&mut plant, 0.5, |_| 0.0, |_| {});
    let t = stance_times(&events)[0];
    assert!(
        ((t - analytic) / analytic).abs() < 1e-6,
        "stance {t} vs {analytic}"
    );
    // The thesis's ~100 ms stance.
    assert!((0.09..0.11).contains(&t), "{t}");
}

#[test]
fn friction_only_decay_is_monotonic_and_stops() {
    let p = Params::identified();
    let mut plant = Plant::new(p, 0.15).unwrap();
    let mut last_e = plant.energy_j();
    let events = simulate(
        &mut plant,
        4.0,
        |_| 0.0,
        |pl| {
            let e = pl.energy_j();
            assert!(
                e <= last_e + 1e-9,
                "energy rose from {last_e} to {e} at {}",
                pl.time_s()
            );
            last_e = e;
        },
    );
    let apexes: Vec<f64> = events
        .iter()
        .filter_map(|e| match *e {
            Event::Apex { toe_height_m, .. } => Some(toe_height_m),
            _ => None,
        })
        .collect();
    assert!(apexes.len() >= 2);
    assert!(apexes.windows(2).all(|w| w[1] < w[0]), "{apexes:?}");
    assert!(apexes[0] < 0.15);
    assert_ne!(plant.mode(), Mode::Flight);
    assert!(plant.state().zd_mps.abs() < 1e-9 || plant.body_stuck());
    assert!(plant.energy_residual_j().abs() < 1e-6);
}

#[test]
fn motor_torque_falls_with_back_emf() {
    // At the no-load speed the amplifier can drive no more forward current.
    let p = Params::design();
    let r = p.screw_m_per_rad();
    let w0 = p.no_load_speed_rad_s();
    let state = State {
        z_m: p.leg_length_m + 0.5,
        zd_mps: 0.0,
        p_m: 0.02,
        pd_mps: w0 * r,
    };
    let mut plant = Plant::with_state(p, Mode::Flight, state).unwrap();
    plant.advance(1e-9, 1000.0, &mut |_| {}).unwrap();
    assert!(
        plant.motor_torque_nm().abs() < 1e-3,
        "{}",
        plant.motor_torque_nm()
    );
    let mut still = Plant::new(p, 0.5).unwrap();
    still.advance(1e-9, 1000.0, &mut |_| {}).unwrap();
    assert!((still.motor_torque_nm() - p.max_torque_nm()).abs() < 1e-9);
}

#[test]
fn full_torque_stance_never_reaches_nominal_speed() {
    // Thesis section 4.4.2: in a ~100 ms stance the motor stays far below its
    // speed range. Full torque from touchdown to liftoff, PD-free flight.
    let p = Params::design();
    let mut plant = Plant::new(p, 0.15).unwrap();
    let mut peak: f64 = 0.0;
    let mut stance_s = 0.0;
    let mut lifted = false;
    while !lifted {
        let cmd = if plant.mode() == Mode::Stance {
            p.current_limit_a
        } else {
            0.0
        };
        plant
            .advance(DT, cmd, &mut |e| {
                lifted |= matches!(e, Event::Liftoff { .. })
            })
            .unwrap();
        if plant.mode() == Mode::Stance {
            stance_s += DT;
        }
        peak = peak.max(plant.motor_speed_rad_s().abs());
    }
    assert!((0.05..0.15).contains(&stance_s), "stance {stance_s} s");
    assert!(peak > 10.0, "motor should move, peak {peak} rad/s");
    assert!(peak < 0.5 * p.no_load_speed_rad_s(), "peak {peak} rad/s");
}

#[test]
fn standing_mode_ends_hopping_without_zeno_chatter() {
    // Full torque drives the nut onto its lower stop; the stiff preloaded leg
    // then holds the body up at full extension once the hops die out.
    let p = Params::design();
    let mut plant = Plant::new(p, 0.05).unwrap();
    let cmd = p.current_limit_a;
    let events = simulate(
        &mut plant,
        20.0,
        |_| cmd,
        |pl| {
            assert!(pl.state().p_m >= 0.0 && pl.state().p_m <= p.stroke_m);
        },
    );
    assert_eq!(plant.mode(), Mode::Standing);
    assert_eq!(plant.nut_stop(), NutStop::Bottom);
    assert!(events.iter().any(|e| matches!(e, Event::Standing { .. })));
    assert!(events.len() < 10_000, "{} events", events.len());
    assert!(plant.energy_residual_j().abs() < 1e-6);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Any current command sequence: the nut never leaves its stroke, the
    /// books close and nothing panics.
    #[test]
    fn stops_are_never_exceeded(
        cmds in proptest::collection::vec(-60.0f64..60.0, 20),
        start in 0.01f64..0.3,
        damping in 0.0f64..200.0,
        identified in any::<bool>(),
    ) {
        let mut p = if identified { Params::identified() } else { Params::design() };
        p.spring_damping_ns_per_m = damping;
        let mut plant = Plant::new(p, start).unwrap();
        let e0 = plant.energy_j();
        let mut worst: f64 = 0.0;
        simulate(&mut plant, 2.0, |t| cmds[((t / 0.1) as usize).min(cmds.len() - 1)], |pl| {
            let s = pl.state();
            assert!(s.p_m >= 0.0 && s.p_m <= p.stroke_m, "p = {}", s.p_m);
            if pl.mode() != Mode::Flight {
                assert!(s.z_m <= p.leg_length_m + 1e-12);
            } else {
                assert!(s.z_m >= p.leg_length_m - 1e-12);
            }
            worst = worst.max(pl.energy_residual_j().abs());
        });
        prop_assert!(worst / e0 < 1e-6, "ledger residual {worst}");
    }
}

/// The hoist's clamp (the bring-up routines' mount): the body stays put
/// whatever the motor does, the nut moves against the spring, the stops'
/// impacts go into the clamp, and the books close.
#[test]
fn a_clamped_body_stays_put_while_the_nut_moves() {
    let mut plant = Plant::new(Params::design(), 0.05).unwrap();
    plant.clamp_body();
    let z0 = plant.state().z_m;
    let mut deepest: f64 = 0.0;
    // 3 A down for 0.5 s (the nut runs into the spring), then 3 A up (it
    // hits the upper stop), then nothing.
    simulate(
        &mut plant,
        2.0,
        |t| {
            if t < 0.5 {
                3.0
            } else if t < 1.0 {
                -3.0
            } else {
                0.0
            }
        },
        |p| {
            assert_eq!(p.state().z_m, z0);
            assert_eq!(p.state().zd_mps, 0.0);
            assert_eq!(p.mode(), Mode::Flight);
            deepest = deepest.max(p.state().p_m);
        },
    );
    // 3 A is 101 N on the nut: 9 mm of an 11 kN/m spring at rest, twice
    // that at the swing's bottom.
    assert!(deepest > 0.012 && deepest < 0.02, "{deepest}");
    assert!(plant.ledger().stop_impact_loss_j > 0.0);
    assert!(
        plant.energy_residual_j().abs() < 1e-6,
        "{}",
        plant.energy_residual_j()
    );
    // Let go: it falls.
    plant.release_body();
    simulate(&mut plant, 0.05, |_| 0.0, |_| {});
    assert!(plant.state().zd_mps < -0.4);
}

/// The hoist lifting a standing robot: the toe leaves the ground at rest
/// when the body passes `l0`, and lowering puts it back; the hoist's work
/// stays out of the books.
#[test]
fn the_hoist_lifts_a_standing_robot_off_the_ground() {
    let params = Params::design();
    let mut plant = Plant::new(params, 0.001).unwrap();
    simulate(&mut plant, 1.0, |_| 0.0, |_| {});
    assert_ne!(plant.mode(), Mode::Flight, "standing after 1 s");
    plant.clamp_body();
    for _ in 0..5000 {
        plant.move_clamped_body(1e-5);
        plant.advance(DT, 0.0, &mut |_| {}).unwrap();
    }
    assert_eq!(plant.mode(), Mode::Flight);
    // 50 mm up, less the standing compression (weight / k = 8.8 mm).
    let toe = plant.toe_height_m();
    assert!((toe - 0.0412).abs() < 1e-3, "{toe}");
    assert!(plant.energy_residual_j().abs() < 1e-6);
    for _ in 0..5000 {
        plant.move_clamped_body(-1e-5);
        plant.advance(DT, 0.0, &mut |_| {}).unwrap();
    }
    assert_ne!(plant.mode(), Mode::Flight);
    assert!(plant.energy_residual_j().abs() < 1e-6);
}

#[test]
fn copper_loss_is_the_current_squared_times_the_resistance_given() {
    // A hop under a current that swings +-20 A at 5 Hz, the winding's
    // resistance changing every period as a thermal model would change it:
    // the ledger's copper loss is sum(i^2 R dt) period by period, to 1e-6 J.
    let p = Params::design();
    let mut plant = Plant::new(p, 0.10).unwrap();
    let dt = 1e-4;
    let (mut want_j, mut want_a2s) = (0.0, 0.0);
    for k in 0..30_000 {
        let t = k as f64 * dt;
        let cmd_a = 20.0 * (2.0 * std::f64::consts::PI * 5.0 * t).sin();
        let r_ohm = 0.3 + 0.1 * (0.7 * t).sin();
        plant.set_winding_resistance_ohm(r_ohm);
        plant.advance(dt, cmd_a, &mut |_| {}).unwrap();
        // Within the supply's reach (the current is the command) all along.
        assert_eq!(plant.motor_current_a(), cmd_a, "at {t} s");
        want_j += cmd_a * cmd_a * r_ohm * dt;
        want_a2s += cmd_a * cmd_a * dt;
    }
    let l = plant.ledger();
    assert!(want_j > 100.0, "{want_j} J");
    assert!(
        (l.copper_loss_j - want_j).abs() < 1e-6,
        "{} vs {want_j} J",
        l.copper_loss_j
    );
    assert!((l.current_squared_a2s - want_a2s).abs() < 1e-6);
    // Outside the mechanical balance: it still closes.
    assert!(
        plant.energy_residual_j().abs() < 1e-6,
        "{}",
        plant.energy_residual_j()
    );
}
