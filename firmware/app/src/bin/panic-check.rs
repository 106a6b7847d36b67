//! `panic-check`: proof that the control period cannot panic.
//!
//! This image runs [`PeriodRunner::new`] and [`PeriodRunner::run_period`]
//! on a configuration and sensor samples the optimiser cannot see through
//! (`core::hint::black_box`), then what runs with it at the control
//! priority: the fault capture's record and the link endpoint's
//! `service` (decoding arbitrary host bytes, every answer, dumps) on a
//! transmit queue of unknown room. Its panic handler calls a function that
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
    use hopper_control::link::{Endpoint, Tx};
    use hopper_control::runner::{NoCounter, PeriodRunner, Timing};
    use hopper_control::telemetry::{FaultCapture, CAPTURE_LEN};

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

    /// A transmit queue whose room the optimiser cannot see.
    struct OpaqueTx;

    impl Tx for OpaqueTx {
        fn room(&self) -> usize {
            black_box(256)
        }
        fn put(&mut self, frame: &[u8]) {
            black_box(frame);
        }
    }

    #[cortex_m_rt::entry]
    fn main() -> ! {
        let cfg = black_box(HopperConfig::default());
        let timing = black_box(Timing::default());
        // The capture and the link's endpoint run at the control priority
        // too (the capture records, the endpoint answers the host in the
        // same interrupt): every byte the host may send is unknown here.
        let mut capture: FaultCapture<CAPTURE_LEN> = FaultCapture::new();
        let mut link = Endpoint::new();
        if let Ok(mut runner) = PeriodRunner::new(cfg, timing) {
            loop {
                let p = runner.run_period(&mut OpaqueIo, &mut NoCounter);
                capture.record(&p.out.record, !p.newly_latched.is_empty());
                let mut rx = core::iter::from_fn(|| black_box(Some(0u8))).take(black_box(64));
                link.service(
                    &mut runner,
                    &p,
                    &mut rx,
                    &mut capture,
                    &mut OpaqueTx,
                    &mut NoCounter,
                );
                black_box(&p);
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
