//! Portable control code for the electrically actuated one-legged hopper.
//!
//! This crate is the part of the controller firmware that does not know which
//! machine it runs on. It is `#![no_std]`, allocation-free and panic-free, works
//! in `f32` SI units (names carry unit suffixes: `_m`, `_mps`, `_n`, `_nm`,
//! `_rad`, `_s`, `_a`), and is compiled both into the STM32F405 firmware
//! (`hopper-app`) and into host-side simulations and tests.
//!
//! Equation numbers refer to the thesis (`thesis.md`); where it is ambiguous
//! or wrong, `MODEL.md` records the reading used here.
//!
//! Contents (every module this file declares):
//! - [`hal`]: the I/O trait ([`hal::HopperIo`]) the board and the simulator implement;
//! - [`calibration`]: raw counts and codes to SI, current to DAC code;
//! - [`filter`]: the filtered derivative of thesis eq 4.1;
//! - [`estimator`]: flight/stance phase, touchdown, liftoff, apex, bottom,
//!   and the filtered velocities;
//! - [`energy`]: the energy estimate of eqs 2.44-2.45;
//! - [`model`]: the parameters the controller believes and `E_D` (eq 2.43);
//! - [`params`]: every runtime parameter defined once (name, unit, range,
//!   default, live or not, doc), read and written by name;
//! - [`laws`]: every controller as a type (passive, each thesis stance law
//!   with the flight PD of eq 4.4, energy-apex, shaped) behind one enum;
//! - [`pd_design`]: flight PD gain design (eqs 4.3-4.18);
//! - [`supervisor`]: latched faults and the current clamp;
//! - [`thermal`]: the motor's winding temperature estimated from the
//!   commanded current: derate, then fault;
//! - [`debounce`]: the e-stop input, debounced;
//! - [`arming`]: whether the operator asked for motion, the gate on every
//!   period's output;
//! - [`bringup`]: the routines run on command while disarmed (sensor check,
//!   tare, height zero, direction check, homing, spring sweep, weight);
//! - [`telemetry`]: the per-step record, the capture that keeps the last of
//!   them (frozen around a fault) and the per-hop energy ledger;
//! - [`hopper`]: the control step, [`hopper::Hopper::step`];
//! - [`runner`]: the one period runner the board, QEMU and the host share;
//! - [`watchdog`]: when the period may feed the hardware watchdog;
//! - [`deadman`]: the hardware deadman on the amplifier enable, its
//!   retrigger logic;
//! - [`persist`]: the saved calibration as one self-checking record;
//! - [`boot`]: what the board found at boot (reset cause, brown-out reset,
//!   clock);
//! - [`selftest`]: the on-target self-test on the loopback harness;
//! - `num` (crate-private): `f32` clamp and max by plain comparison for
//!   the Cortex-M4F;
//! - `proptest_support` (crate-private, tests only): the property tests'
//!   runner and case count.
#![no_std]
// Panic-free, enforced: no indexing that can go out of bounds, no explicit
// panics, no unwrap/expect outside the tests. The `panic-never` check in
// `cargo xtask test` links the control step with a panic handler that does
// not exist, so a panic path anywhere in it fails the build.
#![cfg_attr(
    not(test),
    deny(
        clippy::indexing_slicing,
        clippy::panic,
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented
    )
)]

pub mod arming;
pub mod boot;
pub mod bringup;
pub mod calibration;
pub mod config;
pub mod deadman;
pub mod debounce;
pub mod energy;
pub mod estimator;
pub mod filter;
pub mod hal;
pub mod hopper;
pub mod laws;
pub mod model;
pub mod param;
pub mod params;
pub mod pd_design;
pub mod persist;
pub mod planar;
pub mod runner;
pub mod selftest;
pub mod supervisor;
pub mod telemetry;
pub mod thermal;
pub mod watchdog;

/// `f32` limits by plain comparison, for the control step. The Cortex-M4F
/// has no `VMAXNM`/`VMINNM` (those are ARMv8), so `f32::max` and `f32::min`
/// become library calls there (a call, NaN tests and a return each, about
/// nine of them per period before), and `f32::clamp` asserts its bounds (a
/// panic path). These compile to a compare and a conditional move.
pub(crate) mod num {
    /// `x` limited to `lo..=hi` (for `lo <= hi`); a NaN `x` stays NaN.
    #[inline(always)]
    pub fn clamp(x: f32, lo: f32, hi: f32) -> f32 {
        if x < lo {
            lo
        } else if x > hi {
            hi
        } else {
            x
        }
    }

    /// The larger of `x` and `y` (`y` not NaN); a NaN `x` gives `y`, as
    /// `f32::max` does.
    #[inline(always)]
    pub fn max(x: f32, y: f32) -> f32 {
        if x > y {
            x
        } else {
            y
        }
    }
}

/// Property-test plumbing shared by the modules' tests (host only).
#[cfg(test)]
pub(crate) mod proptest_support {
    extern crate std;

    use core::cell::Cell;
    use proptest::strategy::Strategy;
    use proptest::test_runner::{Config, TestCaseError, TestError, TestRunner};

    /// A hopper at rest in flight at the origin, as `cal` reads it: nut on
    /// its stop, the spring at the default model's preload.
    pub fn rest_sample(cal: &crate::calibration::Calibration) -> crate::hal::RawSample {
        crate::hal::RawSample::at_rest(cal)
    }

    /// Cases per property in the default run: the minimum the project sets
    /// for every property (proptest's own default is 256).
    pub const MIN_CASES: u32 = 10_000;

    /// Cases per property: `HOPPER_PROPTEST_CASES` when set, else
    /// proptest's own `PROPTEST_CASES` when set, else [`MIN_CASES`]. A set
    /// value wins either way, so a quick local run can lower the count
    /// (`PROPTEST_CASES=200 cargo test`) as well as a long one raise it.
    /// `HOPPER_PROPTEST_CASES` comes first because it names these properties
    /// only: an environment that sets `PROPTEST_CASES` low for other crates
    /// can still pin these at 10 000 or more with it. A value that is not a
    /// positive integer counts as not set (0 cases would pass vacuously).
    pub fn cases() -> u32 {
        let from_env = |key: &str| {
            std::env::var(key)
                .ok()
                .and_then(|v| v.trim().parse::<u32>().ok())
                .filter(|n| *n > 0)
        };
        from_env("HOPPER_PROPTEST_CASES")
            .or_else(|| from_env("PROPTEST_CASES"))
            .unwrap_or(MIN_CASES)
    }

    /// Runs `test` on [`cases`] values of `strategy`, reports the number of
    /// cases that ran (`cargo test -- --nocapture` shows it) and returns it.
    /// The runner is driven by hand rather than by `proptest!` so the count
    /// can be checked and printed after the run.
    pub fn run<S: Strategy>(
        name: &str,
        strategy: S,
        test: impl Fn(S::Value) -> Result<(), TestCaseError>,
    ) -> Result<u32, TestError<S::Value>> {
        let wanted = cases();
        let config = Config {
            cases: wanted,
            // No regression files: the crate is `no_std` and proptest cannot
            // find a source file to sit them next to; a failure prints its
            // minimal input instead.
            failure_persistence: None,
            ..Config::default()
        };
        let ran = Cell::new(0_u32);
        TestRunner::new(config).run(&strategy, |v| {
            ran.set(ran.get() + 1);
            test(v)
        })?;
        // Successful cases only count once the whole run passed; shrinking
        // never happens on a passing run, so `ran` is the case count.
        std::println!("property {name}: {} cases passed", ran.get());
        assert!(
            ran.get() >= wanted,
            "{name}: only {} of {wanted} cases ran",
            ran.get()
        );
        Ok(ran.get())
    }
}
