//! `panic-check`: proof that the control period cannot panic.
//!
//! This image runs [`PeriodRunner::new`] and [`PeriodRunner::run_period`]
//! on a configuration and sensor samples the optimiser cannot see through
//! (`core::hint::black_box`), and its panic handler calls a function that
//! exists nowhere. If any panic path (an out-of-bounds index, a failed
//! `unwrap`, a division by zero, a `clamp` with bad bounds, ...) is still
//! reachable after optimisation, the link fails with an undefined
//! `the_control_period_can_panic`. `cargo xtask test` builds it in release
//! for the MCU target (the same profile as the board image); it is never
//! flashed.
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(unsafe_code)]

/// Host stand-in: the check is the MCU link.
#[cfg(not(target_os = "none"))]
fn main() {
    println!(
        "panic-check is an MCU link test: build it with --target thumbv7em-none-eabihf --release"
    );
}

#[cfg(target_os = "none")]
mod check {
    use core::hint::black_box;
    use hopper_control::hal::{HopperIo, IoError, RawSample};
    use hopper_control::hopper::HopperConfig;
    use hopper_control::runner::{NoCounter, PeriodRunner, Timing};

    // The link needs defmt's linker script (`.cargo/config.toml` passes it
    // to every MCU image) and nothing else of it.
    use defmt as _;
    // The interrupt vector table (cortex-m-rt's `device` feature wants one).
    use stm32f4 as _;

    /// Samples and write results the optimiser must treat as unknown.
    struct OpaqueIo;

    impl HopperIo for OpaqueIo {
        type Error = ();
        fn read(&mut self) -> Result<RawSample, IoError<()>> {
            black_box(Ok(RawSample::default()))
        }
        fn write_dac(&mut self, code: u16) -> Result<(), IoError<()>> {
            black_box(code);
            black_box(Ok(()))
        }
        fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<()>> {
            black_box(on);
            black_box(Ok(()))
        }
    }

    #[cortex_m_rt::entry]
    fn main() -> ! {
        let cfg = black_box(HopperConfig::default());
        let timing = black_box(Timing::default());
        if let Ok(mut runner) = PeriodRunner::new(cfg, timing) {
            loop {
                let p = runner.run_period(&mut OpaqueIo, &mut NoCounter);
                black_box(p);
                runner.end_period(black_box(false));
            }
        }
        loop {
            cortex_m::asm::nop();
        }
    }

    #[panic_handler]
    fn panic(_: &core::panic::PanicInfo) -> ! {
        extern "Rust" {
            // Defined nowhere: referencing it makes any reachable panic a
            // link error.
            fn the_control_period_can_panic() -> !;
        }
        // SAFETY: never executed; the link fails before if it is reachable.
        #[allow(unsafe_code)]
        unsafe {
            the_control_period_can_panic()
        }
    }
}
