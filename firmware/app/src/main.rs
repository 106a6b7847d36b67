//! `hopper-fw`: the RTIC 2 controller firmware for the hopper, on an STM32F405.
//!
//! Build it with `cargo build -p hopper-app --release --target thumbv7em-none-eabihf`
//! (`cargo run` with that target runs it on QEMU's `netduinoplus2`, see
//! `.cargo/config.toml`). On the host this crate compiles to a stub `main`
//! that says so, which keeps `cargo clippy --workspace --all-targets` working.
//!
//! # Clock
//! The core runs from the 16 MHz HSI oscillator, the reset default, with no
//! PLL: QEMU does not model the RCC, so the firmware must not wait for PLL
//! lock. SysTick counts core clock cycles.
//!
//! # Pins
//! | Pin | Direction          | Signal                                 | Safe state            |
//! |-----|--------------------|----------------------------------------|-----------------------|
//! | PB0 | output, push-pull  | `AMP_EN`, servo amplifier enable, active high | low (amplifier off) |
//!
//! `AMP_EN` needs an external pull-down on the board: between reset and
//! `init` (and if a panic happens before `init`) the pin is a floating input.
//!
//! # Tasks
//! | Task      | Priority | Trigger                                   |
//! |-----------|----------|-------------------------------------------|
//! | `control` | 3 (highest software priority) | SysTick monotonic, every `1 / CONTROL_HZ` s |
//! | `idle`    | 0        | busy loop                                 |
//!
//! For now `control` only runs a [`hopper_control::filter::FilteredDerivative`]
//! on a zero input and counts periods; the amplifier stays disabled. The
//! control step (estimator, control laws, supervisor), the HAL I/O (encoders,
//! ADC, DAC command) and the QEMU-side plant come in later issues.
//!
//! # Panics
//! The panic handler first drives `AMP_EN` low through the PAC, then masks
//! interrupts, drives it low again (in case a preempting task re-enabled it in
//! between) and spins forever.
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(unsafe_code)]

/// Host stand-in: this binary only does something on the microcontroller.
#[cfg(not(target_os = "none"))]
fn main() {
    println!("hopper-fw is firmware: build it with --target thumbv7em-none-eabihf");
}

/// Control loop rate in Hz (build-time constant); also the SysTick tick rate.
#[cfg(target_os = "none")]
const CONTROL_HZ: u32 = 10_000;

/// Core clock in Hz: the HSI oscillator, no PLL.
#[cfg(target_os = "none")]
const SYSCLK_HZ: u32 = 16_000_000;

/// Control period in seconds, `1 / CONTROL_HZ`.
#[cfg(target_os = "none")]
#[allow(clippy::cast_precision_loss)] // 10_000 is exact in f32.
const CONTROL_PERIOD_S: f32 = 1.0 / CONTROL_HZ as f32;

// `Mono::start` panics unless SysTick can tick at exactly CONTROL_HZ with a
// 24-bit reload of at least 1: check that here so it cannot happen at run time.
#[cfg(target_os = "none")]
const _: () = assert!(
    SYSCLK_HZ.is_multiple_of(CONTROL_HZ)
        && SYSCLK_HZ / CONTROL_HZ >= 2
        && SYSCLK_HZ / CONTROL_HZ - 1 <= 0x00FF_FFFF
);

#[cfg(target_os = "none")]
rtic_monotonics::systick_monotonic!(Mono, CONTROL_HZ);

/// Drives the amplifier-enable pin (PB0) low with one atomic BSRR write.
///
/// Usable from any context, including the panic handler: it needs no owned
/// peripheral. If GPIOB is not clocked yet the write is ignored and the
/// external pull-down keeps the amplifier off.
#[cfg(target_os = "none")]
fn disable_amplifier() {
    // SAFETY: `GPIOB::ptr()` is the fixed address of the GPIOB register block.
    // Writing BSRR only resets the pins whose BR bits are 1 (here PB0) and is a
    // single store, so it cannot race with other users of GPIOB.
    #[allow(unsafe_code)] // Needed to reach GPIOB without owning it (panic path).
    let gpiob = unsafe { &*stm32f4::stm32f405::GPIOB::ptr() };
    gpiob.bsrr().write(|w| w.br0().set_bit());
}

/// Panic: disable the amplifier before anything else, then stop.
#[cfg(target_os = "none")]
#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    disable_amplifier();
    cortex_m::interrupt::disable();
    disable_amplifier();
    loop {
        cortex_m::asm::nop();
    }
}

/// The RTIC application.
#[cfg(target_os = "none")]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true, dispatchers = [FSMC])]
mod app {
    use super::{Mono, CONTROL_PERIOD_S, SYSCLK_HZ};
    use hopper_control::filter::FilteredDerivative;
    use rtic_monotonics::systick::prelude::*;

    /// Filter gain `G` of thesis eq 4.1 for the placeholder velocity estimate.
    const VELOCITY_FILTER_GAIN: f32 = 0.9;

    /// The placeholder velocity filter, validated at compile time.
    const VELOCITY_FILTER: FilteredDerivative = match FilteredDerivative::new(VELOCITY_FILTER_GAIN)
    {
        Ok(filter) => filter,
        Err(_) => panic!("VELOCITY_FILTER_GAIN must be in [0, 1)"),
    };

    /// Resources shared between tasks (none yet).
    #[shared]
    struct Shared {}

    /// Resources owned by one task.
    #[local]
    struct Local {
        /// Velocity estimate of the (for now zero) measured motor angle.
        velocity: FilteredDerivative,
        /// Amplifier current command in A; 0 until the HAL drives the DAC.
        command_a: f32,
    }

    /// Puts the amplifier in its safe state, starts SysTick and the control task.
    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;

        // AMP_EN (PB0): clock GPIOB, latch the output low, then make it an output,
        // so the pin never drives high.
        dp.RCC.ahb1enr().modify(|_, w| w.gpioben().enabled());
        // Read back: errata "delay after an RCC peripheral clock enabling" (ES0182).
        let _ = dp.RCC.ahb1enr().read();
        dp.GPIOB.bsrr().write(|w| w.br0().set_bit());
        dp.GPIOB.otyper().modify(|_, w| w.ot0().push_pull());
        dp.GPIOB.moder().modify(|_, w| w.moder0().output());

        // Cannot panic: the compile-time assert above checks the reload value.
        Mono::start(cx.core.SYST, SYSCLK_HZ);

        // The first spawn of a task that is not running cannot fail; if it
        // did, no control task would run and the amplifier would stay off.
        if control::spawn().is_err() {
            super::disable_amplifier();
        }

        (
            Shared {},
            Local {
                velocity: VELOCITY_FILTER,
                command_a: 0.0,
            },
        )
    }

    /// Background loop. No `wfi`: QEMU 7.2 loses SysTick ticks while sleeping.
    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::nop();
        }
    }

    /// Periodic control task at `CONTROL_HZ`, released by the SysTick monotonic
    /// on an absolute schedule (`delay_until`), so the period does not drift.
    ///
    /// Placeholder: filters a zero input and counts periods (and overruns:
    /// periods whose work ended after the next release time). The control
    /// step, HAL I/O and QEMU plant come in later issues.
    #[task(priority = 3, local = [velocity, command_a, periods: u32 = 0, overruns: u32 = 0])]
    async fn control(cx: control::Context) {
        let period = <Mono as Monotonic>::Duration::from_ticks(1);
        let mut release = Mono::now();
        loop {
            release += period;

            // A constant, finite input with a positive period cannot fail.
            let _ = cx.local.velocity.update(0.0, CONTROL_PERIOD_S);
            *cx.local.command_a = 0.0;
            *cx.local.periods = cx.local.periods.wrapping_add(1);

            if Mono::now() >= release {
                *cx.local.overruns = cx.local.overruns.wrapping_add(1);
            }
            Mono::delay_until(release).await;
        }
    }
}
