//! `hopper-qemu-link`: the QEMU link image: the virtual robot
//! (`hopper_sil::robot::VirtualRobot`) behind the host link on USART1,
//! disarmed until `hopper-link` arms it. `cargo xtask qemu` runs the
//! scripted link session against it.
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(unsafe_code)]

/// Host stand-in: this binary only does something on the microcontroller.
#[cfg(not(target_os = "none"))]
fn main() {
    println!("hopper-qemu-link is firmware: build it with --target thumbv7em-none-eabihf");
}

#[cfg(target_os = "none")]
use defmt_semihosting as _;

#[cfg(target_os = "none")]
hopper_app::fault_handlers!(hopper_app::qemu::exit_failure);

/// The QEMU link image (`hopper-qemu-link`): the virtual robot
/// (`hopper_sil::robot::VirtualRobot`, which `hopper-sim serve` runs too)
/// with the host link on USART1, which QEMU wires to its first `-serial`
/// (the xtask gives it a TCP socket). Its tasks are the board's: the
/// control period with the link's port at priority 3, the link task at 2,
/// the serial interrupt at 4. Like the board it boots disarmed and
/// tethered, so nothing moves until `hopper-link` arms it; the body is held
/// 0.05 m up until then (`VirtualRobot::held`). It runs until QEMU is
/// stopped, or `LINK_LIMIT_S` of robot time.
#[cfg(target_os = "none")]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true, dispatchers = [FSMC])]
mod app {
    use cortex_m::peripheral::{SCB, SYST};
    use cortex_m_semihosting::debug;
    use hopper_app::control::{Bank, Capture, Locked, Slot, CONTROL_HZ};
    use hopper_app::serial::{LinkTx, RxOut, RxQueue, Serial, TxQueue};
    use hopper_app::virtual_robot::{self, Flash, START_APEX_M};
    use hopper_robot_link::{Endpoint, LinkEnds, PortEnds, Queues};
    use hopper_sil::robot::VirtualRobot;
    use stm32f4::stm32f405::Interrupt;

    /// The longest a session may run, s of robot time (then QEMU exits).
    const LINK_LIMIT_S: u32 = 600;
    /// PCLK2 on the HSI, Hz (QEMU has no RCC model, and ignores the baud
    /// rate anyway).
    const PCLK2_HZ: u32 = 16_000_000;
    /// The link task's interrupt, as on the board.
    const LINK_IRQ: Interrupt = Interrupt::SDIO;

    #[shared]
    struct Shared {
        /// The capture, frozen around a fault: a static built in place, as
        /// the board's (32 KiB; inside the robot, built in `init` and moved,
        /// it would take `init`'s stack past the room flip-link leaves).
        capture: &'static mut Capture,
    }

    #[local]
    struct Local {
        robot: VirtualRobot<Slot>,
        port_queues: PortEnds<'static, Slot>,
        counter: hopper_app::qemu::Instructions,
        syst: SYST,
        link: Endpoint<Slot>,
        link_counter: hopper_app::qemu::Instructions,
        link_queues: LinkEnds<'static, Slot>,
        flash: Flash,
        link_rx: RxOut<'static>,
        link_tx: LinkTx<'static>,
        serial: Serial<'static>,
    }

    #[init(local = [
        rxq: RxQueue = RxQueue::new(),
        txq: TxQueue = TxQueue::new(),
        capture_buf: Capture = Capture::new(),
        queues: Queues<Slot> = Queues::new(),
        bank: Bank = [None, None, None],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;
        let mut core = cx.core;
        let counter = hopper_app::qemu::start(&dp.RCC, &dp.GPIOB, dp.TIM5);

        let Some((robot, spares, flash)) = virtual_robot::session(cx.local.bank) else {
            defmt::error!("link image set-up failed");
            debug::exit(debug::EXIT_FAILURE);
            #[allow(clippy::empty_loop)]
            loop {}
        };
        // The link task's own endpoint (the robot's in-line one is for the
        // simulator's single thread).
        let link = Endpoint::simulated(&robot.firmware.runner).with_spares(spares);

        let (rx_in, rx_out) = cx.local.rxq.split();
        let (tx_in, tx_out) = cx.local.txq.split();
        let serial = Serial::new(
            dp.USART1, &dp.RCC, &dp.GPIOA, &dp.GPIOB, PCLK2_HZ, rx_in, tx_out,
        );
        let (port_queues, link_queues) = cx.local.queues.split();

        hopper_app::qemu::start_systick(&mut core.SYST, hopper_app::qemu::PERIOD_TICKS);
        defmt::println!(
            "hopper-fw: QEMU link image, {=u32} Hz, link on USART1; disarmed, held {=f64} m up until armed",
            CONTROL_HZ,
            START_APEX_M
        );
        (
            Shared {
                capture: cx.local.capture_buf,
            },
            Local {
                robot,
                port_queues,
                counter,
                syst: core.SYST,
                link,
                link_counter: hopper_app::qemu::Instructions::reader(),
                link_queues,
                flash,
                link_rx: rx_out,
                link_tx: LinkTx::new(tx_in),
                serial,
            },
        )
    }

    /// Busy idle: QEMU 7.2 loses SysTick ticks while the core sleeps in `wfi`.
    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::nop();
        }
    }

    /// One control period with the link's port (as the board's control
    /// task), then the plant to the next tick with SysTick stopped (as in
    /// the scenario image); the link task is pended.
    #[task(binds = SysTick, priority = 3, local = [robot, port_queues, counter, syst], shared = [capture])]
    fn control(mut cx: control::Context) {
        cx.local.counter.enter();
        let (t0, serial0) = hopper_app::serial_cost::stamp(hopper_app::qemu::tim5_now);
        let robot = &mut *cx.local.robot;
        // The sensor models (the board's ADC and timers), outside the
        // firmware's time, as the plant is.
        let sample = hopper_app::qemu::with_systick_stopped(cx.local.syst, || robot.sample());
        let (queues, counter) = (&mut *cx.local.port_queues, &mut *cx.local.counter);
        let (irq_max, irq_count, irq_lost) = hopper_app::serial_cost::totals();
        robot
            .firmware
            .port
            .set_serial_cost(irq_max, irq_count, irq_lost);
        cx.shared
            .capture
            .lock(|c| robot.control_period(sample, c, queues, counter));
        if hopper_app::qemu::with_systick_stopped(cx.local.syst, || robot.advance(&mut |_| {}))
            .is_err()
        {
            defmt::error!("plant integration failed");
            debug::exit(debug::EXIT_FAILURE);
        }
        robot.firmware.runner.end_period(SCB::is_pendst_pending());
        rtic::pend(LINK_IRQ);
        // The whole handler (the plant too) preempts the link task.
        let (t1, serial1) = hopper_app::serial_cost::stamp(hopper_app::qemu::tim5_now);
        hopper_app::serial_cost::record_control(
            t1.wrapping_sub(t0)
                .wrapping_sub(serial1.wrapping_sub(serial0)),
        );
        if robot.firmware.runner.periods() >= LINK_LIMIT_S * CONTROL_HZ {
            defmt::println!("link image: {=u32} s limit reached", LINK_LIMIT_S);
            debug::exit(debug::EXIT_SUCCESS);
        }
    }

    /// The link task, below the control period (as the board's): a save
    /// goes to the RAM flash at once (the board defers it to its next
    /// boot).
    #[task(binds = SDIO, priority = 2, local = [link, link_counter, link_queues, flash, link_rx, link_tx], shared = [capture])]
    fn link(cx: link::Context) {
        let link = &mut *cx.local.link;
        let rx = &mut *cx.local.link_rx;
        link.set_serial_counts(hopper_app::serial_cost::counts());
        link.serve(
            cx.local.link_queues,
            core::iter::from_fn(|| rx.dequeue()),
            &mut Locked(cx.shared.capture),
            cx.local.link_tx,
            cx.local.link_counter,
        );
        let mut record = [0u8; hopper_control::persist::MAX_RECORD];
        if let Some(r) = link.take_save() {
            let n = r.len().min(record.len());
            record[..n].copy_from_slice(&r[..n]);
            let ok = hopper_store::block_on(cx.local.flash.save(&record[..n])).is_ok();
            link.save_done(ok, false);
        }
    }

    /// The link's bytes in and out, at the control task's priority, not
    /// above it as on the board: QEMU's USART holds the next byte back
    /// until the data register is read (no overrun to race) and has no
    /// baud rate, so at priority 4 the host's bytes would preempt the
    /// control period without the bound the board's 921,600 baud sets
    /// (about 18 interrupts a period, budgeted in docs/link.md), and each
    /// preemption's entry would count in the control period's cost. It
    /// times itself all the same.
    #[task(binds = USART1, priority = 3, local = [serial])]
    fn usart1(cx: usart1::Context) {
        hopper_app::serial_cost::serve(cx.local.serial, hopper_app::qemu::tim5_now);
    }
}
