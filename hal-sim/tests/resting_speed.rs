//! The simulator runs as fast with the hopper at rest as hopping.
//!
//! A run that comes to rest used to run about four times slower per
//! simulated second than one that hops: the firmware's filtered
//! derivatives (eq 4.1) and the amplifier model's current decayed into
//! subnormal floats, on which an x86 FPU is about a hundred times slower.
//! Both now settle to exactly 0 (docs/performance.md, "Resting at full
//! speed"). This compares the two in one process, alternated, best of
//! several: a ratio of times measured side by side, not a wall-clock bound.
#![allow(missing_docs)]

use hal_sim::controller::ControllerSpec;
use hal_sim::inject::Injection;
use hal_sim::run::{run, RunConfig};
use hal_sim::Params;
use std::time::Instant;

/// Seconds of wall time per simulated second of one run, and whether it
/// came to rest.
fn seconds_per_s(duration_s: f64, estop: Option<&str>, protect: bool) -> (f64, bool) {
    let cfg = RunConfig {
        start_apex_m: 0.10,
        duration_s,
        sample_dt_s: 0.0,
        ..RunConfig::new(Params::design())
    };
    let mut spec = ControllerSpec {
        target_apex_m: 0.05,
        ..ControllerSpec::new("energy-apex")
    };
    if let Some(e) = estop {
        spec.injections
            .push(Injection::parse(e).unwrap_or_else(|e| panic!("{e}")));
    }
    if !protect {
        spec.params
            .push((&hopper_control::params::THERMAL_PROTECT, 0.0));
    }
    let mut ctl = spec
        .build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s)
        .unwrap_or_else(|e| panic!("{e}"));
    let started = Instant::now();
    let r = run(&cfg, "design", &mut ctl).unwrap_or_else(|e| panic!("{e}"));
    let wall = started.elapsed().as_secs_f64();
    (wall / duration_s, r.summary.stopped_at_s.is_some())
}

#[test]
fn a_resting_run_is_as_fast_as_a_hopping_one() {
    // Hopping: energy-apex holding 0.05 m for 4 s (no thermal limit, so it
    // hops throughout). Resting: the same law, the e-stop pressed at 1 s
    // (the amplifier disabled, its current decaying to 0), the hopper at
    // rest from about 2.5 s to the end of the 16 s.
    let mut hop = f64::INFINITY;
    let mut rest = f64::INFINITY;
    for _ in 0..5 {
        let (h, h_stopped) = seconds_per_s(4.0, None, false);
        let (r, r_stopped) = seconds_per_s(16.0, Some("estop@1"), true);
        assert!(!h_stopped, "the hopping run stopped");
        assert!(r_stopped, "the resting run never came to rest");
        hop = hop.min(h);
        rest = rest.min(r);
    }
    let ratio = rest / hop;
    println!(
        "hopping {:.0}x real time, at rest {:.0}x: at rest takes {ratio:.2} times as long per simulated second",
        1.0 / hop,
        1.0 / rest
    );
    // With subnormals back in either place alone this ratio was 1.8-2.0
    // (in the filters: 2.0, in the amplifier model: 1.8); without them at
    // rest the plant takes the same short path and the control step does
    // no more, so it is about 1.
    assert!(
        ratio < 1.5,
        "a resting run takes {ratio:.2} times as long per simulated second as a hopping one"
    );
}
