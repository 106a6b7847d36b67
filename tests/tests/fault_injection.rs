//! Fault injection: every kind `hopper-sim run --inject KIND@TIME`
//! accepts, through the same path (`ControllerSpec::injections`, applied by
//! `FirmwareController` each period), in closed loop on the design plant.
//!
//! For each kind: the supervisor latches the fault `docs/safety.md` names
//! within the latency that table states (the same period, except where the
//! fault is physically invisible until the plant moves), from that period on
//! the amplifier is disabled and the command is the zero-current DAC code,
//! the nut stays within its stops, and nothing panics.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hal_sim::controller::{ControllerSpec, PlantDriver};
use hal_sim::inject::{InjectKind, Injection};
use hal_sim::sim_io::SensorConfig;
use hal_sim::{Params, Plant};
use hopper_control::supervisor::Command;

/// Control period, s (the default 10 kHz).
const DT_S: f64 = 1e-4;
/// Drop height, m: touchdown at about 0.143 s, stance until about 0.25 s.
const START_APEX_M: f64 = 0.10;
/// Mid-stance of the first hop, `open-torque` pushing at full current: the
/// worst moment to lose control of the motor.
const MID_STANCE_S: f64 = 0.2;
/// How long to watch after the injection, s.
const WATCH_S: f64 = 0.1;

/// Runs `kind` injected at `time_s` into `controller`; checks everything
/// listed in the module docs with `max_latency_periods` allowed between the
/// injection period and the latch (0: the same period). Returns the
/// measured latency in periods.
fn inject(
    kind: InjectKind,
    controller: &str,
    time_s: f64,
    seed: u64,
    max_latency_periods: usize,
) -> usize {
    let name = kind.name();
    let params = Params::design();
    let spec = ControllerSpec {
        sensors: SensorConfig {
            seed,
            ..SensorConfig::DEFAULT
        },
        injections: vec![Injection { kind, time_s }],
        ..ControllerSpec::new(controller)
    };
    let mut ctl = spec.build(&params, START_APEX_M, DT_S).unwrap();
    let mut plant = Plant::new(params, START_APEX_M).unwrap();
    let zero_code = ctl.hal.dac_zero_code();
    let mut injected_at: Option<usize> = None;
    let mut latched_at: Option<usize> = None;
    let mut k = 0usize;
    loop {
        // The same rule as `FirmwareController`: due in the first period
        // that starts no earlier than half a period before `time_s`.
        if injected_at.is_none() && plant.time_s() + 0.5 * DT_S >= time_s {
            injected_at = Some(k);
        }
        let i = ctl.current_command_a(&plant);
        plant.advance(DT_S, i, &mut |_| {}).unwrap();
        let out = *ctl.last_output().unwrap();
        let faults = ctl.faults();
        let Some(k0) = injected_at else {
            assert!(
                faults.is_empty(),
                "{name}: fault before injection: {faults:?}"
            );
            k += 1;
            continue;
        };
        if latched_at.is_none() && faults.iter().any(|f| kind.detected_as().contains(&f.name)) {
            latched_at = Some(k);
            // Nothing latched before its time, and it is stamped with this period.
            let first = &faults[0];
            assert!(first.time_s + 0.5 * DT_S >= time_s, "{name}: {faults:?}");
        }
        if let Some(kl) = latched_at {
            assert_eq!(out.command, Command::SAFE, "{name}: period {k}");
            assert_eq!(out.dac_code, zero_code, "{name}: period {k}");
            assert!(!ctl.hal.amp_enabled(), "{name}: amplifier on in period {k}");
            assert_eq!(ctl.hal.commanded_current_a(), 0.0, "{name}: period {k}");
            if k >= kl + (WATCH_S / DT_S) as usize {
                break;
            }
        } else {
            assert!(
                k - k0 < max_latency_periods + 1,
                "{name}: not latched {} periods after injection (allowed {max_latency_periods}): {faults:?}",
                k - k0
            );
        }
        let p = plant.state().p_m;
        assert!(
            (0.0..=params.stroke_m).contains(&p),
            "{name}: nut at {p} m, outside its stops"
        );
        k += 1;
    }
    assert_eq!(
        ctl.max_abs_current_after_fault_a(),
        Some(0.0),
        "{name}: current after the fault"
    );
    let latency = latched_at.unwrap() - injected_at.unwrap();
    eprintln!("{name}: latched {latency} periods after injection");
    // The loop checks only the periods before the latch: the latching
    // period itself must be within the allowance too.
    assert!(
        latency <= max_latency_periods,
        "{name}: latched {latency} periods after injection (allowed {max_latency_periods})"
    );
    latency
}

#[test]
fn encoder_jump() {
    inject(InjectKind::EncoderJump, "open-torque", MID_STANCE_S, 1, 0);
}

#[test]
fn encoder_frozen() {
    // Late stance (nut at 0.14 m/s, motor 176 rad/s) and the flight return
    // (0.17 m/s up): no count at that speed is impossible, same period.
    inject(InjectKind::EncoderFrozen, "open-torque", 0.23, 1, 0);
    inject(InjectKind::EncoderFrozen, "open-torque", 0.35, 1, 0);
    // Early stance, motor below 100 rad/s: invisible until the nut has moved
    // 2.7 mm (30 N of spring force) past the frozen count.
    let l = inject(InjectKind::EncoderFrozen, "open-torque", 0.15, 1, 600);
    assert!(l > 0);
}

#[test]
fn loadcell_stuck() {
    // Invisible until the spring force has moved 30 N off the stuck value:
    // early stance, force rising.
    inject(InjectKind::LoadcellStuck, "open-torque", 0.15, 1, 40);
}

#[test]
fn loadcell_saturated() {
    inject(
        InjectKind::LoadcellSaturated,
        "open-torque",
        MID_STANCE_S,
        1,
        0,
    );
}

#[test]
fn pot_open() {
    inject(InjectKind::PotOpen, "open-torque", MID_STANCE_S, 1, 0);
}

#[test]
fn nan_after_conversion() {
    inject(InjectKind::Nan, "open-torque", MID_STANCE_S, 1, 0);
}

#[test]
fn noise_burst() {
    // Each burst sample misses both the range and the cross-check with a
    // few per cent probability: over 20 seeds, in flight and in stance.
    let mut worst = 0;
    for seed in 1..=20 {
        for t in [0.05, MID_STANCE_S] {
            worst = worst.max(inject(InjectKind::NoiseBurst, "open-torque", t, seed, 3));
        }
    }
    eprintln!("noise-burst: worst {worst} periods over 20 seeds");
}

#[test]
fn estop() {
    // A press counts after 0.2 ms pressed (`estop.press_s`): the second
    // period at 10 kHz.
    inject(InjectKind::Estop, "open-torque", MID_STANCE_S, 1, 1);
}

#[test]
fn amp_fault() {
    inject(InjectKind::AmpFault, "open-torque", MID_STANCE_S, 1, 0);
}

#[test]
fn dac_error() {
    inject(InjectKind::DacError, "open-torque", MID_STANCE_S, 1, 0);
}

#[test]
fn overrun() {
    inject(InjectKind::Overrun, "open-torque", MID_STANCE_S, 1, 0);
}

#[test]
fn in_flight_too() {
    // The flight PD is active: the same-period kinds latch in flight as well.
    for kind in InjectKind::ALL {
        if matches!(
            kind,
            InjectKind::EncoderFrozen | InjectKind::LoadcellStuck | InjectKind::NoiseBurst
        ) {
            continue;
        }
        // The e-stop's debounce: one period (see `estop`).
        let allowed = usize::from(kind == InjectKind::Estop);
        inject(kind, "energy-apex", 0.05, 1, allowed);
    }
}
