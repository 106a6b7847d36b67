//! `hopper-fw`: the RTIC 2 controller firmware for the hopper on an
//! STM32F405 board. It runs the control period
//! ([`hopper_control::runner::PeriodRunner`], which the host simulator and
//! the QEMU images run too). A hardware timer (the pin map's control timer) triggers the ADC's
//! injected conversions at `CONTROL_HZ`; their end-of-conversion interrupt
//! runs the control task with fresh samples; the host link on USART1; the
//! saved calibration in flash ([`hopper_app::flash`]). See
//! [`hopper_app::board`] for clocks, pins and the watchdog. Two variants:
//! `--features hse-12mhz` for boards with a 12 MHz crystal (the same image,
//! other PLL constants), and `--features fault-test` for `cargo xtask
//! board-init`, which moves the stack pointer off the SRAM after init to
//! exercise the HardFault entry (never for a board). The other images are
//! the library's other binaries (`hopper_app`'s crate docs).
//!
//! # Tasks
//! | Task      | Priority | Trigger |
//! |-----------|----------|---------|
//! | `usart1`  | 4        | USART1 (the host link's bytes; board; 3 in the QEMU link image, whose USART has no baud rate) |
//! | `control` | 3        | board: ADC injected end of conversion (the control timer at `CONTROL_HZ`); QEMU: SysTick at `CONTROL_HZ` |
//! | `link`    | 2        | SDIO (spare), pended by `control` every period: decode, answer, encode, build sets (board and QEMU link image) |
//! | `logger`  | 1        | CAN2_RX1 (spare), pended by `control` when it queues a log item (hop ledgers, faults) or the dump button asks for the capture; its log frames' critical section masks priorities 1-2 only (BASEPRI) |
//! | `idle`    | 0        | busy loop (no `wfi`: QEMU 7.2 loses SysTick ticks while sleeping) |
//!
//! # Safety
//! At reset the amplifier-enable pin (PB0) floats and the external pull-down
//! keeps the amplifier off; `init` drives it low before anything else. The
//! panic handler and the HardFault handler drive it low first thing.
//! The period runner starts disarmed (`hopper_control::arming`): the board
//! image writes 0 A with the amplifier off until the host link arms it
//! (`hopper-link arm`; among its checks a live link, a tare or a saved
//! calibration, and homing since boot), so a freshly flashed board moves
//! the motor only when the host asks: an arm, or a motor-driving bring-up
//! routine (`hopper-link calibrate`, disarmed, at up to
//! `bringup.current_limit_a`). The QEMU scenario image's scenario arms
//! once, untethered, at the first period.
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(unsafe_code)]

/// Host stand-in: this binary only does something on the microcontroller.
#[cfg(not(target_os = "none"))]
fn main() {
    println!("hopper-fw is firmware: build it with --target thumbv7em-none-eabihf");
}

#[cfg(target_os = "none")]
use defmt_rtt as _;

// Board logs carry the time since boot (the QEMU log stays bare: the xtask
// parses its lines).
#[cfg(target_os = "none")]
defmt::timestamp!("{=u32:us}", hopper_app::log::now_us());

#[cfg(target_os = "none")]
hopper_app::fault_handlers!(hopper_app::park);

/// The fault test (`--features fault-test`, `cargo xtask board-init`).
#[cfg(all(target_os = "none", feature = "fault-test"))]
mod fault_test {
    /// The deadman as an enabled period leaves it (the counter running,
    /// the channel in PWM mode 2, AMP_EN high), so that the fault entry
    /// has an enabled channel to force inactive.
    pub fn enable_deadman() {
        #[allow(unsafe_code)] // The test's own handle; the control task never runs in it.
        // SAFETY: in the fault test the control task never runs (QEMU models
        // no injected ADC), and this path ends in the fault.
        let timer = unsafe { hopper_app::pinmap::DeadmanRegs::steal() };
        let _ = hopper_control::deadman::Deadman::resume(timer).set(true);
    }

    /// Moves the main stack pointer below the SRAM (where a stack that
    /// flip-link put below the statics overflows to) and executes an
    /// undefined instruction: the exception's entry cannot stack, and the
    /// HardFault entry must drop AMP_EN and zero the DAC without the stack.
    pub fn hard_fault_off_the_stack() -> ! {
        #[allow(unsafe_code)] // The fault is the test.
        // SAFETY: it does not return; the fault handler parks.
        unsafe {
            core::arch::asm!("msr msp, {0}", "udf #0", in(reg) 0x1FFF_FF00u32, options(noreturn));
        }
    }
}

/// The board application.
#[cfg(target_os = "none")]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true)]
mod app {
    use cortex_m::peripheral::NVIC;
    use hopper_app::board::{self, BoardIo, CycleCounter, DumpButton, Watchdog};
    use hopper_app::control::{Bank, Capture, Locked, Slot, CONTROL_HZ, TIMING};
    use hopper_app::log::{self, Log};
    use hopper_app::serial::{LinkTx, RxOut, RxQueue, Serial, TxQueue};
    use hopper_control::hopper::HopperConfig;
    use hopper_robot_link::{ControlLoop, Endpoint, LinkEnds, PortEnds, Queues};
    use stm32f4::stm32f405::Interrupt;

    /// The link task's interrupt: a spare one (the SD card interface is
    /// not used), pended by the control task every period.
    const LINK_IRQ: Interrupt = Interrupt::SDIO;
    /// The logger task's vector: an unused peripheral's (never the FPU's,
    /// which floating-point exceptions pend).
    const LOGGER_IRQ: Interrupt = Interrupt::CAN2_RX1;

    /// The link task's own cycles (the control task's and the serial
    /// interrupt's that preempt it left out).
    struct LinkCycles;

    impl hopper_control::runner::CycleCounter for LinkCycles {
        fn now(&mut self) -> u32 {
            hopper_app::serial_cost::below_control(cortex_m::peripheral::DWT::cycle_count)
        }
    }

    #[shared]
    struct Shared {
        /// The capture, frozen around the first fault: a static built in
        /// place (32 KiB: built in `init` and moved, it would be most of
        /// `init`'s stack peak).
        capture: &'static mut Capture,
    }

    #[local]
    struct Local {
        io: BoardIo,
        watchdog: Watchdog,
        dump: DumpButton,
        firmware: ControlLoop<Slot>,
        cycles: CycleCounter,
        log: Log,
        log_rx: log::Receiver,
        port_queues: PortEnds<'static, Slot>,
        link: Endpoint<Slot>,
        link_cycles: LinkCycles,
        link_queues: LinkEnds<'static, Slot>,
        link_rx: RxOut<'static>,
        link_tx: LinkTx<'static>,
        #[cfg(not(feature = "feather"))]
        serial: Serial<'static>,
        #[cfg(feature = "feather")]
        serial3: Serial<'static>,
    }

    #[init(local = [
        rxq: RxQueue = RxQueue::new(),
        txq: TxQueue = TxQueue::new(),
        capture: Capture = Capture::new(),
        log_queue: log::LogQueue = log::LogQueue::new(),
        queues: Queues<Slot> = Queues::new(),
        bank: Bank = [None, None, None],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let mut cfg = HopperConfig::default();
        // The pin map's encoder counters (32 bits on the H405, 16 on the Feather).
        cfg.calibration.motor_counter_bits = board::ENCODER_COUNTER_BITS;
        cfg.calibration.height_counter_bits = board::ENCODER_COUNTER_BITS;
        // The calibration offsets are placeholders until a tare or a saved
        // calibration loads, and the incremental motor encoder boots
        // wherever the nut stands: no arming before both.
        cfg.arming.require_tare = true;
        cfg.arming.require_home = true;
        // The fault test's calibrated zero: the fault handlers must write
        // this one, not the 2048 fixed before the calibration loads.
        #[cfg(feature = "fault-test")]
        {
            cfg.calibration.dac_zero_code = 2050;
        }
        // Validated before the board (and its watchdog) starts: a refused
        // configuration leaves the amplifier off (the pin is an input with
        // its external pull-down) and the MCU parked, not in a reset loop.
        let (mut runner, spares) =
            match hopper_app::control::runner_in_bank(cx.local.bank, cfg, TIMING) {
                Ok(r) => r,
                Err(e) => {
                    hopper_app::disable_amplifier();
                    defmt::error!(
                        "invalid controller configuration ({}): amplifier stays off",
                        e
                    );
                    loop {
                        cortex_m::asm::nop();
                    }
                }
            };
        let mut core = cx.core;
        let mut cycles = CycleCounter::start(&mut core.DCB, &mut core.DWT);
        let (rx_in, rx_out) = cx.local.rxq.split();
        let (tx_in, tx_out) = cx.local.txq.split();
        hopper_app::DAC_ZERO_CODE.store(
            cfg.calibration.dac_zero_code,
            core::sync::atomic::Ordering::Relaxed,
        );
        let board = board::init(
            cx.device,
            CONTROL_HZ,
            cfg.calibration.dac_zero_code,
            (rx_in, tx_out),
        );
        // Period starts are timed with the clock that runs.
        cycles.set_hz(board.io.sysclk_hz(), board.io.control_hz());
        if let Some(e) = board.stored.error {
            defmt::error!("calibration store: {=str}: the defaults run", e.name());
        }
        runner.load_calibration(board.stored.record());
        // The link task's copy of the configuration is the loaded one.
        let mut link = Endpoint::new(&runner).with_spares(spares);
        // The saved calibration (written by this init if a save waited).
        if let Some(ok) = board.stored.saved {
            link.save_done(ok, false);
            if let Some(why) = board.stored.refused {
                defmt::error!("calibration save refused: {=str}", why);
            } else if ok {
                defmt::info!("calibration saved to flash");
            } else {
                defmt::error!("calibration save to flash failed");
            }
        }
        // The fault handlers' zero code is the calibrated one from here on.
        hopper_app::DAC_ZERO_CODE.store(
            runner.hopper().config().calibration.dac_zero_code,
            core::sync::atomic::Ordering::Relaxed,
        );
        defmt::info!("calibration at boot: {}", runner.calibration_at_boot());
        // Reported over the link; a clock that fell back to the HSI or a
        // brown-out reset left off refuses arming.
        runner.arming_mut().set_boot(board.boot);
        for cause in board.boot.resets.iter() {
            defmt::info!("reset cause: {=str}", cause.name());
        }
        if let Some(r) = board.boot.refusal() {
            defmt::error!("boot check: {=str}: arming refused", r.name());
        }
        // Nothing of the motor's heat survives a reset or a power cycle
        // here (the backup domain is not used: no battery on VBAT), and a
        // motor that just tripped at the trip temperature is still that
        // hot a few seconds later: every boot starts the estimate at the
        // derating temperature (`status` says so).
        defmt::info!("motor temperature estimate starts at the derating temperature");
        runner.assume_motor_warm();
        let watchdog = board.watchdog;
        if watchdog.caused_last_reset() {
            // The control loop stopped or misbehaved last time: start faulted,
            // amplifier off, until someone looks (a reset of the latch).
            defmt::error!("watchdog reset: amplifier stays off (overrun latched)");
            runner.report_overrun();
            runner.arming_mut().note_watchdog_reset();
        }
        let (log_tx, log_rx) = cx.local.log_queue.split();
        if board.io.control_hz() != CONTROL_HZ {
            // The runner steps with the built-in period: on another rate
            // every filter and law would be wrong, so the motor stays off.
            defmt::error!(
                "control timer at {=u32} Hz, not {=u32} Hz: amplifier stays off (overrun latched)",
                board.io.control_hz(),
                CONTROL_HZ
            );
            runner.report_overrun();
        }
        defmt::info!(
            "hopper-fw: board build ({=str}, {=str} pin map), control at {=u32} Hz, core clock {=u32} Hz, link on {=str} at {=u32} baud; disarmed until the host arms",
            board::CLOCK_PROFILE,
            hopper_app::pinmap::NAME,
            board.io.control_hz(),
            board.io.sysclk_hz(),
            hopper_app::pinmap::LINK_NAME,
            hopper_app::serial::LINK_BAUD
        );
        let (port_queues, link_queues) = cx.local.queues.split();
        (
            Shared {
                capture: cx.local.capture,
            },
            Local {
                io: board.io,
                watchdog,
                dump: board.dump_button,
                firmware: ControlLoop::new(runner),
                cycles,
                log: Log::new(log_tx, LOGGER_IRQ),
                log_rx,
                port_queues,
                link,
                link_cycles: LinkCycles,
                link_queues,
                link_rx: rx_out,
                link_tx: LinkTx::new(tx_in),
                #[cfg(not(feature = "feather"))]
                serial: board.serial,
                #[cfg(feature = "feather")]
                serial3: board.serial,
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        #[cfg(feature = "fault-test")]
        {
            crate::fault_test::enable_deadman();
            crate::fault_test::hard_fault_off_the_stack();
        }
        #[cfg(not(feature = "fault-test"))]
        loop {
            cortex_m::asm::nop();
        }
    }

    /// The control period: fresh ADC samples are in; the runner reads, steps
    /// and writes; the port records the capture, publishes the period's
    /// note and applies at most one command the link task prepared; this
    /// task paces it, feeds the watchdog, queues the log, and pends the
    /// link task. Nothing here waits, decodes, encodes or builds: its
    /// work is bounded and alike every period (timed entry to exit).
    #[task(binds = ADC, priority = 3, local = [io, watchdog, dump, firmware, cycles, log, port_queues, polls: u32 = 0], shared = [capture])]
    fn control(cx: control::Context) {
        let (t0, serial0) = hopper_app::serial_cost::stamp(cortex_m::peripheral::DWT::cycle_count);
        if !cx.local.io.ack_control_irq() {
            return;
        }
        let firmware = &mut *cx.local.firmware;
        let p = firmware.period(
            cx.local.io,
            cx.local.cycles,
            &mut Locked(cx.shared.capture),
            cx.local.port_queues,
        );
        if p.feed_watchdog {
            cx.local.watchdog.feed();
        }
        let (runner, port) = (&mut firmware.runner, &mut firmware.port);
        // A set or a routine may have moved the zero code: the fault
        // handlers write the one in use (one relaxed store).
        hopper_app::DAC_ZERO_CODE.store(
            runner.hopper().config().calibration.dac_zero_code,
            core::sync::atomic::Ordering::Relaxed,
        );
        // A save waits in the RAM slot: `init` writes it after the reset
        // (never while armed: the port disarms first).
        if port.restart_due(runner) {
            hopper_app::disable_amplifier();
            cortex_m::peripheral::SCB::sys_reset();
        }
        // The next conversion already finished: this period overran.
        runner.end_period(NVIC::is_pending(Interrupt::ADC));
        log::PERIODS.store(runner.periods(), core::sync::atomic::Ordering::Relaxed);
        if let Some(item) = p.log {
            cx.local.log.push(&item);
        }
        *cx.local.polls = cx.local.polls.wrapping_add(1);
        // The dump's thousand log frames only while disarmed: each frame
        // masks interrupts (docs/safety.md, "Logging").
        if cx.local.polls.is_multiple_of(100) && !p.armed && cx.local.dump.pressed() {
            cx.local.log.request_dump();
        }
        rtic::pend(LINK_IRQ);
        let (irq_max, irq_count, irq_lost) = hopper_app::serial_cost::totals();
        port.set_serial_cost(irq_max, irq_count, irq_lost);
        // Entry to exit, less the serial interrupts that preempted it
        // (counted per byte in the budget, docs/link.md).
        let (t1, serial1) = hopper_app::serial_cost::stamp(cortex_m::peripheral::DWT::cycle_count);
        let own = t1
            .wrapping_sub(t0)
            .wrapping_sub(serial1.wrapping_sub(serial0));
        port.add_isr_cost(own);
        hopper_app::serial_cost::record_control(own);
    }

    /// The link task, below the control task, once a period: the notes and
    /// answers the control task published, the bytes received, decoded
    /// and answered, sets checked and their controllers built, frames
    /// encoded into the transmit ring; a save into the RAM slot for
    /// `init` to write after the reset the control task makes.
    #[task(binds = SDIO, priority = 2, local = [link, link_cycles, link_queues, link_rx, link_tx], shared = [capture])]
    fn link(cx: link::Context) {
        let link = &mut *cx.local.link;
        let rx = &mut *cx.local.link_rx;
        // A save the board could not write after its restart is refused
        // when asked, with the reason.
        link.set_save_refusal(hopper_app::flash::save_refusal_now());
        link.set_serial_counts(hopper_app::serial_cost::counts());
        link.serve(
            cx.local.link_queues,
            core::iter::from_fn(|| rx.dequeue()),
            &mut Locked(cx.shared.capture),
            cx.local.link_tx,
            cx.local.link_cycles,
        );
        if let Some(r) = link.take_save() {
            hopper_app::flash::queue_save(r);
            link.save_done(true, true);
        }
    }

    /// The link's bytes in and out, above the control task: the USART has
    /// no receive FIFO (`serial`'s module docs). It times itself in core
    /// cycles.
    #[cfg(not(feature = "feather"))]
    #[task(binds = USART1, priority = 4, local = [serial])]
    fn usart1(cx: usart1::Context) {
        hopper_app::serial_cost::serve(cx.local.serial, cortex_m::peripheral::DWT::cycle_count);
    }

    /// The same on the Feather's pin map (its link is USART3).
    #[cfg(feature = "feather")]
    #[task(binds = USART3, priority = 4, local = [serial3])]
    fn usart3(cx: usart3::Context) {
        hopper_app::serial_cost::serve(cx.local.serial3, cortex_m::peripheral::DWT::cycle_count);
    }

    /// Logs hop ledgers and faults as the control task queues them, and
    /// prints the capture when the dump button asked for it. Lowest
    /// priority: its log frames take the image's critical section, which
    /// masks this task and the link task, never the control or serial
    /// interrupts.
    #[task(binds = CAN2_RX1, priority = 1, local = [log_rx], shared = [capture])]
    fn logger(mut cx: logger::Context) {
        while let Some(item) = cx.local.log_rx.dequeue() {
            log::print(&item);
        }
        if log::take_dump() {
            dump(&mut cx.shared.capture, log::dropped());
        }
    }

    /// Prints the capture, oldest first; it stays in place (the link's
    /// `dump` reads the same records).
    fn dump(capture: &mut impl rtic::Mutex<T = &'static mut Capture>, log_dropped: u32) {
        let (n, frozen, fault_step) =
            capture.lock(|c| (c.len(), c.frozen(), c.fault_step().unwrap_or(0)));
        defmt::info!(
            "capture dump begins: {=usize} records, frozen by a fault: {=bool} (step {=u32})",
            n,
            frozen,
            fault_step
        );
        for i in 0..n {
            if let Some(r) = capture.lock(|c| c.get(i).copied()) {
                defmt::info!("{}", r);
            }
        }
        defmt::info!("capture dump ends ({=u32} log items dropped)", log_dropped);
    }
}
