//! Arbitrary raw sensor words through the whole control period
//! (`hopper_control::runner::PeriodRunner`).
//!
//! libFuzzer's bytes are decoded with `arbitrary` into a
//! [`hopper_fuzz::Input`]: the strategy, the target apex, configuration
//! perturbations (the sensor-disagree check off, 32-bit counters, another
//! apex-loop gain), the control period and overrun limit for the runner's
//! `Timing` (chosen once per input; a refused timing or configuration just
//! returns), then a sequence of periods, each the four raw sensor words
//! (absolute, or steps from the last sample so the fuzzer gets past the
//! encoder-jump check into the laws), e-stop, amplifier fault, a failing
//! read, DAC write or enable write, an overrun report (`report_overrun`), a
//! change of target apex (`hopper_mut().set_target_apex`) and whether the
//! period was late (`end_period`). The logic and the asserted invariants
//! live in `fuzz/src/lib.rs` (`hopper_fuzz::run`):
//!
//! - no panic (libFuzzer reports one as a crash);
//! - the approved command is finite and within the supervisor's current limit;
//! - the DAC code is within the 12-bit range, and is the code the fake DAC
//!   received (when it accepted the write);
//! - a period with a latched fault commands 0 A, the zero-current code and
//!   the amplifier disabled, and every latched fault stays latched;
//! - the watchdog feed policy never starves: every period has
//!   `feed_watchdog`, and `Fault::SelfCheck` never latches.
//!
//! The same function runs on stable, without libFuzzer, under
//! `cargo test --manifest-path fuzz/Cargo.toml`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|input: hopper_fuzz::Input| {
    hopper_fuzz::run(&input);
});
