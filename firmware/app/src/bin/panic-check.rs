//! `panic-check`: proof that the control period cannot panic.
//!
//! This image runs [`PeriodRunner::new`] and [`PeriodRunner::run_period`]
//! on a configuration and sensor samples the optimiser cannot see through
//! (`core::hint::black_box`), then everything else that runs at the
//! control priority or above: the control port (the capture's record, the
//! period's note, a command applied) and the USART interrupt's handler;
//! and, though it runs below, the link task that prepares the commands
//! (decoding arbitrary host bytes, every answer, sets and their
//! controllers, dumps) on a transmit queue of unknown room, so the
//! commands the port applies are any the host can cause. Its panic
//! handler calls a function that
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

/// The board's USART transport, as the image builds it.
#[cfg(target_os = "none")]
#[path = "../serial.rs"]
#[allow(dead_code)]
mod serial;

/// The board's pin map (the link's USART and pins), as the image builds it.
#[cfg(target_os = "none")]
#[path = "../pinmap.rs"]
#[allow(dead_code, unused_macros, unused_imports)]
mod pinmap;

#[cfg(target_os = "none")]
mod check {
    use core::hint::black_box;
    use hopper_control::hal::{HopperIo, IoError, RawSample};
    use hopper_control::hopper::HopperConfig;
    use hopper_control::runner::{NoCounter, PeriodRunner, Timing};
    use hopper_control::telemetry::{FaultCapture, CAPTURE_LEN};
    use hopper_robot_link::{ControlPort, Endpoint, Queues, Tx};

    // The link needs defmt's linker script (`.cargo/config.toml` passes it
    // to every MCU image) and nothing else of it.
    use defmt as _;
    // The interrupt vector table (cortex-m-rt's `device` feature wants one).
    use stm32f4::stm32f405 as pac;
    // The image's critical section (BASEPRI), which `Peripherals::take`
    // takes.
    use hopper_app as _;

    use super::serial;

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
        // Every byte the host may send is unknown here.
        let mut capture: FaultCapture<CAPTURE_LEN> = FaultCapture::new();
        let mut queues = Queues::new();
        let mut port = ControlPort::new();
        let mut rxq = serial::RxQueue::new();
        let mut txq = serial::TxQueue::new();
        let (rx_in, mut rx_out) = rxq.split();
        let (tx_in, tx_out) = txq.split();
        let (Ok(mut runner), Some(dp)) = (PeriodRunner::new(cfg, timing), pac::Peripherals::take())
        else {
            loop {
                cortex_m::asm::nop();
            }
        };
        let (_, link_usart) = crate::take_deadman_and_link!(dp);
        let mut usart = serial::Serial::new(
            link_usart,
            &dp.RCC,
            &dp.GPIOA,
            &dp.GPIOB,
            black_box(16_000_000),
            rx_in,
            tx_out,
        );
        let mut link_tx = serial::LinkTx::new(tx_in);
        let mut link = Endpoint::new(&runner);
        loop {
            // Priority 4: the USART's bytes in and out.
            usart.on_interrupt();
            // Priority 3: the control period and its port.
            let p = runner.run_period(&mut OpaqueIo, &mut NoCounter);
            port.after_period(
                &mut runner,
                &p,
                &mut capture,
                &mut queues.commands,
                &mut queues.answers,
                &mut queues.notes,
                &mut queues.stats,
                &mut queues.logs,
            );
            port.add_isr_cost(black_box(0));
            black_box(port.restart_due(&mut runner));
            black_box(&p);
            runner.end_period(black_box(false));
            // Priority 2: the link task, on arbitrary bytes and a transmit
            // queue of unknown room.
            let mut rx = core::iter::from_fn(|| black_box(rx_out.dequeue())).take(black_box(64));
            link.service(
                &mut queues.notes,
                &mut queues.stats,
                &mut queues.logs,
                &mut queues.answers,
                &mut queues.commands,
                &mut rx,
                &mut &mut capture,
                &mut OpaqueTx,
                &mut NoCounter,
            );
            black_box(&mut link_tx);
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
