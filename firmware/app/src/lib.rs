//! `hopper-app`: what the firmware images share on the STM32F405 (the
//! control task's constants and bank, the board's registers, pins and
//! watchdog, the saved calibration's flash, the serial transport, the log,
//! the QEMU images' counter and pacing, and the fault paths). Each image is
//! a binary with its one `#[rtic::app]`:
//!
//! | Binary | Source | Image | Features |
//! |--------|--------|-------|----------|
//! | `hopper-fw` | `src/main.rs` | the board | `board` (default); `hse-12mhz`, `feather` (the pin map, [`pinmap`]), `fault-test` |
//! | `hopper-selftest` | `src/bin/selftest.rs` | the on-target self-test | `board` |
//! | `hopper-hil` | `src/bin/hil.rs` | hardware in the loop: the board's firmware, its sensors the host's models | `board` |
//! | `hopper-sih` | `src/bin/sih.rs` | the simulated hopper on a board (the plant on the chip, the link on its USART) | `sih` |
//! | `hopper-qemu` | `src/bin/qemu.rs` | the QEMU scenario | `qemu-sim` |
//! | `hopper-qemu-link` | `src/bin/qemu-link.rs` | the QEMU link image | `qemu-sim` |
//! | `hopper-qemu-planar` | `src/bin/qemu-planar.rs` | the planar machine's controller on QEMU | `qemu-sim` |
//! | `panic-check` | `src/bin/panic-check.rs` | the panic-never link check | |
//!
//! Features are additive: `board` brings the RTT logger, `qemu-sim` the
//! plant models and semihosting, for the binaries that need them; only the
//! QEMU binaries and `hopper-sih` use the plant. On the host this library is empty, which
//! keeps `cargo clippy --workspace --all-targets` working.
#![cfg_attr(target_os = "none", no_std)]
#![deny(unsafe_code)]

#[cfg(target_os = "none")]
pub mod control;

#[cfg(target_os = "none")]
pub mod serial;

#[cfg(target_os = "none")]
pub mod board;

#[cfg(target_os = "none")]
pub mod pinmap;

#[cfg(target_os = "none")]
pub mod flash;

/// Drives the amplifier-enable pin (the pin map's AMP_EN: PB0 by
/// default) low with one atomic BSRR write.
///
/// Usable from any context, including the panic and fault handlers: it needs
/// no owned peripheral. If GPIOB is not clocked yet the write is ignored and
/// the external pull-down keeps the amplifier off.
#[cfg(target_os = "none")]
pub fn disable_amplifier() {
    // SAFETY: `GPIOB::ptr()` is the fixed address of its register block,
    // and the deadman timer's second handle is only used here, on paths
    // that either do not return or (the save's reset) end in a reset.
    // BSRR resets only AMP_EN (one store). Then AMP_EN leaves the deadman
    // timer's alternate function for a GPIO output, which drives the low
    // just latched, whatever the timer does; and the timer's channel is
    // forced inactive, its counter stopped and cleared too
    // (`hopper_control::deadman::force_off`). The MODER read-modify-write
    // can race with nothing: every other path that writes MODER runs in
    // `init` or in a fault handler, which does not return.
    #[allow(unsafe_code)] // Needed to reach GPIOB and the timer without owning them (panic path).
    let (gpiob, mut timer) = unsafe {
        (
            &*stm32f4::stm32f405::GPIOB::ptr(),
            pinmap::DeadmanRegs::steal(),
        )
    };
    gpiob.bsrr().write(|w| w.br(pinmap::AMP_EN).set_bit());
    gpiob
        .moder()
        .modify(|_, w| w.moder(pinmap::AMP_EN).output());
    hopper_control::deadman::force_off(&mut timer);
}

/// What every fault path of the board's images ends in: `AMP_EN` low, the
/// DAC at its zero code, then nothing until the watchdog resets the MCU.
/// (The QEMU images end in [`qemu::exit_failure`].)
#[cfg(target_os = "none")]
pub fn park() -> ! {
    disable_amplifier();
    zero_dac();
    loop {
        cortex_m::asm::nop();
    }
}

/// What the serial interrupt cost, in the image's counter ticks (board:
/// cycles; QEMU: instructions): it preempts the control interrupt, whose
/// own cost leaves it out and whose budget counts it per byte.
#[cfg(target_os = "none")]
pub mod serial_cost {
    use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

    static SPENT: AtomicU32 = AtomicU32::new(0);
    static MAX: AtomicU32 = AtomicU32::new(0);
    static COUNT: AtomicU32 = AtomicU32::new(0);
    static LOST: AtomicU32 = AtomicU32::new(0);
    static OVERRUN: AtomicU32 = AtomicU32::new(0);
    static FRAMING: AtomicU32 = AtomicU32::new(0);
    static NOISE: AtomicU32 = AtomicU32::new(0);
    static FULL: AtomicU32 = AtomicU32::new(0);

    /// The serial interrupt's work on `serial`, timed with the image's
    /// counter `now` and recorded: what every image's USART task does.
    pub fn serve(serial: &mut crate::serial::Serial<'_>, now: impl Fn() -> u32) {
        let t0 = now();
        serial.on_interrupt();
        record(now().wrapping_sub(t0));
        LOST.store(serial.lost(), Relaxed);
        let c = serial.counts();
        OVERRUN.store(c.overrun, Relaxed);
        FRAMING.store(c.framing, Relaxed);
        NOISE.store(c.noise, Relaxed);
        FULL.store(c.full, Relaxed);
    }

    /// What the line lost so far, by cause (for the link's counts).
    pub fn counts() -> hopper_robot_link::SerialCounts {
        hopper_robot_link::SerialCounts {
            overrun: OVERRUN.load(Relaxed),
            framing: FRAMING.load(Relaxed),
            noise: NOISE.load(Relaxed),
            full: FULL.load(Relaxed),
        }
    }

    /// One interrupt of `ticks`.
    pub fn record(ticks: u32) {
        SPENT.fetch_add(ticks, Relaxed);
        MAX.fetch_max(ticks, Relaxed);
        COUNT.fetch_add(1, Relaxed);
    }

    /// Ticks spent in it so far (wrapping).
    pub fn spent() -> u32 {
        SPENT.load(Relaxed)
    }

    /// The largest, the count and the bytes the line lost (USART
    /// overruns, a full receive queue) so far.
    pub fn totals() -> (u32, u32, u32) {
        (MAX.load(Relaxed), COUNT.load(Relaxed), LOST.load(Relaxed))
    }

    /// `counter()` and the ticks spent so far, read together: a serial
    /// interrupt between the two reads is read again.
    pub fn stamp(counter: impl Fn() -> u32) -> (u32, u32) {
        loop {
            let a = spent();
            let t = counter();
            if spent() == a {
                return (t, a);
            }
        }
    }

    /// The control task's own ticks (the serial interrupt's left out): it
    /// preempts the link task, whose cost leaves both out.
    static CONTROL_SPENT: AtomicU32 = AtomicU32::new(0);

    /// The control task ran `ticks` of its own.
    pub fn record_control(ticks: u32) {
        CONTROL_SPENT.fetch_add(ticks, Relaxed);
    }

    /// `counter()` less every tick spent in the serial interrupt and the
    /// control task: the link task's own time.
    pub fn below_control(counter: impl Fn() -> u32) -> u32 {
        loop {
            let (a, b) = (spent(), CONTROL_SPENT.load(Relaxed));
            let t = counter();
            if spent() == a && CONTROL_SPENT.load(Relaxed) == b {
                return t.wrapping_sub(a).wrapping_sub(b);
            }
        }
    }
}

/// The zero-current DAC code, for the exception handlers (they own no
/// peripheral): the configuration's, set by the board's init (then the
/// saved calibration's) and kept current by the control task; mid-scale
/// until init. Unmangled: the HardFault entry reads it before it touches
/// the stack.
#[cfg(target_os = "none")]
#[allow(unsafe_code)] // An unmangled static (read by `HardFault`'s assembly).
#[no_mangle]
pub static HOPPER_DAC_ZERO_CODE: core::sync::atomic::AtomicU16 =
    core::sync::atomic::AtomicU16::new(2048);

#[cfg(target_os = "none")]
pub use HOPPER_DAC_ZERO_CODE as DAC_ZERO_CODE;

/// Both DAC channels (the leg's amplifier's, the hip's) at the zero-current
/// code, from any context (one store each to DHR12R1 and DHR12R2; ignored
/// while the DAC is not clocked). Both amplifiers are already off by then:
/// their enable is AMP_EN.
#[cfg(target_os = "none")]
pub fn zero_dac() {
    let code = DAC_ZERO_CODE.load(core::sync::atomic::Ordering::Relaxed);
    // SAFETY: `DAC::ptr()` is the fixed address of the DAC register block;
    // DHR12R1 takes a single store, so it cannot race with the owner's
    // writes in a way that matters (either value is a current command, and
    // the enable is already low).
    #[allow(unsafe_code)] // Needed to reach the DAC without owning it (fault path).
    let dac = unsafe { &*stm32f4::stm32f405::DAC::ptr() };
    dac.dhr12r1().write(|w| w.daccdhr().set(code & 0x0FFF));
    dac.dhr12r2().write(|w| w.daccdhr().set(code & 0x0FFF));
}

/// What both QEMU images share: the amplifier pin and the instruction
/// counter at start-up, SysTick's clock.
#[cfg(all(target_os = "none", feature = "qemu-sim"))]
pub mod qemu {
    use hopper_control::runner::{CycleCounter, Pacing};
    use stm32f4::stm32f405 as pac;

    /// QEMU clocks SysTick (and counts guest time) at the netduinoplus2's
    /// 168 MHz CPU clock, whatever the RCC says; with `-icount shift=0` one
    /// tick is 1/168 us of virtual time.
    pub const SYSTICK_HZ: u32 = 168_000_000;
    const _: () = assert!(SYSTICK_HZ.is_multiple_of(crate::control::CONTROL_HZ));

    /// Periods per 100 us of virtual time in both QEMU images: a period's
    /// deadline is 4,200 SysTick ticks, 25,000 instructions. Robot time is
    /// still 100 us a period (the runner's and the plant's `dt`; the plant
    /// advances with SysTick stopped). Not 1 (100,000 instructions a
    /// period): then most of QEMU's wall time is the busy idle between
    /// periods. The period's work within the deadline is the step (at most
    /// about 1,100 instructions), the link's (at most about 10,800) and the
    /// simulated sensors' noise (soft `f64`, the ADC's and the timers' work
    /// on the board); not 6 (16,667 instructions, a 168 MHz core's 100 us
    /// at one instruction per cycle): the sensor model can overrun that.
    pub const PACE: u32 = 4;
    /// SysTick ticks per control period.
    pub const PERIOD_TICKS: u32 = SYSTICK_HZ / crate::control::CONTROL_HZ / PACE;
    const _: () = assert!((SYSTICK_HZ / crate::control::CONTROL_HZ).is_multiple_of(PACE));

    /// TIM5 as the runner's counter: a free-running 32-bit counter that QEMU
    /// runs at 1 GHz of virtual time, so under `-icount shift=0` it counts
    /// guest instructions.
    pub struct Instructions {
        overhead: u32,
        /// The link task's: the control task's instructions left out too.
        below_control: bool,
        /// The clock at the control task's entry ([`Instructions::enter`]),
        /// until the runner reads it as the period's start.
        entry: Option<u32>,
    }

    impl Instructions {
        /// Another reader of the counter [`start`] started, for the link
        /// task (the control task's and the serial interrupt's
        /// instructions left out).
        pub fn reader() -> Self {
            let a = tim5_now();
            let b = tim5_now();
            Instructions {
                overhead: b.wrapping_sub(a),
                below_control: true,
                entry: None,
            }
        }

        /// The control task's entry: the period starts here, whatever the
        /// task does before the runner reads its clock (the link image's
        /// sensor models sample the plant first, in soft `f64`: up to
        /// about 6,700 instructions, which the board's ADC and timers do
        /// in hardware).
        pub fn enter(&mut self) {
            self.entry = Some(clock_now());
        }
    }

    /// TIM5 with SysTick running: less the plant's integration
    /// ([`with_systick_stopped`]).
    fn clock_now() -> u32 {
        tim5_now().wrapping_sub(STOPPED.load(Ordering::Relaxed))
    }

    impl CycleCounter for Instructions {
        /// Instructions of the running context: the serial interrupt's
        /// (which preempts it) left out, as QEMU delivers the host's bytes
        /// with no baud rate (the board's budget counts them per byte).
        #[inline(always)]
        fn now(&mut self) -> u32 {
            if self.below_control {
                return crate::serial_cost::below_control(tim5_now);
            }
            let (t, spent) = crate::serial_cost::stamp(tim5_now);
            t.wrapping_sub(spent)
        }
        fn overhead(&self) -> u32 {
            self.overhead
        }
        /// SysTick at the control rate, [`PERIOD_CLOCK_TICKS`] guest
        /// instructions a period (the control task's counter; the link
        /// task's reader checks nothing).
        fn pacing(&self) -> Pacing {
            if self.below_control {
                Pacing::NoClock
            } else {
                Pacing::Trigger {
                    ticks: PERIOD_CLOCK_TICKS,
                }
            }
        }
        /// Guest instructions with SysTick running (TIM5 less the plant's
        /// integration, which runs with SysTick stopped:
        /// [`with_systick_stopped`]), at the task's entry where it was
        /// marked ([`Instructions::enter`]).
        fn clock(&mut self) -> Option<u32> {
            Some(self.entry.take().unwrap_or_else(clock_now))
        }
    }

    /// TIM5 counts (guest instructions at 1 GHz of virtual time) per
    /// control period of [`PERIOD_TICKS`] at [`SYSTICK_HZ`]: 25,000.
    pub const PERIOD_CLOCK_TICKS: u32 =
        (PERIOD_TICKS as u64 * 1_000_000_000 / SYSTICK_HZ as u64) as u32;

    /// TIM5 counts spent with SysTick stopped so far (wrapping).
    static STOPPED: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);

    /// Runs `f` (the plant between two periods) with SysTick stopped, so
    /// that the simulated world takes no time from the firmware's point
    /// of view, and leaves its instructions out of the period clock.
    pub fn with_systick_stopped<R>(
        syst: &mut cortex_m::peripheral::SYST,
        f: impl FnOnce() -> R,
    ) -> R {
        syst.disable_counter();
        let t0 = tim5_now();
        let r = f();
        STOPPED.fetch_add(tim5_now().wrapping_sub(t0), Ordering::Relaxed);
        syst.enable_counter();
        r
    }

    /// TIM5's count now, from any task ([`start`] started it; the
    /// serial interrupt times itself with it).
    pub use crate::ticks::tim5_now;

    /// SysTick every `ticks` (a control period: `SYSTICK_HZ / CONTROL_HZ`),
    /// its interrupt on (the control task).
    pub fn start_systick(syst: &mut cortex_m::peripheral::SYST, ticks: u32) {
        syst.set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
        syst.set_reload(ticks - 1);
        syst.clear_current();
        syst.enable_interrupt();
        syst.enable_counter();
    }

    /// The stack's depth, measured: `idle` paints the free stack below
    /// its own frame with a pattern ([`paint_stack`]); at the end the
    /// lowest word no longer the pattern is how deep the tasks went
    /// ([`stack_depths`]).
    const PAINT: u32 = 0x5AA5_C33C;
    static PAINTED_FROM: AtomicUsize = AtomicUsize::new(0);
    static PAINTED_TO: AtomicUsize = AtomicUsize::new(0);
    use core::sync::atomic::{AtomicUsize, Ordering};

    extern "C" {
        static _stack_start: u32;
        static _stack_end: u32;
    }

    /// From `idle`, once: paints from 256 bytes below its stack pointer down
    /// to the end of the statics (the linker's `_stack_end`). A task that
    /// preempts it meanwhile runs below `idle`'s frame and is gone when
    /// `idle` paints on: nothing live is overwritten.
    #[allow(unsafe_code)] // Raw writes to the free stack below idle's frame.
    #[inline(never)]
    pub fn paint_stack() {
        let here = cortex_m::register::msp::read() as usize;
        let from = (here - 256) & !3;
        let to = (core::ptr::addr_of!(_stack_end) as usize + 3) & !3;
        let mut a = from;
        while a > to {
            a -= 4;
            // SAFETY: between the end of the statics and below idle's
            // frame: the free stack, used only by tasks that preempt idle,
            // which have returned whenever this runs.
            unsafe { core::ptr::write_volatile(a as *mut u32, PAINT) };
        }
        PAINTED_TO.store(to, Ordering::Relaxed);
        PAINTED_FROM.store(from, Ordering::Relaxed);
    }

    /// (`idle`'s depth, the deepest the stack went), bytes from its top;
    /// (0, 0) before [`paint_stack`] finished.
    #[allow(unsafe_code)] // Raw reads of the painted stack.
    pub fn stack_depths() -> (u32, u32) {
        let (from, to) = (
            PAINTED_FROM.load(Ordering::Relaxed),
            PAINTED_TO.load(Ordering::Relaxed),
        );
        if from == 0 {
            return (0, 0);
        }
        let top = core::ptr::addr_of!(_stack_start) as usize;
        let mut a = to;
        // SAFETY: the painted range, word-aligned, in RAM.
        while a < from && unsafe { core::ptr::read_volatile(a as *const u32) } == PAINT {
            a += 4;
        }
        ((top - from) as u32, (top - a) as u32)
    }

    /// What every fault path of the QEMU images ends in: `AMP_EN` low, the
    /// DAC at its zero code (as on the board), then QEMU's exit with
    /// failure through semihosting.
    pub fn exit_failure() -> ! {
        crate::disable_amplifier();
        crate::zero_dac();
        cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::nop();
        }
    }

    /// AMP_EN (PB0) low before anything else, as on the board; then TIM5
    /// free-running as the instruction counter.
    pub fn start(rcc: &pac::RCC, gpiob: &pac::GPIOB, tim5: pac::TIM5) -> Instructions {
        rcc.ahb1enr()
            .modify(|_, w| w.gpioaen().enabled().gpioben().enabled());
        let _ = rcc.ahb1enr().read();
        gpiob.bsrr().write(|w| w.br0().set_bit());
        gpiob.moder().modify(|_, w| w.moder0().output());

        rcc.apb1enr().modify(|_, w| w.tim5en().enabled());
        let _ = rcc.apb1enr().read();
        crate::ticks::run_tim5(&tim5);
        // Cost of reading the counter twice back to back, subtracted from
        // every measurement.
        let _ = tim5;
        Instructions {
            below_control: false,
            ..Instructions::reader()
        }
    }
}

/// The virtual robot the QEMU link image and `hopper-sih` run: the CI
/// session's mis-calibrated robot (as `hopper-sim serve`'s), its firmware
/// configured for the nominal machine and booting as the board's does
/// (disarmed, tethered, no arming before a tare and homing), the body held
/// [`virtual_robot::START_APEX_M`] up until armed, and its flash in RAM.
#[cfg(all(target_os = "none", any(feature = "qemu-sim", feature = "sih")))]
pub mod virtual_robot {
    use crate::control::{Bank, Slot, CONTROL_PERIOD_S, TIMING};
    use hopper_control::hopper::Strategy;
    use hopper_plant::Params;
    use hopper_sil::robot::{Miscalibration, VirtualRobot};
    use hopper_sil::sim_io::{firmware_config, SensorConfig, SimHal};

    /// Where the body is held until armed, m (toe height).
    pub const START_APEX_M: f64 = 0.05;

    /// The image's flash: RAM, kept while it runs (erased at every start).
    pub type Flash = hopper_store::Store<hopper_store::RamFlash<2, 2048>>;

    /// The robot (its runner in the bank's first slot, no calibration
    /// loaded), the bank's spare slots and the flash; `None` when a part
    /// refuses its configuration.
    pub fn session(bank: &'static mut Bank) -> Option<(VirtualRobot<Slot>, [Slot; 2], Flash)> {
        let params = Params::design();
        // The plant is the real machine, the firmware believes the
        // nominal one: the session's bring-up routines must find the
        // difference.
        let mis = Miscalibration::SESSION;
        // The board's defaults (energy-apex, 0.05 m, tethered); the host
        // chooses the controller and target over the link.
        let mut cfg = firmware_config(
            &params,
            &params,
            Strategy::default(),
            0.05,
            mis.believed_start_apex_m(START_APEX_M),
        );
        cfg.arming.require_tare = true;
        cfg.arming.require_home = true;
        let plant = mis.plant(params, START_APEX_M).ok()?;
        let (runner, spares) = crate::control::runner_in_bank(bank, cfg, TIMING).ok()?;
        let flash = Flash::new(hopper_store::RamFlash::new(), 0..4096).ok()?;
        let hal = mis.hal(
            SimHal::new(&cfg.calibration, &mis.sensors(SensorConfig::DEFAULT)),
            &plant,
        );
        let mut robot = VirtualRobot::new(plant, hal, runner, f64::from(CONTROL_PERIOD_S)).hold();
        robot.firmware.runner.load_calibration(None);
        Some((robot, spares, flash))
    }
}

/// The control interrupt's counter for the images whose periods are not
/// the board's timer's (`hopper-hil`, `hopper-sih`): the core's cycle
/// counter on a board; where it does not count (QEMU models no DWT), TIM5
/// free-running, which counts guest instructions under `-icount shift=0`.
#[cfg(target_os = "none")]
pub mod ticks {
    use stm32f4::stm32f405 as pac;

    /// Which counter runs.
    #[derive(Clone, Copy)]
    pub struct Ticks {
        dwt: bool,
        hz: u32,
    }

    /// Runs TIM5 (clocked) free from 0 to 2^32 - 1 at its input clock: under
    /// QEMU's `-icount shift=0`, one count per guest instruction.
    pub fn run_tim5(tim5: &pac::TIM5) {
        tim5.psc().write(|w| w.psc().set(0));
        tim5.arr().write(|w| w.arr().set(u32::MAX));
        tim5.egr().write(|w| w.ug().set_bit());
        tim5.cr1().modify(|_, w| w.cen().enabled());
    }

    /// TIM5's count now, from any task (free-running: the QEMU images'
    /// counter, and this one's where the core has no cycle counter).
    /// Each reading is marked by a `YIELD` (a hint: one instruction, no
    /// effect on a single core) that QEMU's execution trace shows: `cargo
    /// xtask qemu` weighs the instructions between two readings in cycles
    /// (the `*_cycles_est_max` figures). The mark is inside what the
    /// counter's overhead (two readings back to back) takes off.
    #[allow(unsafe_code)] // The marker, and a read of a free-running counter's register.
    pub fn tim5_now() -> u32 {
        // SAFETY: a hint instruction; it touches no memory or register.
        unsafe { core::arch::asm!("yield", options(nomem, nostack, preserves_flags)) };
        // SAFETY: `TIM5::ptr()` is its register block's fixed address; CNT
        // has no read side effect, and TIM5 is only written while it is
        // set up, before any task runs.
        unsafe { (*pac::TIM5::ptr()).cnt().read().bits() }
    }

    impl Ticks {
        /// Starts the cycle counter, or TIM5 (clocked) where that does not
        /// count.
        pub fn start(
            dcb: &mut cortex_m::peripheral::DCB,
            dwt: &mut cortex_m::peripheral::DWT,
            tim5: pac::TIM5,
            sysclk_hz: u32,
        ) -> Self {
            dcb.enable_trace();
            dwt.enable_cycle_counter();
            let a = cortex_m::peripheral::DWT::cycle_count();
            for _ in 0..16 {
                cortex_m::asm::nop();
            }
            if cortex_m::peripheral::DWT::cycle_count() != a {
                return Ticks {
                    dwt: true,
                    hz: sysclk_hz,
                };
            }
            run_tim5(&tim5);
            Ticks { dwt: false, hz: 0 }
        }

        /// The count now.
        #[inline(always)]
        pub fn raw(self) -> u32 {
            if self.dwt {
                cortex_m::peripheral::DWT::cycle_count()
            } else {
                tim5_now()
            }
        }
    }

    /// The control interrupt's counter: its own time, the serial
    /// interrupts that preempt it left out; and what paces its periods
    /// (the host's samples in `hopper-hil`, a slowing SysTick in
    /// `hopper-sih`: neither is a trigger at the control rate that the
    /// core clock could check, so [`Pacing`] says which, and `status`
    /// shows it).
    ///
    /// [`Pacing`]: hopper_control::runner::Pacing
    pub struct Control(pub Ticks, pub hopper_control::runner::Pacing);

    impl hopper_control::runner::CycleCounter for Control {
        #[inline(always)]
        fn now(&mut self) -> u32 {
            let t = self.0;
            let (now, spent) = crate::serial_cost::stamp(move || t.raw());
            now.wrapping_sub(spent)
        }
        fn hz(&self) -> u32 {
            self.0.hz
        }
        fn pacing(&self) -> hopper_control::runner::Pacing {
            self.1
        }
    }

    /// The link task's counter: its own time, the control and serial
    /// interrupts that preempt it left out.
    pub struct Link(pub Ticks);

    impl hopper_control::runner::CycleCounter for Link {
        fn now(&mut self) -> u32 {
            let t = self.0;
            crate::serial_cost::below_control(move || t.raw())
        }
        fn hz(&self) -> u32 {
            self.0.hz
        }
    }
}

/// The image's critical section, for the crates that take one (defmt's
/// logger above all): it raises BASEPRI to mask the tasks at
/// [`MASKED_PRIORITY`] and below, never the control task or the serial
/// interrupt above them. Mutual exclusion holds because no code at those
/// higher priorities takes a critical section: `cargo xtask size` checks
/// the board image's call graph for it (and for `cpsid`), so a log frame
/// costs the control trigger and the USART nothing, whatever its length.
#[cfg(target_os = "none")]
#[allow(unsafe_code)] // The `critical_section::Impl` contract is `unsafe`.
mod critical {
    use cortex_m::register::{basepri, basepri_max};

    /// The highest task priority a critical section masks: the link
    /// task's (main.rs). The control task (3) and the serial interrupt
    /// (4) run through it.
    pub const MASKED_PRIORITY: u8 = 2;

    /// BASEPRI's value for [`MASKED_PRIORITY`]: RTIC's logical priority
    /// `p` is the hardware level `(16 - p) << 4` with the F4's four
    /// priority bits (PM0214 4.2.7), and BASEPRI masks that level and
    /// every lower priority (higher value).
    pub const BASEPRI: u8 = ((1u8 << stm32f4::stm32f405::NVIC_PRIO_BITS) - MASKED_PRIORITY)
        << (8 - stm32f4::stm32f405::NVIC_PRIO_BITS);

    struct BasePri;
    critical_section::set_impl!(BasePri);

    // SAFETY: acquire only raises BASEPRI (`basepri_max`) and release puts
    // back what it read, so sections nest; nothing above
    // `MASKED_PRIORITY` enters one (checked on the image), so every
    // section excludes every other.
    unsafe impl critical_section::Impl for BasePri {
        #[inline(never)]
        unsafe fn acquire() -> critical_section::RawRestoreState {
            let old = basepri::read();
            basepri_max::write(BASEPRI);
            old
        }

        #[inline(never)]
        unsafe fn release(old: critical_section::RawRestoreState) {
            // SAFETY: `old` is what `acquire` read, an earlier level.
            unsafe { basepri::write(old) };
        }
    }
}

#[cfg(target_os = "none")]
pub use critical::{BASEPRI as CRITICAL_SECTION_BASEPRI, MASKED_PRIORITY};

/// The log queue's ends, the count of items it had no room for, and the
/// dump request: the control task's side never waits and never masks an
/// interrupt (a lock-free queue, atomics and a pend); the logger task, at
/// the lowest priority, drains it and prints.
#[cfg(target_os = "none")]
pub mod log {
    use crate::control::LOG_CAPACITY;
    use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
    use hopper_control::runner::LogItem;
    use stm32f4::stm32f405::Interrupt;

    /// The queue's length: it holds one less.
    pub const LOG_QUEUE: usize = LOG_CAPACITY + 1;
    /// The queue, [`LOG_CAPACITY`] items.
    pub type LogQueue = spsc::spsc::Queue<LogItem, LOG_QUEUE>;
    /// The control task's end.
    pub type Sender = spsc::spsc::Producer<'static, LogItem, LOG_QUEUE>;
    /// The logger's end.
    pub type Receiver = spsc::spsc::Consumer<'static, LogItem, LOG_QUEUE>;

    /// Items that found the queue full.
    static DROPPED: AtomicU32 = AtomicU32::new(0);
    /// A capture dump asked for and not yet begun.
    static DUMP: AtomicBool = AtomicBool::new(false);

    /// The control task's side of the log: an item that finds the queue
    /// full is dropped and counted.
    pub struct Log {
        tx: Sender,
        logger: Interrupt,
    }

    impl Log {
        /// Wraps the sending end; `logger` is the logger task's interrupt.
        pub fn new(tx: Sender, logger: Interrupt) -> Self {
            Self { tx, logger }
        }

        /// Queues `item` if there is room, and wakes the logger. Out of
        /// line: a hop or a fault, rarely, and the period's code stays as
        /// compact around it as without a log.
        #[inline(never)]
        pub fn push(&mut self, item: &LogItem) {
            if self.tx.enqueue(*item).is_err() {
                DROPPED.fetch_add(1, Ordering::Relaxed);
            }
            cortex_m::peripheral::NVIC::pend(self.logger);
        }

        /// Asks the logger for a capture dump.
        pub fn request_dump(&mut self) {
            DUMP.store(true, Ordering::Relaxed);
            cortex_m::peripheral::NVIC::pend(self.logger);
        }

        /// Items dropped so far.
        pub fn dropped(&self) -> u32 {
            dropped()
        }
    }

    /// Items dropped so far.
    pub fn dropped() -> u32 {
        DROPPED.load(Ordering::Relaxed)
    }

    /// Whether a dump was asked for since the last call.
    pub fn take_dump() -> bool {
        DUMP.swap(false, Ordering::Relaxed)
    }

    /// Control periods run, for the log's timestamps (the control task
    /// stores it once a period).
    pub static PERIODS: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);

    /// Microseconds since boot in control periods (wraps after 71 min at
    /// 10 kHz).
    pub fn now_us() -> u32 {
        PERIODS
            .load(core::sync::atomic::Ordering::Relaxed)
            .wrapping_mul(1_000_000 / crate::control::CONTROL_HZ)
    }

    /// Prints one item at info and warn level (the board).
    pub fn print(item: &LogItem) {
        match item {
            LogItem::Hop(h) => defmt::info!("hop {}", h),
            LogItem::Faults { step, faults } => {
                defmt::warn!("faults latched at step {=u32}: {}", step, faults)
            }
        }
    }

    /// Prints one item whatever the log level (QEMU: its run's log is the
    /// test's evidence, parsed by the xtask).
    pub fn print_always(item: &LogItem) {
        match item {
            LogItem::Hop(h) => defmt::println!("hop {}", h),
            LogItem::Faults { step, faults } => {
                defmt::println!("faults latched at step {=u32}: {}", step, faults)
            }
        }
    }
}

/// The fault paths every image defines the same way, ending in `$park`
/// ([`park`] on the board, `qemu::exit_failure` in QEMU): the panic
/// handler, the HardFault entry and its Rust part, NMI and the default
/// handler. A macro, not functions here: each binary chooses its own end,
/// and an exception handler must be linked into the binary that owns the
/// vector table.
///
/// HardFault (entered from its vector, through cortex-m-rt's trampoline
/// where the version has one, which uses no stack): before anything
/// touches the stack, which may be the fault (flip-link puts it below the
/// statics, so an overflow faults), AMP_EN is driven low (reset through
/// BSRR, then a GPIO output, off the deadman timer: the pin map's pin and
/// timer), the deadman timer's channel is forced inactive and its counter
/// stopped and cleared, and
/// the DAC takes the zero code ([`HOPPER_DAC_ZERO_CODE`]); then a fresh
/// stack at its top (`_stack_start`) for the Rust handler, which ends in
/// `$park`.
#[cfg(target_os = "none")]
#[macro_export]
macro_rules! fault_handlers {
    ($park:path) => {
        /// Panic: disable the amplifier before anything else, then the
        /// image's end.
        #[panic_handler]
        fn panic(_info: &core::panic::PanicInfo) -> ! {
            $crate::disable_amplifier();
            cortex_m::interrupt::disable();
            $park()
        }

        #[allow(unsafe_code)] // The handler's entry, in assembly: it must not use the stack.
        mod hard_fault_entry {
            core::arch::global_asm!(
                ".section .HardFault.user, \"ax\"",
                ".global HardFault",
                ".type HardFault, %function",
                ".thumb_func",
                "HardFault:",
                // GPIOB (0x4002_0400): BSRR = AMP_EN's reset bit, then
                // its MODER field = 0b01 (output).
                "ldr r0, =0x40020400",
                "ldr r1, ={bsrr}",
                "str r1, [r0, #0x18]",
                "ldr r1, [r0, #0x00]",
                "ldr r2, ={moder_mask}",
                "bic r1, r1, r2",
                "ldr r2, ={moder_output}",
                "orr r1, r1, r2",
                "str r1, [r0, #0x00]",
                // The deadman timer, as `deadman::force_off`: its channel
                // forced inactive (OCxM = 0b100 in its CCMR), whatever
                // the counter does; then CR1 = OPM, the counter stopped,
                // and CNT = 0.
                "ldr r0, ={deadman}",
                "ldr r1, [r0, #{ccmr}]",
                "bic r1, r1, #{ocm_mask}",
                "orr r1, r1, #{ocm_inactive}",
                "str r1, [r0, #{ccmr}]",
                "mov r1, #8",
                "str r1, [r0, #0x00]",
                "mov r1, #0",
                "str r1, [r0, #0x24]",
                // DAC (0x4000_7400): DHR12R1 and DHR12R2 (the hip's
                // channel) = the zero code.
                "ldr r0, =HOPPER_DAC_ZERO_CODE",
                "ldrh r1, [r0]",
                "ubfx r1, r1, #0, #12",
                "ldr r0, =0x40007400",
                "str r1, [r0, #0x08]",
                "str r1, [r0, #0x14]",
                // A fresh main stack, then the Rust part (it does not return).
                "ldr r0, =_stack_start",
                "msr msp, r0",
                "b hopper_hard_fault",
                ".ltorg",
                bsrr = const $crate::pinmap::AMP_EN_BSRR_RESET,
                moder_mask = const $crate::pinmap::AMP_EN_MODER_MASK,
                moder_output = const $crate::pinmap::AMP_EN_MODER_OUTPUT,
                deadman = const $crate::pinmap::DEADMAN_TIMER_ADDR,
                ccmr = const $crate::pinmap::DEADMAN_CCMR_OFFSET,
                ocm_mask = const $crate::pinmap::DEADMAN_OCM_MASK,
                ocm_inactive = const $crate::pinmap::DEADMAN_OCM_FORCE_INACTIVE,
            );
        }

        /// HardFault's Rust part, on a fresh stack: the same end as a panic.
        #[allow(unsafe_code)] // Unmangled: the assembly entry branches to it.
        #[no_mangle]
        extern "C" fn hopper_hard_fault() -> ! {
            $park()
        }

        /// NMI: the clock security system found the crystal stopped (the
        /// core now runs on the HSI, every rate derived from the crystal is
        /// wrong). Drop AMP_EN, zero the DAC, and wait for the watchdog's
        /// reset: the next boot runs on the HSI, reports `clock-fallback`
        /// and refuses to arm.
        #[cortex_m_rt::exception]
        #[allow(unsafe_code)] // cortex-m-rt requires the NMI handler to be `unsafe fn`.
        unsafe fn NonMaskableInt() {
            $park()
        }

        /// Every exception and interrupt without a handler of its own:
        /// outputs safe, then the image's end.
        #[cortex_m_rt::exception]
        #[allow(unsafe_code)] // cortex-m-rt requires the DefaultHandler to be `unsafe fn`.
        unsafe fn DefaultHandler(_irqn: i16) {
            $park()
        }
    };
}
