//! `hopper-sih`: the simulated hopper on the chip (simulation in
//! hardware, as PX4's SIH). The virtual robot of `hopper-sim serve` and the
//! QEMU link image (`hopper_sil::robot::VirtualRobot`: the firmware's
//! control period on the plant and sensor models) runs on a board, its
//! link on the board's USART1, so `hopper-link` operates a simulated robot
//! on real silicon: the firmware's timing is the chip's, with no motor.
//!
//! The plant integrates in `f64`, in software on the M4F: a period with
//! its plant takes longer than the robot's 100 us. SysTick paces the
//! periods at the rate the chip sustains: it starts at the robot's rate and
//! lengthens its interval by a quarter each time three periods in a row
//! (control and plant) overrun it, until they do not (a single long
//! period, where the plant locates an event, only delays the next); robot time is unchanged (each
//! period is 100 us of it), only slower than real time. `hopper-link cost`
//! gives the interrupt's cost in cycles; the log says the rate.
//!
//! AMP_EN (PB0) stays low: there is no motor, the enable is the model's.
//! Like the board it boots disarmed and tethered; the body is held 0.05 m
//! up until armed.
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(unsafe_code)]

/// Host stand-in: this binary only does something on the microcontroller.
#[cfg(not(target_os = "none"))]
fn main() {
    println!("hopper-sih is firmware: build it with --target thumbv7em-none-eabihf");
}

#[cfg(target_os = "none")]
use defmt_rtt as _;

#[cfg(target_os = "none")]
hopper_app::fault_handlers!(hopper_app::park);

/// The simulated robot on the chip.
#[cfg(target_os = "none")]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true, dispatchers = [FSMC])]
mod app {
    use cortex_m::peripheral::{SCB, SYST};
    use hopper_app::board;
    use hopper_app::control::{Bank, Capture, Locked, Slot, CONTROL_HZ};
    use hopper_app::serial::{LinkTx, RxOut, RxQueue, Serial, TxQueue};
    use hopper_app::ticks::{Control, Link, Ticks};
    use hopper_app::virtual_robot::{self, Flash, START_APEX_M};
    use hopper_robot_link::{Endpoint, LinkEnds, PortEnds, Queues};
    use hopper_sil::robot::VirtualRobot;
    use stm32f4::stm32f405::Interrupt;

    /// The link task's interrupt, as on the board.
    const LINK_IRQ: Interrupt = Interrupt::SDIO;
    /// SysTick's longest reload (24 bits).
    const MAX_RELOAD: u32 = (1 << 24) - 1;

    #[shared]
    struct Shared {
        /// The capture, frozen around a fault (a static built in place).
        capture: &'static mut Capture,
    }

    #[local]
    struct Local {
        robot: VirtualRobot<Slot>,
        port_queues: PortEnds<'static, Slot>,
        control_ticks: Control,
        syst: SYST,
        reload: u32,
        sysclk_hz: u32,
        link: Endpoint<Slot>,
        link_ticks: Link,
        link_queues: LinkEnds<'static, Slot>,
        flash: Flash,
        link_rx: RxOut<'static>,
        link_tx: LinkTx<'static>,
        #[cfg(not(feature = "feather"))]
        serial: Serial<'static>,
        #[cfg(not(feature = "feather"))]
        serial_ticks: Ticks,
        #[cfg(feature = "feather")]
        serial3: Serial<'static>,
        #[cfg(feature = "feather")]
        serial3_ticks: Ticks,
    }

    #[init(local = [
        rxq: RxQueue = RxQueue::new(),
        txq: TxQueue = TxQueue::new(),
        capture_buf: Capture = Capture::new(),
        queues: Queues<Slot> = Queues::new(),
        bank: Bank = [None, None, None],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let mut core = cx.core;
        let (rx_in, rx_out) = cx.local.rxq.split();
        let (tx_in, tx_out) = cx.local.txq.split();
        let board = board::init_hil(cx.device, (rx_in, tx_out));
        let ticks = Ticks::start(&mut core.DCB, &mut core.DWT, board.tim5, board.sysclk_hz);
        let Some((mut robot, spares, flash)) = virtual_robot::session(cx.local.bank) else {
            defmt::error!("simulated robot set-up failed");
            hopper_app::park();
        };
        // The periods' length is the pacing's, not the core clock's.
        robot
            .firmware
            .runner
            .arming_mut()
            .set_boot(hopper_control::boot::BootReport {
                clock_as_configured: true,
                ..board.boot
            });
        let link = Endpoint::simulated(&robot.firmware.runner).with_spares(spares);
        let (port_queues, link_queues) = cx.local.queues.split();
        // Start at the robot's rate; the control task lengthens it.
        let reload = (board.sysclk_hz / CONTROL_HZ).clamp(1, MAX_RELOAD);
        core.SYST
            .set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
        core.SYST.set_reload(reload - 1);
        core.SYST.clear_current();
        core.SYST.enable_interrupt();
        core.SYST.enable_counter();
        defmt::info!(
            "hopper-sih: the simulated hopper on the chip, core clock {=u32} Hz, link on {=str} at {=u32} baud; disarmed, held {=f64} m up until armed",
            board.sysclk_hz,
            hopper_app::pinmap::LINK_NAME,
            hopper_app::serial::LINK_BAUD,
            START_APEX_M
        );
        (
            Shared {
                capture: cx.local.capture_buf,
            },
            Local {
                robot,
                port_queues,
                control_ticks: Control(ticks, hopper_control::runner::Pacing::Sustained),
                syst: core.SYST,
                reload,
                sysclk_hz: board.sysclk_hz,
                link,
                link_ticks: Link(ticks),
                link_queues,
                flash,
                link_rx: rx_out,
                link_tx: LinkTx::new(tx_in),
                #[cfg(not(feature = "feather"))]
                serial: board.serial,
                #[cfg(not(feature = "feather"))]
                serial_ticks: ticks,
                #[cfg(feature = "feather")]
                serial3: board.serial,
                #[cfg(feature = "feather")]
                serial3_ticks: ticks,
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::nop();
        }
    }

    /// One control period with the link's port, then the plant to the
    /// next period; an overrun of SysTick's interval lengthens it.
    #[task(binds = SysTick, priority = 3, local = [robot, port_queues, control_ticks, syst, reload, sysclk_hz, late: u32 = 0], shared = [capture])]
    fn control(mut cx: control::Context) {
        let ticks = cx.local.control_ticks.0;
        let (t0, serial0) = hopper_app::serial_cost::stamp(move || ticks.raw());
        let robot = &mut *cx.local.robot;
        let sample = robot.sample();
        let (queues, counter) = (&mut *cx.local.port_queues, &mut *cx.local.control_ticks);
        let (irq_max, irq_count, irq_lost) = hopper_app::serial_cost::totals();
        robot
            .firmware
            .port
            .set_serial_cost(irq_max, irq_count, irq_lost);
        cx.shared
            .capture
            .lock(|c| robot.control_period(sample, c, queues, counter));
        if robot.advance(&mut |_| {}).is_err() {
            defmt::error!("plant integration failed: the simulated robot stops");
            hopper_app::park();
        }
        // Soft deadline: a late period slows the pacing, it is no overrun
        // of the robot's (robot time is a count of periods).
        robot.firmware.runner.end_period(false);
        // Three late in a row (not one long period, an event's): lengthen.
        let late = cx.local.late;
        *late = if SCB::is_pendst_pending() {
            late.saturating_add(1)
        } else {
            0
        };
        if *late >= 3 && *cx.local.reload < MAX_RELOAD {
            *late = 0;
            let r = (*cx.local.reload + *cx.local.reload / 4).min(MAX_RELOAD);
            *cx.local.reload = r;
            cx.local.syst.set_reload(r - 1);
            defmt::info!(
                "hopper-sih: {=u32} periods/s ({=u32} core clocks a period with its plant)",
                *cx.local.sysclk_hz / r,
                r
            );
        }
        rtic::pend(LINK_IRQ);
        let (t1, serial1) = hopper_app::serial_cost::stamp(move || ticks.raw());
        let own = t1
            .wrapping_sub(t0)
            .wrapping_sub(serial1.wrapping_sub(serial0));
        robot.firmware.port.add_isr_cost(own);
        hopper_app::serial_cost::record_control(own);
    }

    /// The link task, below the control period (as the board's); a save
    /// goes to the image's RAM flash.
    #[task(binds = SDIO, priority = 2, local = [link, link_ticks, link_queues, flash, link_rx, link_tx], shared = [capture])]
    fn link(cx: link::Context) {
        let link = &mut *cx.local.link;
        let rx = &mut *cx.local.link_rx;
        link.set_serial_counts(hopper_app::serial_cost::counts());
        link.serve(
            cx.local.link_queues,
            core::iter::from_fn(|| rx.dequeue()),
            &mut Locked(cx.shared.capture),
            cx.local.link_tx,
            cx.local.link_ticks,
        );
        let mut record = [0u8; hopper_control::persist::MAX_RECORD];
        if let Some(r) = link.take_save() {
            let n = r.len().min(record.len());
            record[..n].copy_from_slice(&r[..n]);
            let ok = hopper_store::block_on(cx.local.flash.save(&record[..n])).is_ok();
            link.save_done(ok, false);
        }
    }

    /// The link's bytes in and out, above the control task (as the
    /// board's).
    #[cfg(not(feature = "feather"))]
    #[task(binds = USART1, priority = 4, local = [serial, serial_ticks])]
    fn usart1(cx: usart1::Context) {
        let ticks = &*cx.local.serial_ticks;
        hopper_app::serial_cost::serve(cx.local.serial, || ticks.raw());
    }

    /// The same on the Feather's pin map (its link is USART3).
    #[cfg(feature = "feather")]
    #[task(binds = USART3, priority = 4, local = [serial3, serial3_ticks])]
    fn usart3(cx: usart3::Context) {
        let ticks = &*cx.local.serial3_ticks;
        hopper_app::serial_cost::serve(cx.local.serial3, || ticks.raw());
    }
}
