//! Hardware in the loop, in this process: `hopper-sim run --hil`'s host end
//! (`hal_sim::hil::HilDriver`) against the HIL image's loop
//! (`hal_sim::hil::HilTarget`: the link's endpoint, a control period on
//! each sample, the answer), the same exchange `cargo xtask hil` runs
//! against the image on QEMU.

use hal_sim::controller::ControllerSpec;
use hal_sim::hil::{Connection, HilTarget};
use hal_sim::run::{run, RunConfig, RunResult};
use hal_sim::Params;

const DT_S: f64 = 1e-4;
/// The in-process target answers at once.
const TIMEOUT: std::time::Duration = std::time::Duration::from_secs(1);

fn config() -> RunConfig {
    RunConfig {
        start_apex_m: 0.10,
        duration_s: 2.0,
        sample_dt_s: 0.0,
        ..RunConfig::new(Params::design())
    }
}

fn spec() -> ControllerSpec {
    ControllerSpec::new("energy-apex")
}

fn host_run() -> RunResult {
    let cfg = config();
    let mut ctl = spec()
        .build(&cfg.params, cfg.start_apex_m, DT_S)
        .unwrap_or_else(|e| panic!("{e}"));
    run(&cfg, "design", &mut ctl).unwrap_or_else(|e| panic!("{e}"))
}

fn hil_run(target: HilTarget) -> Result<RunResult, String> {
    let cfg = config();
    let mut ctl = spec().build_hil(&cfg.params, cfg.start_apex_m, DT_S, connection(target))?;
    run(&cfg, "design", &mut ctl)
}

fn connection(target: HilTarget) -> Connection {
    Connection {
        line: Box::new(target),
        timeout: TIMEOUT,
    }
}

/// The HIL target named by `HOPPER_HIL` (`sil_tests::HIL_TARGET_VAR`), or
/// the in-process one.
fn named_or_in_process() -> Connection {
    match std::env::var(sil_tests::HIL_TARGET_VAR) {
        Ok(t) => Connection::named(&t, std::time::Duration::from_secs(5))
            .unwrap_or_else(|e| panic!("{e}")),
        Err(_) => connection(target()),
    }
}

fn target() -> HilTarget {
    HilTarget::new(DT_S).unwrap_or_else(|e| panic!("{e}"))
}

/// The firmware configured over the link (the run's parameters set by
/// name, then armed) runs the host run's periods: the same apexes, hop
/// ledgers, estimator events, to the bit (the winding temperature and the
/// copper loss booked at its resistance to 1e-4) (the
/// setup's periods on the held start sample leave no trace).
#[test]
fn a_hil_run_is_the_host_run() {
    let host = host_run();
    let hil = hil_run(target()).unwrap_or_else(|e| panic!("{e}"));
    let (h, l) = (&host.summary, &hil.summary);
    assert!(h.apex_heights_m.len() >= 5, "{:?}", h.apex_heights_m);
    assert_eq!(h.apex_heights_m, l.apex_heights_m);
    // The hops' copper loss takes the winding's resistance from that
    // temperature (below): within 1e-4 of each other (f32 sums); all else to the bit.
    let bare = |hops: &[hopper_control::telemetry::HopLedger]| {
        hops.iter()
            .map(|x| hopper_control::telemetry::HopLedger {
                copper_loss_j: 0.0,
                stance_copper_loss_j: 0.0,
                ..*x
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(bare(&h.firmware_hops), bare(&l.firmware_hops));
    for (x, y) in h.firmware_hops.iter().zip(&l.firmware_hops) {
        assert!((x.copper_loss_j - y.copper_loss_j).abs() <= 1e-4 * x.copper_loss_j.max(1.0));
        assert!(
            (x.stance_copper_loss_j - y.stance_copper_loss_j).abs()
                <= 1e-4 * x.stance_copper_loss_j.max(1.0)
        );
    }
    assert_eq!(h.estimated_events, l.estimated_events);
    assert_eq!(h.faults, l.faults);
    // The winding temperature's model integrates in 10 ms steps of
    // accumulated periods (`hopper_control::thermal`), which the setup's
    // held periods shift against the run's: 0.0014 C apart at 8.7 C of
    // rise over 2 s.
    let (ht, lt) = (h.thermal.unwrap_or_default(), l.thermal.unwrap_or_default());
    assert!(ht.peak_winding_c > 33.0, "{ht:?}");
    assert!(
        (ht.peak_winding_c - lt.peak_winding_c).abs() < 0.01,
        "{ht:?} {lt:?}"
    );
    assert_eq!(ht.first_derated_s, lt.first_derated_s);
    assert_eq!(h.arm_refused, None);
    assert_eq!(l.arm_refused, None);
    let r = l.hil.as_ref().unwrap_or_else(|| panic!("no HIL report"));
    assert_eq!(r.periods, 20_000);
    // The energy-apex run's settings beyond the image's boot ones: the
    // controller, the untethered arming, no tare or homing needed, the
    // start height, the supervisor's spring check from the plant.
    assert!(r.params_set >= 4 && r.params_set <= 12, "{r:?}");
    assert!(host.summary.hil.is_none());
}

/// A host frame the robot never sees (here a sample in the run) stops the
/// run with the error, not a run on stale outputs.
#[test]
fn a_lost_frame_stops_the_run() {
    let mut t = target();
    // Frame 0 is the hello; the configuration takes a few hundred.
    t.drop_frames = vec![2_000];
    let e = match hil_run(t) {
        Ok(_) => panic!("a run that lost a frame went on"),
        Err(e) => e,
    };
    assert!(e.contains("no answer from the robot for sample"), "{e}");
}

/// Another machine (here twice the lead) runs in the loop: its constants
/// are parameters, set on the robot over the link before the run; what the
/// link cannot set (a board fact: the motor counter's width) is refused
/// before the run, with the reason, instead of run on the image's board.
#[test]
fn another_machine_is_set_over_the_link_and_a_board_fact_is_refused() {
    let cfg = config();
    let mut params = Params::design();
    params.screw_lead_m *= 2.0;
    if let Err(e) = spec().build_hil(&params, cfg.start_apex_m, DT_S, connection(target())) {
        panic!("a HIL run on another lead was refused: {e}");
    }
    // `calibration.motor_counter_bits` is no parameter: the board's timer.
    let mut desired = hal_sim::sim_io::firmware_config(
        &Params::design(),
        &Params::design(),
        hopper_control::hopper::Strategy::default(),
        0.05,
        cfg.start_apex_m,
    );
    desired.calibration.motor_counter_bits = 32;
    let e = hal_sim::hil::configure_check(&desired)
        .err()
        .unwrap_or_else(|| panic!("a 32-bit motor counter was accepted"));
    assert!(e.contains("what the link cannot set"), "{e}");
}

/// The sensor-side faults (`--inject`) in the loop: each latches the fault
/// `docs/safety.md` names within the periods `tests/fault_injection.rs`
/// allows a host run, and from then on the robot's DAC code and enable
/// command no current; the firmware-side kinds are refused. With
/// `HOPPER_HIL` set, against that target.
#[test]
fn sensor_faults_latch_and_stop_the_motor_in_the_loop() {
    use hal_sim::inject::{InjectKind, Injection};
    // Mid-stance of the first hop, open-torque pushing at full current.
    let time_s = 0.2;
    for (kind, latency) in [
        (InjectKind::EncoderJump, 0),
        (InjectKind::LoadcellSaturated, 0),
        (InjectKind::PotOpen, 0),
        (InjectKind::Estop, 1),
        (InjectKind::AmpFault, 0),
    ] {
        let cfg = RunConfig {
            duration_s: 0.3,
            ..config()
        };
        let spec = ControllerSpec {
            injections: vec![Injection { kind, time_s }],
            ..ControllerSpec::new("open-torque")
        };
        let mut ctl = spec
            .build_hil(&cfg.params, cfg.start_apex_m, DT_S, named_or_in_process())
            .unwrap_or_else(|e| panic!("{e}"));
        let s = run(&cfg, "design", &mut ctl)
            .unwrap_or_else(|e| panic!("{e}"))
            .summary;
        let name = kind.name();
        assert!(
            s.faults.iter().all(|f| f.time_s + 0.5 * DT_S >= time_s),
            "{name}: a fault before the injection: {:?}",
            s.faults
        );
        let first = s
            .faults
            .iter()
            .find(|f| kind.detected_as().contains(&f.name))
            .unwrap_or_else(|| panic!("{name}: not latched: {:?}", s.faults));
        let late = ((first.time_s - time_s) / DT_S).round().abs();
        assert!(
            (0.0..=f64::from(latency)).contains(&late),
            "{name}: latched {late} periods after the injection"
        );
        assert_eq!(s.max_abs_current_after_fault_a, Some(0.0), "{name}");
    }
    for kind in [InjectKind::Nan, InjectKind::Overrun, InjectKind::DacError] {
        let cfg = config();
        let spec = ControllerSpec {
            injections: vec![Injection { kind, time_s: 0.2 }],
            ..ControllerSpec::new("open-torque")
        };
        match spec.build_hil(&cfg.params, cfg.start_apex_m, DT_S, connection(target())) {
            Ok(_) => panic!("{}: a firmware-side injection was taken", kind.name()),
            Err(e) => assert!(e.contains("inside the firmware"), "{e}"),
        }
    }
}
