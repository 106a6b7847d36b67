//! `hopper-hil`: the hardware-in-the-loop image. The firmware of the board
//! image (the same control period, supervisor, arming, bring-up and
//! parameter handling, the same link) on a board, or on QEMU's
//! netduinoplus2, whose sensors are the host's models: each control
//! period's raw sample arrives over the link from `hopper-sim run --hil`
//! (`hopper_robot_link::hil`), and the DAC code, the amplifier enable and
//! the control interrupt's cost go back. The host owns the clock: a period
//! runs when its sample arrives. The board's e-stop input and AMP_EN stay
//! in the loop (PB1, PB0).
//!
//! # Tasks
//! | Task      | Priority | Trigger |
//! |-----------|----------|---------|
//! | `usart1`  | 4        | USART1 (the link's bytes); pends `link` |
//! | `control` | 3        | ADC's interrupt line, pended by `link` when a sample arrived (the converter is not used) |
//! | `link`    | 2        | SDIO (spare), pended by `usart1` and `control`: decode, answer, encode; hands a sample to `control` |
//! | `idle`    | 0        | busy loop |
//!
//! # What differs from the board image
//! No converters, encoders, control timer or watchdog: the host paces the
//! periods, at the rate the line allows, with pauses while it configures.
//! AMP_EN is the deadman with a 50 ms wall-clock window
//! (`board::HilPins`): it follows the periods' enable while samples come,
//! and falls by itself when they stop.
//! No flash: the host sets the configuration over the link (a save is
//! refused). The boot check does not refuse arming for a clock on the HSI
//! (the periods' length is the host's), and the motor's temperature
//! estimate starts at the ambient (the host's motor model does).
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(unsafe_code)]

/// Host stand-in: this binary only does something on the microcontroller.
#[cfg(not(target_os = "none"))]
fn main() {
    println!("hopper-hil is firmware: build it with --target thumbv7em-none-eabihf");
}

#[cfg(target_os = "none")]
use defmt_rtt as _;

#[cfg(target_os = "none")]
hopper_app::fault_handlers!(hopper_app::park);

/// The HIL application.
#[cfg(target_os = "none")]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true, dispatchers = [FSMC])]
mod app {
    use heapless::spsc::{Consumer, Producer, Queue};
    use hopper_app::board::{self, HilPins};
    use hopper_app::control::{Bank, Capture, Locked, Slot, CONTROL_HZ, TIMING};
    use hopper_app::serial::{LinkTx, RxOut, RxQueue, Serial, TxQueue};
    use hopper_app::ticks::{Control, Link, Ticks};
    use hopper_protocol::{HilActuate, HilSample};
    use hopper_robot_link::hil::{boot_config, HilIo};
    use hopper_robot_link::{ControlLoop, Endpoint, LinkEnds, PortEnds, Queues};
    use stm32f4::stm32f405::Interrupt;

    /// The link task's interrupt (the SD card interface is not used).
    const LINK_IRQ: Interrupt = Interrupt::SDIO;
    /// The control task's interrupt line: the ADC's, pended by the link
    /// task (the converter is off).
    const CONTROL_IRQ: Interrupt = Interrupt::ADC;

    #[shared]
    struct Shared {
        /// The capture, frozen around the first fault (a static built in
        /// place, as the board's).
        capture: &'static mut Capture,
    }

    #[local]
    struct Local {
        io: HilIo<HilPins>,
        firmware: ControlLoop<Slot>,
        control_ticks: Control,
        port_queues: PortEnds<'static, Slot>,
        samples_in: Consumer<'static, HilSample>,
        answers_out: Producer<'static, HilActuate>,
        link: Endpoint<Slot>,
        link_ticks: Link,
        link_queues: LinkEnds<'static, Slot>,
        link_rx: RxOut<'static>,
        link_tx: LinkTx<'static>,
        samples_out: Producer<'static, HilSample>,
        answers_in: Consumer<'static, HilActuate>,
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
        capture: Capture = Capture::new(),
        queues: Queues<Slot> = Queues::new(),
        bank: Bank = [None, None, None],
        samples: Queue<HilSample, 2> = Queue::new(),
        answers: Queue<HilActuate, 4> = Queue::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;
        let mut core = cx.core;
        let (rx_in, rx_out) = cx.local.rxq.split();
        let (tx_in, tx_out) = cx.local.txq.split();
        let board = board::init_hil(dp, (rx_in, tx_out));
        let ticks = Ticks::start(&mut core.DCB, &mut core.DWT, board.tim5, board.sysclk_hz);
        let Ok((mut runner, spares)) =
            hopper_app::control::runner_in_bank(cx.local.bank, boot_config(), TIMING)
        else {
            hopper_app::disable_amplifier();
            defmt::error!("invalid HIL configuration: amplifier stays off");
            loop {
                cortex_m::asm::nop();
            }
        };
        // The periods' length is the host's: a core clock on the HSI does
        // not make them wrong, so it does not refuse arming here.
        runner
            .arming_mut()
            .set_boot(hopper_control::boot::BootReport {
                clock_as_configured: true,
                ..board.boot
            });
        // Simulated: the host's run may switch protections off for a
        // control study (the motor is its model).
        let link = Endpoint::simulated(&runner).with_spares(spares);
        let (samples_out, samples_in) = cx.local.samples.split();
        let (answers_out, answers_in) = cx.local.answers.split();
        let (port_queues, link_queues) = cx.local.queues.split();
        defmt::info!(
            "hopper-hil: hardware-in-the-loop image, {=u32} Hz periods paced by the host over {=str} at {=u32} baud; core clock {=u32} Hz; disarmed",
            CONTROL_HZ,
            hopper_app::pinmap::LINK_NAME,
            hopper_app::serial::LINK_BAUD,
            board.sysclk_hz
        );
        (
            Shared {
                capture: cx.local.capture,
            },
            Local {
                io: HilIo::new(board.pins),
                firmware: ControlLoop::new(runner),
                control_ticks: Control(ticks, hopper_control::runner::Pacing::Host),
                port_queues,
                samples_in,
                answers_out,
                link,
                link_ticks: Link(ticks),
                link_queues,
                link_rx: rx_out,
                link_tx: LinkTx::new(tx_in),
                samples_out,
                answers_in,
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

    /// One control period on the sample the link task handed over: the
    /// board image's period (read, step, write; the port's capture, note
    /// and at most one command), then the answer for the link task. Timed
    /// entry to exit, less the serial interrupts that preempted it.
    #[task(binds = ADC, priority = 3, local = [io, firmware, control_ticks, port_queues, samples_in, answers_out], shared = [capture])]
    fn control(cx: control::Context) {
        let ticks = cx.local.control_ticks.0;
        let (t0, serial0) = hopper_app::serial_cost::stamp(move || ticks.raw());
        let Some(sample) = cx.local.samples_in.dequeue() else {
            return;
        };
        let io = &mut *cx.local.io;
        io.load(&sample);
        let firmware = &mut *cx.local.firmware;
        let p = firmware.period(
            io,
            cx.local.control_ticks,
            &mut Locked(cx.shared.capture),
            cx.local.port_queues,
        );
        // The host owns the clock: no period is late.
        firmware.runner.end_period(false);
        let (irq_max, irq_count, irq_lost) = hopper_app::serial_cost::totals();
        firmware.port.set_serial_cost(irq_max, irq_count, irq_lost);
        let (t1, serial1) = hopper_app::serial_cost::stamp(move || ticks.raw());
        let own = t1
            .wrapping_sub(t0)
            .wrapping_sub(serial1.wrapping_sub(serial0));
        firmware.port.add_isr_cost(own);
        hopper_app::serial_cost::record_control(own);
        // A full queue loses the answer: the host, missing it, stops.
        let _ = cx
            .local
            .answers_out
            .enqueue(io.actuate(&p, &firmware.runner, own));
        rtic::pend(LINK_IRQ);
    }

    /// The link task: the board's (decode, answer, encode, build sets),
    /// then the periods' answers, then a received sample to the control
    /// task.
    #[task(binds = SDIO, priority = 2, local = [link, link_ticks, link_queues, link_rx, link_tx, samples_out, answers_in], shared = [capture])]
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
        while let Some(a) = cx.local.answers_in.dequeue() {
            link.send_hil(cx.local.link_tx, &a);
        }
        // No flash here: the configuration is the host's.
        if link.take_save().is_some() {
            link.save_done(false, false);
        }
        if let Some(s) = link.take_hil_sample() {
            if cx.local.samples_out.enqueue(s).is_ok() {
                rtic::pend(CONTROL_IRQ);
            }
        }
    }

    /// The link's bytes in and out, above the control task (as the
    /// board's); a received byte pends the link task.
    #[cfg(not(feature = "feather"))]
    #[task(binds = USART1, priority = 4, local = [serial, serial_ticks])]
    fn usart1(cx: usart1::Context) {
        let ticks = &*cx.local.serial_ticks;
        hopper_app::serial_cost::serve(cx.local.serial, || ticks.raw());
        rtic::pend(LINK_IRQ);
    }

    /// The same on the Feather's pin map (its link is USART3).
    #[cfg(feature = "feather")]
    #[task(binds = USART3, priority = 4, local = [serial3, serial3_ticks])]
    fn usart3(cx: usart3::Context) {
        let ticks = &*cx.local.serial3_ticks;
        hopper_app::serial_cost::serve(cx.local.serial3, || ticks.raw());
        rtic::pend(LINK_IRQ);
    }
}
