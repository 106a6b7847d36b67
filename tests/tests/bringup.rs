//! The bring-up routines on a mis-calibrated simulated robot, run
//! through the period runner as the link runs them: what they find against
//! the truth, their refusals, and the amplifier when something goes wrong.

use hal_sim::robot::{Miscalibration, VirtualRobot};
use hal_sim::sim_io::{firmware_config, SensorConfig, SimHal};
use hal_sim::{Event, Params};
use hopper_control::arming::ArmRefusal;
use hopper_control::bringup::BringupReport;
use hopper_control::bringup::{CalRefusal, CalState, Routine};
use hopper_control::hopper::Strategy;
use hopper_control::runner::{NoCounter, PeriodRunner, Timing};
use hopper_control::telemetry::{FaultCapture, CAPTURE_LEN};
use hopper_robot_link::Tx;

const DT_S: f64 = 1e-4;
const START_APEX_M: f64 = 0.05;

struct NullTx;
impl Tx for NullTx {
    fn room(&self) -> usize {
        usize::MAX
    }
    fn put(&mut self, _frame: &[u8]) {}
}

/// The robot on the hoist, its firmware configured for the nominal design
/// machine, arming requiring homing and a tare (as the board); untethered
/// (no host in these tests).
/// A virtual robot and its link's queues, which live as long as it does
/// (a command the link task queued is applied at the next period).
struct Robot {
    vr: VirtualRobot,
    link: hopper_robot_link::Endpoint,
    queues: Box<hopper_robot_link::Queues>,
}

impl std::ops::Deref for Robot {
    type Target = VirtualRobot;
    fn deref(&self) -> &VirtualRobot {
        &self.vr
    }
}

impl std::ops::DerefMut for Robot {
    fn deref_mut(&mut self) -> &mut VirtualRobot {
        &mut self.vr
    }
}

fn robot(mis: Miscalibration, set: &[(&str, f32)]) -> Robot {
    let params = Params::design();
    let nominal = firmware_config(
        &params,
        &params,
        Strategy::default(),
        0.12,
        mis.believed_start_apex_m(START_APEX_M),
    );
    let mut cfg = nominal;
    cfg.arming.untethered = true;
    cfg.arming.require_home = true;
    cfg.arming.require_tare = true;
    for (name, v) in set {
        hopper_control::params::set(&mut cfg, name, *v).unwrap_or_else(|e| panic!("{name}: {e:?}"));
    }
    let runner = PeriodRunner::new(cfg, Timing::default()).unwrap_or_else(|e| panic!("{e:?}"));
    let plant = mis
        .plant(params, START_APEX_M)
        .unwrap_or_else(|e| panic!("{e:?}"));
    let hal = mis.hal(
        // The sensors as they are; `set` may mis-configure the firmware.
        SimHal::new(&nominal.calibration, &mis.sensors(SensorConfig::DEFAULT)),
        &plant,
    );
    let vr = VirtualRobot::new(plant, hal, runner, DT_S).hold();
    Robot {
        link: hopper_robot_link::Endpoint::simulated(&vr.firmware.runner),
        vr,
        queues: Box::default(),
    }
}

/// Runs `seconds`; returns the plant's apexes (true toe heights) and the
/// largest current commanded while disarmed.
fn run(r: &mut Robot, seconds: f64) -> Vec<f64> {
    let mut apexes = Vec::new();
    // Faults are not the subject here: a fresh capture each run.
    let mut capture = Box::new(FaultCapture::<CAPTURE_LEN>::new());
    for _ in 0..(seconds / DT_S).round() as u64 {
        r.vr.control(
            &mut r.link,
            core::iter::empty(),
            &mut NullTx,
            &mut capture,
            &mut r.queues,
            &mut NoCounter,
        );
        r.firmware.runner.end_period(false);
        r.advance(&mut |e| {
            if let Event::Apex { toe_height_m, .. } = e {
                apexes.push(toe_height_m);
            }
        })
        .unwrap_or_else(|e| panic!("{e:?}"));
    }
    apexes
}

/// Runs `routine` to its end (20 s at most); its state and results.
fn calibrate(r: &mut Robot, routine: Routine) -> (CalState, BringupReport) {
    r.firmware
        .runner
        .start_calibration(routine, 0.5)
        .unwrap_or_else(|e| panic!("{routine:?} refused: {e:?}"));
    for _ in 0..200 {
        run(r, 0.1);
        let s = r.firmware.runner.calibration().state;
        if s != CalState::Running {
            // Its results are installed by the link task's controller a
            // period or two after it ends.
            run(r, 0.001);
            return (s, r.firmware.runner.bringup_results());
        }
    }
    panic!("{routine:?} still running after 20 s");
}

fn done(r: &mut Robot, routine: Routine) -> BringupReport {
    let (s, b) = calibrate(r, routine);
    assert_eq!(s, CalState::Done, "{routine:?}: {b:?}");
    b
}

fn arm_refusal(r: &VirtualRobot) -> Option<ArmRefusal> {
    let last = r.firmware.runner.hopper().last_input().copied();
    let i = hopper_control::arming::ArmInput {
        faults: r.firmware.runner.hopper().supervisor().faults(),
        estop_pressed: false,
        sensors_ok: true,
        nut_position_m: last.map_or(0.0, |i| i.nut_position_m),
        nut_velocity_mps: 0.0,
        body_velocity_mps: 0.0,
        calibrating: false,
    };
    r.firmware.runner.arming().refusal(&i)
}

fn offsets(r: &VirtualRobot) -> (f32, f32) {
    let c = &r.firmware.runner.hopper().config().calibration;
    (
        c.loadcell_offset_code * c.loadcell_gain_n_per_code,
        c.pot_offset_code * c.pot_gain_m_per_code,
    )
}

/// The whole bring-up of docs/bring-up.md, then the shaped controller: with
/// the spring 15% stiffer and the load cell 5% low, and the spring 15%
/// softer and the load cell 5% high, the routines recover every constant
/// within its tolerance (the CI sessions' figures) and the robot then hops
/// at its target, measured on the plant.
#[test]
fn bring_up_recovers_the_machine_and_the_shaped_controller_then_converges() {
    for (spring_rate_error, loadcell_gain_error) in [(0.15, -0.05), (-0.15, 0.05)] {
        let mis = Miscalibration {
            spring_rate_error,
            loadcell_gain_error,
            ..Miscalibration::SESSION
        };
        let mut r = robot(mis, &[("controller", 8.0), ("target_apex_m", 0.12)]);
        let k_true = Params::design().spring_stiffness_n_per_m * (1.0 + spring_rate_error);
        run(&mut r, 0.05);
        assert_eq!(arm_refusal(&r), Some(ArmRefusal::NotHomed));
        assert_eq!(
            r.firmware.runner.start_calibration(Routine::Home, 0.5),
            Err(CalRefusal::DirectionFirst)
        );
        assert_eq!(
            r.firmware.runner.start_calibration(Routine::Spring, 0.5),
            Err(CalRefusal::HomeFirst)
        );
        done(&mut r, Routine::SensorCheck);
        let d = done(&mut r, Routine::Direction);
        assert!(d.nut_travel_m > 3e-4 && d.force_change_n > 0.0, "{d:?}");
        let h = done(&mut r, Routine::Home);
        // The nut booted 1 mm below its stop: the stop was at -1 mm.
        assert!(
            (f64::from(h.nut_offset_m) + mis.nut_start_m).abs() < 2e-5,
            "{h:?}"
        );
        assert!(h.peak_current_a <= 6.0 + 1e-4, "{h:?}");
        assert_eq!(arm_refusal(&r), Some(ArmRefusal::NotCalibrated));
        // The weighing reads forces through the tare's offset.
        assert_eq!(
            r.firmware.runner.start_calibration(Routine::Weight, 0.5),
            Err(CalRefusal::TareFirst)
        );
        let before = offsets(&r);
        done(&mut r, Routine::Tare);
        let s = done(&mut r, Routine::Spring);
        // The rate as the load cell reads it: its gain error included.
        let k = f64::from(s.spring_rate_n_per_m);
        let k_read = k_true * (1.0 + loadcell_gain_error);
        assert!((k / k_read - 1.0).abs() < 0.01, "{k} vs {k_read}: {s:?}");
        assert_eq!(
            r.firmware
                .runner
                .hopper()
                .config()
                .supervisor
                .spring_rate_n_per_m,
            s.spring_rate_n_per_m
        );
        done(&mut r, Routine::Tare);
        let after = offsets(&r);
        let lc = f64::from(after.0 - before.0);
        let pot = f64::from(after.1 - before.1);
        assert!((lc - mis.loadcell_bias_n).abs() < 0.24, "load cell {lc}");
        assert!((pot - mis.pot_bias_m).abs() < 1e-5, "pot {pot}");
        // On the hoist the leg carries nothing: no weighing, no height
        // zero (refused before they start).
        for routine in [Routine::Weight, Routine::Height] {
            assert_eq!(
                r.firmware.runner.start_calibration(routine, 0.5),
                Err(CalRefusal::NotOnGround),
                "{routine:?}"
            );
        }
        // Off the hoist onto the ground: the weighing, the height zero, up
        // again.
        r.mount(None);
        let bounces = run(&mut r, 3.0);
        eprintln!("after the drop: {bounces:?}");
        let gain_before = r
            .firmware
            .runner
            .hopper()
            .config()
            .calibration
            .loadcell_gain_n_per_code;
        // Standing, the leg carries the robot: a tare would take its
        // weight for the zero, a sweep would lift it, the direction pulse
        // and the homing move would push against it. Each is refused and
        // nothing changes.
        let cfg_before = *r.firmware.runner.hopper().config();
        for routine in [
            Routine::Tare,
            Routine::Spring,
            Routine::Direction,
            Routine::Home,
        ] {
            assert_eq!(
                r.firmware.runner.start_calibration(routine, 0.5),
                Err(CalRefusal::LegLoaded),
                "{routine:?}"
            );
        }
        run(&mut r, 0.01);
        assert_eq!(*r.firmware.runner.hopper().config(), cfg_before);
        done(&mut r, Routine::Weight);
        let w = r.firmware.runner.weighing();
        let c = r.firmware.runner.hopper().config();
        let found = f64::from(gain_before / c.calibration.loadcell_gain_n_per_code) - 1.0;
        eprintln!("weighing: {w:?}: gain error {found:+.4}");
        assert!(
            (found - loadcell_gain_error).abs() < 0.005,
            "gain error {found} vs {loadcell_gain_error}: {w:?}"
        );
        let k = f64::from(c.supervisor.spring_rate_n_per_m);
        assert!(
            (k / k_true - 1.0).abs() < 0.01,
            "{k} vs {k_true} after the weighing"
        );
        // The stance friction, within a tenth of the plant's.
        let f_true = Params::design().leg_friction_n + Params::design().planarizer_friction_n;
        assert!(
            (f64::from(w.friction_n) - f_true).abs() < 0.1 * f_true,
            "friction {} vs {f_true}",
            w.friction_n
        );
        let z = done(&mut r, Routine::Height);
        assert!(
            (f64::from(z.height_offset_m) + mis.height_zero_error_m).abs() < 1e-4,
            "{z:?}"
        );
        r.mount(Some(START_APEX_M));
        run(&mut r, 1.0);
        assert_eq!(arm_refusal(&r), None);
        // Saved to a flash and loaded by the next boot of the same robot:
        // the tare's offsets and the spring rate come back, and the tare is
        // no longer needed (homing is: the encoder is incremental).
        if spring_rate_error > 0.0 {
            saved_and_loaded_at_the_next_boot(&r, mis);
        }
        r.firmware.runner.arming_mut().request_arm();
        let apexes = run(&mut r, 8.0);
        assert!(
            r.firmware.runner.arming().is_armed(),
            "{:?}",
            r.firmware.runner.hopper().supervisor().faults()
        );
        let tail = &apexes[apexes.len().saturating_sub(5)..];
        assert!(
            apexes.len() >= 15 && tail.iter().all(|a| (a - 0.12).abs() < 0.02 * 0.12),
            "spring {spring_rate_error}: {apexes:?}"
        );
    }
}

/// A motor encoder counting the wrong way: the pulse down reads as the nut
/// going up; arming and homing are refused until a check passes.
#[test]
fn a_reversed_encoder_fails_the_direction_check_and_blocks_arming() {
    let mut r = robot(
        Miscalibration::NONE,
        &[("calibration.motor_counts_positive_down", 0.0)],
    );
    run(&mut r, 0.05);
    let (s, d) = calibrate(&mut r, Routine::Direction);
    assert_eq!(s, CalState::FailedReversed, "{d:?}");
    assert!(d.nut_travel_m < -3e-4, "{d:?}");
    assert!(!r.firmware.runner.arming().direction_ok());
    // The reversed count also trips the supervisor's spring cross-check
    // (the spring compresses while the nut reads up); once the nut is back
    // the fault clears, and the reversal is what refuses arming.
    let faults = r.firmware.runner.hopper().supervisor().faults();
    run(&mut r, 1.0);
    if let Some(input) = r.firmware.runner.hopper().last_input().copied() {
        let _ = r.firmware.runner.reset_faults(&input);
    }
    assert_eq!(
        arm_refusal(&r),
        Some(ArmRefusal::DirectionReversed),
        "latched after the check: {faults:?}, now {:?}",
        r.firmware.runner.hopper().supervisor().faults()
    );
    assert_eq!(
        ArmRefusal::DirectionReversed.name(),
        "encoder-or-motor-direction-reversed"
    );
    assert_eq!(
        r.firmware.runner.start_calibration(Routine::Home, 0.5),
        Err(CalRefusal::DirectionFirst)
    );
    // The amplifier is off again at once: no current after the verdict.
    run(&mut r, 0.01);
    assert!(r.hal.mean_current_a(DT_S).abs() < 1e-9);
}

/// The e-stop pressed while the nut is being homed: the routine stops in
/// the same period with the amplifier off, nothing applied, not homed.
#[test]
fn the_estop_stops_homing_with_the_amplifier_off() {
    let mut r = robot(Miscalibration::SESSION, &[("bringup.speed_mps", 0.001)]);
    run(&mut r, 0.05);
    done(&mut r, Routine::Direction);
    r.firmware
        .runner
        .start_calibration(Routine::Home, 0.5)
        .unwrap_or_else(|e| panic!("{e:?}"));
    let mut driven = 0;
    let mut after = 0;
    let mut pressed = false;
    for i in 0..10_000 {
        // Half a second in (1 mm at 1 mm/s takes a second), the button.
        pressed |= i == 5_000;
        r.hal.faults.estop = pressed;
        let vr = &mut r.vr;
        let p = {
            let mut io = vr.hal.io(&vr.plant);
            vr.firmware.runner.run_period(&mut io, &mut NoCounter)
        };
        vr.firmware.runner.end_period(false);
        vr.advance(&mut |_| {}).unwrap_or_else(|e| panic!("{e:?}"));
        if p.out.command.amp_enable {
            if pressed {
                after += 1;
            } else {
                driven += 1;
            }
        }
    }
    assert!(driven > 4_000, "{driven}");
    // The press is debounced for 0.2 ms: two periods at most.
    assert!(after <= 2, "{after} periods enabled after the press");
    assert_eq!(r.firmware.runner.calibration().state, CalState::FailedFault);
    assert!(!r.firmware.runner.arming().homed());
    assert!(r.firmware.runner.bringup_results().nut_offset_m.is_nan());
}

fn saved_and_loaded_at_the_next_boot(r: &VirtualRobot, mis: Miscalibration) {
    use hopper_control::persist::{AtBoot, LoadError, MAX_RECORD};
    use hopper_store::{block_on, RamFlash, Store};
    let mut record = [0u8; MAX_RECORD];
    let n = r.firmware.runner.calibration_record(&mut record);
    let mut store =
        Store::new(RamFlash::<2, 2048>::new(), 0..4096).unwrap_or_else(|e| panic!("{e:?}"));
    block_on(store.save(&record[..n])).unwrap_or_else(|e| panic!("{e:?}"));
    let mut back = [0u8; MAX_RECORD];
    let len = block_on(store.load(&mut back))
        .unwrap_or_else(|e| panic!("{e:?}"))
        .unwrap_or(0);
    let mut next = robot(mis, &[]);
    next.firmware.runner.load_calibration(back.get(..len));
    assert_eq!(
        next.firmware.runner.calibration_at_boot(),
        AtBoot::Loaded(hopper_control::persist::saved_count() as u8)
    );
    let (a, b) = (
        r.firmware.runner.hopper().config(),
        next.firmware.runner.hopper().config(),
    );
    assert_eq!(a.calibration, b.calibration);
    assert_eq!(
        a.supervisor.spring_rate_n_per_m,
        b.supervisor.spring_rate_n_per_m
    );
    run(&mut next, 0.05);
    assert_eq!(arm_refusal(&next), Some(ArmRefusal::NotHomed));
    // A corrupted record: refused, the defaults run, and the tare is
    // required again.
    let mut bad = back;
    bad[10] ^= 0x40;
    let mut next = robot(mis, &[]);
    next.firmware.runner.load_calibration(bad.get(..len));
    assert_eq!(
        next.firmware.runner.calibration_at_boot(),
        AtBoot::Refused(LoadError::Crc)
    );
    assert_eq!(
        next.firmware.runner.hopper().config().calibration,
        robot(mis, &[])
            .firmware
            .runner
            .hopper()
            .config()
            .calibration
    );
    next.firmware.runner.arming_mut().note_direction(false);
    next.firmware.runner.arming_mut().note_homed();
    run(&mut next, 0.05);
    assert_eq!(arm_refusal(&next), Some(ArmRefusal::NotCalibrated));
}

/// The operator's disarm stops a motor-driving routine like the e-stop; a
/// parameter cannot change under a running routine; changing what the
/// direction check and homing were made on undoes them, changing the
/// load cell's offset by hand undoes the tare.
#[test]
fn disarm_stops_a_routine_and_hand_changes_undo_its_verdicts() {
    let mut r = robot(Miscalibration::SESSION, &[("bringup.speed_mps", 0.001)]);
    run(&mut r, 0.05);
    done(&mut r, Routine::Direction);
    r.firmware
        .runner
        .start_calibration(Routine::Home, 0.5)
        .unwrap_or_else(|e| panic!("{e:?}"));
    run(&mut r, 0.2);
    assert_eq!(
        r.firmware
            .runner
            .set_param("calibration.motor_counts_positive_down", 0.0),
        Err(hopper_control::runner::SetError::Calibrating)
    );
    r.firmware.runner.arming_mut().request_disarm();
    run(&mut r, 0.001);
    assert_eq!(r.firmware.runner.calibration().state, CalState::FailedFault);
    run(&mut r, 0.01);
    assert!(r.hal.mean_current_a(DT_S).abs() < 1e-6);
    // Home properly, tare, then change things by hand.
    done(&mut r, Routine::Home);
    done(&mut r, Routine::Tare);
    assert!(r.firmware.runner.arming().homed() && r.firmware.runner.arming().tared());
    r.firmware
        .runner
        .set_param("calibration.loadcell_offset_code", 230.0)
        .unwrap_or_else(|e| panic!("{e:?}"));
    assert!(!r.firmware.runner.arming().tared() && r.firmware.runner.arming().homed());
    r.firmware
        .runner
        .set_param("calibration.motor_counts_positive_down", 0.0)
        .unwrap_or_else(|e| panic!("{e:?}"));
    assert!(!r.firmware.runner.arming().homed() && !r.firmware.runner.arming().direction_ok());
}
