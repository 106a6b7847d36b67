//! Closed loop: the firmware's control crate on the simulated hardware (sensor
//! quantisation, default Gaussian noise, DAC, amplifier lag) against the
//! plant, through the runner `hopper-sim run` uses.
//!
//! Each test asserts what this model's physics gives. Where that differs
//! from the thesis's claims (section 2.1.3: every law "converges" to
//! `E_D = 70 J`), `docs/controllers.md` says why: the thesis's simulations
//! had no torque-speed limit and no stop impacts.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hal_sim::controller::{ControllerSpec, FirmwareController, PlantDriver};
use hal_sim::run::{run, RunConfig, Summary};
use hal_sim::{Params, Plant};
use hopper_control::laws::ControllerKind;
use sil_tests::{snapshot_text, CliRun, NO_THERMAL_LIMIT};

fn sim(spec: &ControllerSpec, params: Params, start: f64, duration: f64) -> Summary {
    let mut cfg = RunConfig::new(params);
    cfg.start_apex_m = start;
    cfg.duration_s = duration;
    cfg.sample_dt_s = 0.0;
    let mut c = sil_tests::firmware(spec, &params, start, cfg.control_dt_s).unwrap();
    run(&cfg, "test", &mut *c).unwrap().summary
}

/// `name` aiming at `target`, with the motor's thermal protection off:
/// these tests study the laws' limit cycles over 15 s, past the 8 to 14 s
/// after which the protection derates them on the design machine.
fn spec(name: &str, target: f64) -> ControllerSpec {
    ControllerSpec {
        target_apex_m: target,
        params: NO_THERMAL_LIMIT.to_vec(),
        ..ControllerSpec::new(name)
    }
}

fn last(s: &Summary, n: usize) -> &[f64] {
    let a = &s.apex_heights_m;
    &a[a.len().saturating_sub(n)..]
}

#[test]
fn energy_apex_converges_to_the_target_from_low_and_high_starts() {
    for start in [0.02, 0.25] {
        let s = sim(&spec("energy-apex", 0.05), Params::design(), start, 15.0);
        let htc = s.hops_to_converge;
        assert!(htc.is_some(), "start {start}: {:?}", s.apex_heights_m);
        // Converged and stays: the last 10 apexes all within 2% of 0.05 m.
        for h in last(&s, 10) {
            assert!((h - 0.05).abs() <= 0.02 * 0.05, "start {start}: {h}");
        }
        assert!(s.faults.is_empty(), "{:?}", s.faults);
        assert!(htc.unwrap() <= 35, "start {start}: {htc:?}");
    }
}

/// Canonical run (a): `hopper-sim run --params design --controller
/// energy-apex --start-apex 0.10 --target-apex 0.05 --duration 10 --json`,
/// the README's and the benchmark's energy-apex run. One simulation feeds
/// the bands and the snapshot, which pins every figure of the JSON so that
/// a refactor that moves any of them (not only by the 5 % a band allows)
/// fails here.
#[test]
fn energy_apex_canonical_run_converges_and_matches_its_snapshot() {
    let s = CliRun {
        params: Some("design"),
        controller: Some(ControllerKind::EnergyApex),
        start_apex_m: Some(0.10),
        target_apex_m: Some(0.05),
        duration_s: Some(10.0),
        set: &[],
    }
    .run()
    .unwrap();
    // The first hops overshoot the dip (the law sheds the drop's surplus
    // energy), then the apex climbs back, overshoots by 6 % and stays
    // within 2 % of the target: from hop 15 of 33 (the requirement is at
    // most 15).
    let htc = s.hops_to_converge.unwrap();
    assert!(htc <= 15, "converged at hop {htc}");
    for h in last(&s, 5) {
        assert!((h - 0.05).abs() <= 0.02 * 0.05, "{:?}", s.apex_heights_m);
    }
    let climb = &s.apex_heights_m[3..];
    assert!(climb.iter().all(|h| *h < 0.054), "{:?}", s.apex_heights_m);
    assert!(s.faults.is_empty(), "{:?}", s.faults);
    assert!(s.max_current_a <= Params::design().current_limit_a + 1e-9);
    assert!(s.energy_residual_j.abs() < 1e-3, "{}", s.energy_residual_j);
    insta::assert_snapshot!("energy_apex_design", snapshot_text(&s).unwrap());
}

#[test]
fn energy_apex_regulates_a_lower_target_too() {
    let s = sim(&spec("energy-apex", 0.04), Params::design(), 0.10, 15.0);
    for h in last(&s, 5) {
        assert!((h - 0.04).abs() <= 0.02 * 0.04, "{:?}", s.apex_heights_m);
    }
}

#[test]
fn constant_torque_limit_cycle_grows_with_torque() {
    let mut steady = Vec::new();
    for torque in [0.5, 0.8, 0.9, 1.0] {
        let s = sim(
            &ControllerSpec {
                torque_nm: Some(torque),
                // Protection on, 0.5 N m derates from 12.4 s.
                params: NO_THERMAL_LIMIT.to_vec(),
                ..ControllerSpec::new("open-torque")
            },
            Params::design(),
            0.10,
            15.0,
        );
        let h = s
            .steady_apex_m
            .unwrap_or_else(|| panic!("{torque} N m: no limit cycle: {:?}", last(&s, 6)));
        steady.push(h);
    }
    assert!(steady.windows(2).all(|w| w[0] < w[1]), "{steady:?}");
    // The 1 N m cycle is about 0.087 m (0.040 m with the old 5 mm preload):
    // below the thesis's 0.15 m (70 J), which constant torque need not reach.
    assert!((0.083..0.091).contains(&steady[3]), "{steady:?}");
    // Even 0.5 N m holds about 0.021 m (with the old 5 mm preload and late
    // contact detection it decayed below 5 mm).
    assert!((0.0204..0.0218).contains(&steady[0]), "{steady:?}");
}

#[test]
fn thesis_laws_steady_apexes_on_the_design_preset() {
    let run = |kind: ControllerKind, start: f64| {
        CliRun {
            params: Some("design"),
            controller: Some(kind),
            start_apex_m: Some(start),
            target_apex_m: Some(0.15),
            duration_s: Some(15.0),
            // Protection on, energy-apex derates from 8.4 s and open-torque
            // from 10.6 s at this target.
            set: &NO_THERMAL_LIMIT,
        }
        .run()
        .unwrap()
    };
    // Hops (1-based) from which every apex is within 2 % of the steady one.
    let settled = |s: &Summary| {
        let h = s.steady_apex_m.unwrap();
        let a = &s.apex_heights_m;
        (0..a.len())
            .find(|&i| a[i..].iter().all(|x| (x - h).abs() <= 0.02 * h))
            .map(|i| i + 1)
            .unwrap()
    };
    let mut hops = Vec::new();
    for (kind, steady_m) in [
        (ControllerKind::OpenTorque, 0.0871),
        (ControllerKind::Energy, 0.0800),
        (ControllerKind::Velocity, 0.0708),
    ] {
        for start in [0.05, 0.25] {
            let s = run(kind, start);
            let h = s
                .steady_apex_m
                .unwrap_or_else(|| panic!("{kind}: {:?}", s.apex_heights_m));
            assert!(
                (h - steady_m).abs() <= 0.03 * steady_m,
                "{kind} from {start}: {h}"
            );
            // The thesis's "about 100 ms" stance (93 ms with a 5 mm preload).
            let t = s.stance_time_s.unwrap();
            assert!((0.097..0.102).contains(&t), "{kind}: stance {t}");
            assert!(s.faults.is_empty(), "{kind}: {:?}", s.faults);
            hops.push(settled(&s));
        }
    }
    // "Energy feedback converges much faster than constant torque": from
    // 0.25 m, 12 hops against 22 (and from 0.05 m, 12 against 16).
    assert!(hops[3] < hops[1] && hops[2] < hops[0], "{hops:?}");
    // Position steps (eqs 2.49-2.50): the 1 N m motor moves the nut only
    // about a centimetre against the spring before liftoff, and hopping
    // decays to sub-millimetre bounces.
    for kind in [ControllerKind::StepOpen, ControllerKind::StepClosed] {
        let s = run(kind, 0.10);
        assert!(s.max_stroke_m < 0.045, "{kind}: {}", s.max_stroke_m);
        assert!(
            last(&s, 1).iter().all(|h| *h < 0.002),
            "{kind}: {:?}",
            s.apex_heights_m
        );
    }
}

#[test]
fn estimator_reports_one_touchdown_and_one_liftoff_per_hop_with_noise() {
    for name in ["open-torque", "energy-apex", "passive"] {
        let s = sim(&spec(name, 0.05), Params::design(), 0.10, 6.0);
        let e = s.estimated_events.unwrap();
        // Hops the sensors can resolve: apex above 2 mm (the touchdown
        // thresholds are 2 mm of pot compression and 40 N excess force).
        let visible = s.apex_heights_m.iter().filter(|h| **h > 0.002).count();
        assert!(
            e.apexes >= visible && e.apexes <= s.apex_heights_m.len(),
            "{name}: {e:?} {visible}"
        );
        assert!(
            e.touchdowns <= s.hops,
            "{name}: {e:?} vs {} plant touchdowns",
            s.hops
        );
        assert!(
            e.liftoffs <= e.touchdowns && e.touchdowns <= e.liftoffs + 1,
            "{name}: {e:?}"
        );
        assert_eq!(s.firmware_hops.len(), e.apexes, "{name}");
    }
}

#[test]
fn firmware_hop_ledger_tracks_the_plant() {
    let s = sim(&spec("energy-apex", 0.05), Params::design(), 0.02, 10.0);
    assert!(s.firmware_hops.len() >= 20);
    // Apex estimate from the height encoder vs the plant's exact apex.
    let n = s.firmware_hops.len().min(s.apex_heights_m.len());
    for (f, h) in s.firmware_hops.iter().zip(&s.apex_heights_m).take(n) {
        assert!(
            (f64::from(f.apex_height_m) - h).abs() < 1.5e-3,
            "{} vs {h}",
            f.apex_height_m
        );
        assert!(
            f.stance_duration_s > 0.05 && f.stance_duration_s < 0.15,
            "{f:?}"
        );
        assert!(f.peak_current_a <= 33.7 && f.peak_stroke_m < 0.05, "{f:?}");
    }
}

/// Steps the closed loop by hand, with a fault injected at `t_fault`.
struct Rig {
    plant: Plant,
    ctl: FirmwareController,
}

impl Rig {
    fn new(name: &str) -> Self {
        let params = Params::design();
        let ctl = spec(name, 0.05).build(&params, 0.10, 1e-4).unwrap();
        Rig {
            plant: Plant::new(params, 0.10).unwrap(),
            ctl,
        }
    }

    fn step(&mut self) {
        let i = self.ctl.current_command_a(&self.plant);
        self.plant.advance(1e-4, i, &mut |_| {}).unwrap();
    }

    /// Runs to `t`, applies `inject`, then checks 0.5 s of safe output.
    /// `latency` is the number of periods after the injection by which the
    /// fault must have latched (0: in the same period).
    fn check_trip(
        mut self,
        t: f64,
        fault: &str,
        latency: usize,
        inject: impl Fn(&mut hal_sim::sim_io::IoFaults, usize),
    ) {
        // Contact disagreement needs the leg well compressed (the load cell's
        // contact threshold is 150 N of excess force, 13.6 mm).
        let deep_stance = |p: &Plant| {
            p.mode() == hal_sim::Mode::Stance && p.params().leg_length_m - p.state().z_m > 0.02
        };
        while self.plant.time_s() < t || (fault == "contact-disagree" && !deep_stance(&self.plant))
        {
            self.step();
            assert!(
                self.ctl.faults().is_empty(),
                "{fault}: early {:?}",
                self.ctl.faults()
            );
        }
        for k in 0..5000 {
            inject(&mut self.ctl.hal.faults, k);
            self.step();
            let out = *self.ctl.last_output().unwrap();
            if k >= latency {
                assert!(
                    self.ctl.faults().iter().any(|f| f.name == fault),
                    "{fault}: period {k}: {:?}",
                    self.ctl.faults()
                );
                assert!(!self.ctl.hal.amp_enabled(), "{fault}: amplifier on");
                assert_eq!(self.ctl.hal.commanded_current_a(), 0.0, "{fault}");
                assert_eq!(out.command.current_a, 0.0);
                let p = self.plant.state().p_m;
                assert!((0.0..=0.05).contains(&p));
            }
        }
    }
}

#[test]
fn supervisor_trips_on_each_injected_fault_and_stays_safe() {
    let t = 1.03; // mid-hop for the 0.10 m drop
                  // The e-stop counts once pressed for 0.2 ms (`estop.press_s`): the
                  // second period.
    Rig::new("open-torque").check_trip(t, "estop", 1, |f, _| f.estop = true);
    Rig::new("open-torque").check_trip(t, "amp-fault", 0, |f, k| f.amp_fault = k == 0);
    Rig::new("open-torque").check_trip(t, "dac-error", 0, |f, k| f.dac_error = k == 0);
    Rig::new("open-torque").check_trip(t, "sensor-range", 0, |f, k| f.read_error = k == 0);
    Rig::new("open-torque").check_trip(t, "encoder-jump", 0, |f, k| {
        if k == 0 {
            f.motor_counts_offset = 5000;
        }
    });
    // A runaway the plant does not follow: 60 counts per period (1.5 m/s of
    // nut); the filtered velocity (eq 4.1, G = 0.9) needs a few periods.
    Rig::new("open-torque").check_trip(t, "stroke-limit", 10, |f, k| {
        if k < 40 {
            f.motor_counts_offset = f.motor_counts_offset.wrapping_add(60);
        }
    });
    // Load cell stuck at the top rail: out of range.
    Rig::new("energy-apex").check_trip(t, "sensor-range", 0, |f, _| f.loadcell_code = Some(4095));
    // Potentiometer open (bottom rail): below its physical range.
    Rig::new("energy-apex").check_trip(t, "sensor-range", 0, |f, _| f.pot_code = Some(0));
    // Potentiometer stuck at "no compression" while the load cell sees stance.
    Rig::new("open-torque").check_trip(1.0, "contact-disagree", 25, |f, _| f.pot_code = Some(205));
}
