//! `hopper-selftest`: the on-target self-test image: the board's `init`,
//! then the loopback harness checks of [`hopper_control::selftest`] instead
//! of the controller (docs/board.md, "Self-test"). Never with the
//! amplifier connected.
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(unsafe_code)]

/// Host stand-in: this binary only does something on the microcontroller.
#[cfg(not(target_os = "none"))]
fn main() {
    println!("hopper-selftest is firmware: build it with --target thumbv7em-none-eabihf");
}

#[cfg(target_os = "none")]
use defmt_rtt as _;

// Board logs carry the time since boot (the QEMU log stays bare: the xtask
// parses its lines).
#[cfg(target_os = "none")]
defmt::timestamp!("{=u32:us}", hopper_app::log::now_us());

#[cfg(target_os = "none")]
hopper_app::fault_handlers!(hopper_app::park);

/// The on-target self-test (`hopper-selftest`): the board's `init`,
/// then one [`hopper_control::selftest`] step per control period on the
/// loopback harness (docs/board.md, "Self-test"), the verdicts over defmt.
/// The harness is the H405 map's (PC6-PC12): on the Feather's map those
/// pins carry the motor encoder and the microSD card, so there the image
/// only says so and parks (below).
#[cfg(all(target_os = "none", not(feature = "feather")))]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true)]
mod app {
    use hopper_app::board::{self, BoardIo, Watchdog};
    use hopper_app::control::CONTROL_HZ;
    use hopper_app::serial::{RxQueue, TxQueue};
    use hopper_control::hal::HopperIo;
    use hopper_control::hopper::HopperConfig;
    use hopper_control::selftest::{Inputs, SelfTest};
    use stm32f4::stm32f405 as pac;

    #[shared]
    struct Shared {}

    #[local]
    struct Local {
        io: BoardIo,
        watchdog: Watchdog,
        test: SelfTest,
    }

    #[init(local = [rxq: RxQueue = RxQueue::new(), txq: TxQueue = TxQueue::new()])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let zero = HopperConfig::default().calibration.dac_zero_code;
        let (rx_in, _rx_out) = cx.local.rxq.split();
        let (_tx_in, tx_out) = cx.local.txq.split();
        let board = board::init(cx.device, CONTROL_HZ, zero, (rx_in, tx_out));
        harness_pins();
        defmt::info!(
            "hopper-fw self-test ({=str}): unplug the amplifier; the loopback harness of docs/board.md",
            board::CLOCK_PROFILE
        );
        // What init found: the clock, the crystal, the saved calibration.
        let b = board.boot;
        defmt::info!(
            "selftest: core clock {=u32} Hz (as configured: {=bool}), crystal {=u32} Hz measured against the HSI (profile {=u32} Hz), brown-out reset on: {=bool}, a saved calibration: {=bool}",
            b.sysclk_hz,
            b.clock_as_configured,
            b.hse_measured_hz,
            b.hse_expected_hz,
            b.brown_out_reset_on,
            board.stored.len.is_some()
        );
        (
            Shared {},
            Local {
                io: board.io,
                watchdog: board.watchdog,
                test: SelfTest::new(zero),
            },
        )
    }

    /// PC6..PC10 push-pull outputs, low (quadrature for both encoders, the
    /// probe); PC11, PC12 inputs with pull-downs (the probe's and AMP_EN's
    /// loopbacks: an open harness reads low).
    #[allow(unsafe_code)] // GPIOC belongs to the board (PC13, the hip encoder's PC6/PC7); the self-test takes these pins.
    fn harness_pins() {
        // SAFETY: GPIOC's other users are PC13 (an input the self-test
        // does not use) and the hip encoder's PC6/PC7 (TIM8 inputs the
        // self-test never reads; it makes them outputs, as the harness
        // wires them); the writes below touch PC6..PC12 alone.
        let gpioc = unsafe { &*pac::GPIOC::ptr() };
        gpioc
            .bsrr()
            .write(|w| unsafe { w.bits(0b11111 << (6 + 16)) });
        gpioc.moder().modify(|r, w| unsafe {
            let mut m = r.bits() & !(0x3FFF << 12);
            for pin in 6..=10 {
                m |= 0b01 << (2 * pin);
            }
            w.bits(m)
        });
        gpioc.pupdr().modify(|r, w| unsafe {
            w.bits((r.bits() & !(0xF << 22)) | (0b10 << 22) | (0b10 << 24))
        });
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::nop();
        }
    }

    /// One step per period, with fresh ADC samples; the watchdog fed as by
    /// the controller.
    #[task(binds = ADC, priority = 3, local = [io, watchdog, test, reported: bool = false])]
    #[allow(unsafe_code)] // GPIOC's harness pins (see `harness_pins`).
    fn control(cx: control::Context) {
        if !cx.local.io.ack_control_irq() {
            return;
        }
        cx.local.watchdog.feed();
        let Ok(sample) = cx.local.io.read() else {
            // (Infallible on the board: its reads are register reads.)
            return;
        };
        // SAFETY: as in `harness_pins`.
        let gpioc = unsafe { &*pac::GPIOC::ptr() };
        let idr = gpioc.idr().read().bits();
        let test = &mut *cx.local.test;
        let o = test.period(&Inputs {
            sample,
            harness_in: idr & (1 << 11) != 0,
            amp_loop_in: idr & (1 << 12) != 0,
        });
        let _ = cx.local.io.write_dac(o.dac_code);
        let _ = cx.local.io.set_amp_enabled(o.amp_enable);
        let bit = |on: bool, pin: u32| if on { 1 << pin } else { 1 << (pin + 16) };
        let bsrr = bit(o.motor_ab.0, 6)
            | bit(o.motor_ab.1, 7)
            | bit(o.height_ab.0, 8)
            | bit(o.height_ab.1, 9)
            | bit(o.probe, 10);
        gpioc.bsrr().write(|w| unsafe { w.bits(bsrr) });
        if test.done() && !*cx.local.reported {
            *cx.local.reported = true;
            for v in test.verdicts() {
                defmt::info!(
                    "selftest: {} {=str}: measured {=i32}, expected {=i32}",
                    v.check,
                    if v.passed { "PASS" } else { "FAIL" },
                    v.measured,
                    v.expected
                );
            }
            if test.passed() {
                defmt::info!("selftest: all checks passed");
            } else {
                defmt::error!("selftest: FAILED (docs/board.md, \"Self-test\")");
            }
        }
    }
}

/// The Feather's map has no loopback harness: AMP_EN stays low (it floats
/// to the external pull-down until driven), the log says why, and the
/// image parks.
#[cfg(all(target_os = "none", feature = "feather"))]
#[cortex_m_rt::entry]
fn main() -> ! {
    hopper_app::disable_amplifier();
    defmt::error!(
        "hopper-selftest: no loopback harness on the feather pin map (its PC6-PC12 carry the motor encoder and the microSD card): build it without `feather`"
    );
    hopper_app::park()
}
