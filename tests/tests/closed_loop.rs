//! Closed loop: the firmware's control crate on the mock HAL (sensor
//! quantisation, default Gaussian noise, DAC, amplifier lag) against the
//! plant, through the runner `hopper-sim run` uses.
//!
//! Each test asserts what this model's physics gives. Where that differs
//! from the thesis's claims (section 2.1.3: every law "converges" to
//! `E_D = 70 J`), `docs/controllers.md` says why: the thesis's simulations
//! had no torque-speed limit and no stop impacts.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hal_sim::controller::{Controller, ControllerSpec, FirmwareController};
use hal_sim::run::{run, RunConfig, Summary};
use hal_sim::{Params, Plant};
use hopper_control::laws::ControllerKind;
use sil_tests::{snapshot_text, CliRun};

fn sim(spec: &ControllerSpec, params: Params, start: f64, duration: f64) -> Summary {
    let mut cfg = RunConfig::new(params);
    cfg.start_apex_m = start;
    cfg.duration_s = duration;
    cfg.sample_dt_s = 0.0;
    let mut c = spec.build(&params, start, cfg.control_dt_s).unwrap();
    run(&cfg, "test", &mut c).unwrap().summary
}

fn spec(name: &str, target: f64) -> ControllerSpec {
    ControllerSpec {
        target_apex_m: target,
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
    }
    .run()
    .unwrap();
    // The first hops overshoot the dip (the law sheds the drop's surplus
    // energy), then the apex climbs back without overshoot and stays within
    // 2 % of the target: from hop 26 of 34 today.
    let htc = s.hops_to_converge.unwrap();
    assert!(htc <= 30, "converged at hop {htc}");
    for h in last(&s, 5) {
        assert!((h - 0.05).abs() <= 0.02 * 0.05, "{:?}", s.apex_heights_m);
    }
    let climb = &s.apex_heights_m[3..];
    assert!(
        climb.windows(2).all(|w| w[1] > w[0]) && climb.iter().all(|h| *h < 0.05),
        "{:?}",
        s.apex_heights_m
    );
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
    for torque in [0.8, 0.9, 1.0] {
        let s = sim(
            &ControllerSpec {
                torque_nm: Some(torque),
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
    assert!(steady[0] < steady[1] && steady[1] < steady[2], "{steady:?}");
    // The 1 N m cycle is about 0.040 m: far below the thesis's 0.15 m (70 J).
    assert!((0.035..0.046).contains(&steady[2]), "{steady:?}");
    // Below about 0.7 N m the stance work cannot pay for the losses.
    let weak = sim(
        &ControllerSpec {
            torque_nm: Some(0.5),
            ..ControllerSpec::new("open-torque")
        },
        Params::design(),
        0.10,
        10.0,
    );
    assert!(
        last(&weak, 3).iter().all(|h| *h < 0.005),
        "{:?}",
        weak.apex_heights_m
    );
}

#[test]
fn thesis_laws_against_the_torque_limited_actuator() {
    // Design parameters, 0.10 m drop, 0.05 m target (E_D = 60.3 J).
    let run = |name: &str| sim(&spec(name, 0.05), Params::design(), 0.10, 8.0);
    // Position steps (eqs 2.49-2.50): the 1 N m motor moves the nut only a
    // few mm against the spring before liftoff, so hopping decays.
    for name in ["step-open", "step-closed"] {
        let s = run(name);
        assert!(s.max_stroke_m < 0.01, "{name}: {}", s.max_stroke_m);
        assert!(s.stopped_at_s.is_some(), "{name}: {:?}", s.apex_heights_m);
    }
    // Energy feedback (eq 2.52) and velocity (eq 2.53) count the rotor's
    // kinetic energy as hop energy: they cut the torque while the motor
    // spins, and hopping decays too.
    for name in ["energy", "velocity"] {
        let s = run(name);
        assert!(
            last(&s, 3).iter().all(|h| *h < 0.01),
            "{name}: {:?}",
            s.apex_heights_m
        );
    }
    // Modified torque (section 4.4.3): spinning up before touchdown gets the
    // apex far above the stance-only laws.
    let s = run("modified-torque");
    let best = s.apex_heights_m.iter().copied().fold(0.0, f64::max);
    assert!(best > 0.09, "{:?}", s.apex_heights_m);
    for s in [run("energy"), run("velocity"), run("modified-torque")] {
        assert!(s.faults.is_empty(), "{}: {:?}", s.controller, s.faults);
        assert!(s.max_current_a <= Params::design().current_limit_a + 1e-9);
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
        inject: impl Fn(&mut hal_sim::mock::IoFaults, usize),
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
    Rig::new("open-torque").check_trip(t, "estop", 0, |f, _| f.estop = true);
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
