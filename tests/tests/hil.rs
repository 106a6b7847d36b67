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

fn target() -> HilTarget {
    HilTarget::new(DT_S).unwrap_or_else(|e| panic!("{e}"))
}

/// The firmware configured over the link (the run's parameters set by
/// name, then armed) runs the host run's periods: the same apexes, hop
/// ledgers, estimator events and winding temperature, to the bit (the
/// setup's periods on the held start sample leave no trace).
#[test]
fn a_hil_run_is_the_host_run() {
    let host = host_run();
    let hil = hil_run(target()).unwrap_or_else(|e| panic!("{e}"));
    let (h, l) = (&host.summary, &hil.summary);
    assert!(h.apex_heights_m.len() >= 5, "{:?}", h.apex_heights_m);
    assert_eq!(h.apex_heights_m, l.apex_heights_m);
    assert_eq!(h.firmware_hops, l.firmware_hops);
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

/// What the link cannot set (the machine's lead, here) is refused before
/// the run, with the reason, instead of run on the image's machine.
#[test]
fn a_machine_the_link_cannot_configure_is_refused() {
    let cfg = config();
    let mut params = Params::design();
    params.screw_lead_m *= 2.0;
    let e = match spec().build_hil(&params, cfg.start_apex_m, DT_S, connection(target())) {
        Ok(_) => panic!("a HIL run on another lead was accepted"),
        Err(e) => e,
    };
    assert!(e.contains("what the link cannot set"), "{e}");
}
