//! `hopper-fw`: the RTIC 2 controller firmware for the hopper, on an STM32F405.
//!
//! One binary, four `#[rtic::app]`s, chosen by Cargo feature (see
//! `Cargo.toml`); every image but the self-test runs the same control
//! period ([`hopper_control::runner::PeriodRunner`], which the host
//! simulator runs too), and they differ in their I/O and what paces them:
//!
//! * the board image (`board`, the default feature): the real board. A
//!   hardware timer (TIM4) triggers the ADC's injected conversions at
//!   `CONTROL_HZ`; their end-of-conversion interrupt runs the control task
//!   with fresh samples; the host link on USART1; the saved calibration in
//!   flash ([`flash`]). See [`board`] for clocks, pins and the watchdog.
//!   Two variants of it: `--features hse-12mhz` for boards with a 12 MHz
//!   crystal (the same image, other PLL constants), and `--features
//!   fault-test` for `cargo xtask board-init`, which moves the stack
//!   pointer off the SRAM after init to exercise the HardFault entry
//!   (never for a board).
//! * the self-test image (`--features selftest`): the board's `init`, then
//!   the loopback harness checks of [`hopper_control::selftest`] instead of
//!   the controller (docs/board.md, "Self-test"). Never with the amplifier
//!   connected.
//! * the QEMU scenario image (`--no-default-features --features qemu-sim`;
//!   `qemu-sim` takes precedence over `board`): QEMU's `netduinoplus2`.
//!   The `no_std` plant and sensor models of `hopper-plant` stand in for
//!   the hardware behind the same [`hopper_control::hal::HopperIo`] trait;
//!   SysTick paces the control task; the scripted scenario
//!   (`HOPPER_QEMU_SCENARIO` at build time: `energy-apex` or `shaped`)
//!   ends with a semihosting exit. `cargo xtask qemu` runs it.
//! * the QEMU link image (`--features qemu-link`, which turns on
//!   `qemu-sim`): the virtual robot (`hopper_plant::robot::VirtualRobot`)
//!   behind the host link on USART1, disarmed until `hopper-link` arms it.
//!   `cargo xtask qemu` runs the scripted link session against it.
//!
//! The panic-never link check is another binary (`src/bin/panic-check.rs`).
//! On the host this crate compiles to a stub `main` that says so, which keeps
//! `cargo clippy --workspace --all-targets` working.
//!
//! # Tasks
//! | Task      | Priority | Trigger |
//! |-----------|----------|---------|
//! | `usart1`  | 4        | USART1 (the host link's bytes; board; 3 in the QEMU link image, whose USART has no baud rate) |
//! | `control` | 3        | board: ADC injected end of conversion (TIM4 at `CONTROL_HZ`); QEMU: SysTick at `CONTROL_HZ` |
//! | `link`    | 2        | SDIO (spare), pended by `control` every period: decode, answer, encode, build sets (board and QEMU link image) |
//! | `logger`  | 1        | started in `init`; waits on the log channel (hop ledgers, faults) |
//! | `dump`    | 1        | board: spawned when the dump button is pressed; drains the capture |
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
pub mod control;

#[cfg(target_os = "none")]
pub mod serial;

#[cfg(all(target_os = "none", not(feature = "qemu-sim")))]
// The self-test uses the board's init and I/O, not its controller's parts.
#[cfg_attr(feature = "selftest", allow(dead_code))]
mod board;

#[cfg(all(target_os = "none", not(feature = "qemu-sim")))]
#[cfg_attr(feature = "selftest", allow(dead_code))]
mod flash;

#[cfg(all(target_os = "none", not(feature = "qemu-sim")))]
use defmt_rtt as _;

// Board logs carry the time since boot (the QEMU log stays bare: the xtask
// parses its lines).
#[cfg(all(target_os = "none", not(feature = "qemu-sim")))]
defmt::timestamp!("{=u32:us}", crate::log::now_us());

#[cfg(all(target_os = "none", feature = "qemu-sim"))]
use defmt_semihosting as _;

/// Drives the amplifier-enable pin (PB0) low with one atomic BSRR write.
///
/// Usable from any context, including the panic and fault handlers: it needs
/// no owned peripheral. If GPIOB is not clocked yet the write is ignored and
/// the external pull-down keeps the amplifier off.
#[cfg(target_os = "none")]
fn disable_amplifier() {
    // SAFETY: `GPIOB::ptr()` and `TIM3::ptr()` are the fixed addresses of
    // their register blocks. BSRR resets only PB0 (one store). Then PB0
    // leaves the deadman timer's alternate function for a GPIO output,
    // which drives the low just latched, whatever the timer does; and the
    // timer's output is forced low too. The MODER read-modify-write can
    // race with nothing: every other path that writes MODER runs in `init`
    // or in a fault handler, which does not return.
    #[allow(unsafe_code)] // Needed to reach GPIOB and TIM3 without owning them (panic path).
    let (gpiob, tim3) = unsafe {
        (
            &*stm32f4::stm32f405::GPIOB::ptr(),
            &*stm32f4::stm32f405::TIM3::ptr(),
        )
    };
    gpiob.bsrr().write(|w| w.br0().set_bit());
    gpiob.moder().modify(|_, w| w.moder0().output());
    tim3.ccmr2_output().modify(|_, w| w.oc3m().force_inactive());
    tim3.cr1().write(|w| w.cen().disabled());
}

/// Panic: disable the amplifier before anything else, then stop (QEMU: exit
/// with failure).
#[cfg(target_os = "none")]
#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    disable_amplifier();
    cortex_m::interrupt::disable();
    safe_and_parked()
}

/// What every fault path ends in: `AMP_EN` low, the DAC at its zero code,
/// then nothing until the watchdog resets the MCU (QEMU: exit with failure).
#[cfg(target_os = "none")]
fn safe_and_parked() -> ! {
    disable_amplifier();
    zero_dac();
    #[cfg(feature = "qemu-sim")]
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::nop();
    }
}

// HardFault (entered from its vector, through cortex-m-rt's trampoline
// where the version has one, which uses no stack):
// before anything touches the stack, which may be the fault (flip-link puts
// it below the statics, so an overflow faults), AMP_EN is driven low (PB0
// reset through BSRR, then a GPIO output, off the deadman timer), TIM3 is
// stopped, and the DAC takes the zero code; then a fresh stack at its top
// (`_stack_start`) for the Rust handler, which parks (the watchdog resets
// the MCU).
#[cfg(target_os = "none")]
#[allow(unsafe_code)] // The handler's entry, in assembly: it must not use the stack.
mod hard_fault {
    core::arch::global_asm!(
        ".section .HardFault.user, \"ax\"",
        ".global HardFault",
        ".type HardFault, %function",
        ".thumb_func",
        "HardFault:",
        // GPIOB (0x4002_0400): BSRR = BR0, then MODER0 = 0b01 (output).
        "ldr r0, =0x40020400",
        "mov r1, #0x10000",
        "str r1, [r0, #0x18]",
        "ldr r1, [r0, #0x00]",
        "bic r1, r1, #3",
        "orr r1, r1, #1",
        "str r1, [r0, #0x00]",
        // TIM3 (0x4000_0400): CR1 = 0, the counter stopped.
        "ldr r0, =0x40000400",
        "mov r1, #0",
        "str r1, [r0, #0x00]",
        // DAC (0x4000_7400): DHR12R1 = the zero code.
        "ldr r0, =HOPPER_DAC_ZERO_CODE",
        "ldrh r1, [r0]",
        "ubfx r1, r1, #0, #12",
        "ldr r0, =0x40007400",
        "str r1, [r0, #0x08]",
        // A fresh main stack, then the Rust part (it does not return).
        "ldr r0, =_stack_start",
        "msr msp, r0",
        "b hopper_hard_fault",
        ".ltorg",
    );
}

/// The fault test (`--features fault-test`, `cargo xtask board-init`).
#[cfg(all(target_os = "none", feature = "fault-test"))]
mod fault_test {
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

/// HardFault's Rust part, on a fresh stack: the same end as a panic.
#[cfg(target_os = "none")]
#[allow(unsafe_code)] // Unmangled: the assembly entry branches to it.
#[no_mangle]
extern "C" fn hopper_hard_fault() -> ! {
    safe_and_parked()
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

    /// The largest and the count so far.
    pub fn max_and_count() -> (u32, u32) {
        (MAX.load(Relaxed), COUNT.load(Relaxed))
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
static HOPPER_DAC_ZERO_CODE: core::sync::atomic::AtomicU16 =
    core::sync::atomic::AtomicU16::new(2048);

#[cfg(target_os = "none")]
use HOPPER_DAC_ZERO_CODE as DAC_ZERO_CODE;

/// The DAC's channel 1 at the zero-current code, from any context (one
/// store to DHR12R1; ignored while the DAC is not clocked).
#[cfg(target_os = "none")]
fn zero_dac() {
    let code = DAC_ZERO_CODE.load(core::sync::atomic::Ordering::Relaxed);
    // SAFETY: `DAC::ptr()` is the fixed address of the DAC register block;
    // DHR12R1 takes a single store, so it cannot race with the owner's
    // writes in a way that matters (either value is a current command, and
    // the enable is already low).
    #[allow(unsafe_code)] // Needed to reach the DAC without owning it (fault path).
    let dac = unsafe { &*stm32f4::stm32f405::DAC::ptr() };
    dac.dhr12r1().write(|w| w.daccdhr().set(code & 0x0FFF));
}

/// NMI: the clock security system found the crystal stopped (the core now
/// runs on the HSI, every rate derived from the crystal is wrong). Drop
/// AMP_EN, zero the DAC, and wait for the watchdog's reset: the next boot
/// runs on the HSI, reports `clock-fallback` and refuses to arm.
#[cfg(target_os = "none")]
#[cortex_m_rt::exception]
#[allow(unsafe_code)] // cortex-m-rt requires the NMI handler to be `unsafe fn`.
unsafe fn NonMaskableInt() {
    safe_and_parked()
}

/// Every exception and interrupt without a handler of its own: outputs
/// safe, then wait for the watchdog's reset.
#[cfg(target_os = "none")]
#[cortex_m_rt::exception]
#[allow(unsafe_code)] // cortex-m-rt requires the DefaultHandler to be `unsafe fn`.
unsafe fn DefaultHandler(_irqn: i16) {
    safe_and_parked()
}

/// What both QEMU images share: the amplifier pin and the instruction
/// counter at start-up, SysTick's clock.
#[cfg(all(target_os = "none", feature = "qemu-sim"))]
pub mod qemu {
    use hopper_control::runner::CycleCounter;
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
            }
        }
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
    }

    /// TIM5's count now, from any task ([`start`] started it; the
    /// serial interrupt times itself with it).
    #[allow(unsafe_code)]
    pub fn tim5_now() -> u32 {
        // SAFETY: a read of a free-running counter register, which has no
        // side effect; the only writes to TIM5 are `start`'s, before any
        // task runs.
        unsafe { (*pac::TIM5::ptr()).cnt().read().bits() }
    }

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
        tim5.psc().write(|w| w.psc().set(0));
        tim5.arr().write(|w| w.arr().set(u32::MAX));
        tim5.egr().write(|w| w.ug().set_bit());
        tim5.cr1().modify(|_, w| w.cen().enabled());
        // Cost of reading the counter twice back to back, subtracted from
        // every measurement.
        let _ = tim5;
        Instructions {
            below_control: false,
            ..Instructions::reader()
        }
    }
}

/// The log channel's ends and the count of items it had no room for.
#[cfg(target_os = "none")]
pub mod log {
    use crate::control::LOG_CAPACITY;
    use hopper_control::runner::LogItem;

    /// The control task's end.
    pub type Sender = rtic_sync::channel::Sender<'static, LogItem, LOG_CAPACITY>;
    /// The logger's end.
    pub type Receiver = rtic_sync::channel::Receiver<'static, LogItem, LOG_CAPACITY>;

    /// The control task's side of the log: never blocks; an item that finds
    /// the channel full is dropped and counted, and the count goes out with
    /// the next item that fits.
    pub struct Log {
        tx: Sender,
        dropped: u32,
    }

    impl Log {
        /// Wraps the sending end.
        pub fn new(tx: Sender) -> Self {
            Self { tx, dropped: 0 }
        }

        /// Queues `item` if there is room.
        pub fn push(&mut self, item: LogItem) {
            if self.tx.try_send(item).is_err() {
                self.dropped = self.dropped.saturating_add(1);
            }
        }

        /// Items dropped so far.
        pub fn dropped(&self) -> u32 {
            self.dropped
        }
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

    /// Prints one item (board: at info and warn level; QEMU: always, as
    /// its run's log is the test's evidence).
    pub fn print(item: &LogItem) {
        #[cfg(not(feature = "qemu-sim"))]
        match item {
            LogItem::Hop(h) => defmt::info!("hop {}", h),
            LogItem::Faults { step, faults } => {
                defmt::warn!("faults latched at step {=u32}: {}", step, faults)
            }
        }
        #[cfg(feature = "qemu-sim")]
        match item {
            LogItem::Hop(h) => defmt::println!("hop {}", h),
            LogItem::Faults { step, faults } => {
                defmt::println!("faults latched at step {=u32}: {}", step, faults)
            }
        }
    }
}

/// The board application.
#[cfg(all(
    target_os = "none",
    not(feature = "qemu-sim"),
    not(feature = "selftest")
))]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true, dispatchers = [FSMC, FPU])]
mod app {
    use crate::board::{self, BoardIo, CycleCounter, DumpButton, Watchdog};
    use crate::control::{Bank, Capture, Slot, CONTROL_HZ, LOG_CAPACITY, TIMING};
    use crate::log::{self, Log};
    use crate::serial::{LinkTx, RxQueue, Serial, TxQueue};
    use cortex_m::peripheral::NVIC;
    use heapless::spsc::{Consumer, Producer};
    use hopper_control::hopper::HopperConfig;
    use hopper_control::link::{
        Answer, AnswerQueue, Command, CommandQueue, ControlPort, Endpoint, LogQueue, Note,
        NoteQueue, Stats, StatsQueue,
    };
    use hopper_control::runner::{LogItem, PeriodRunner};
    use rtic::Mutex;
    use rtic_sync::make_channel;
    use stm32f4::stm32f405::Interrupt;

    /// The link task's interrupt: a spare one (the SD card interface is
    /// not used), pended by the control task every period.
    const LINK_IRQ: Interrupt = Interrupt::SDIO;

    /// The link task's own cycles (the control task's and the serial
    /// interrupt's that preempt it left out).
    struct LinkCycles;

    impl hopper_control::runner::CycleCounter for LinkCycles {
        fn now(&mut self) -> u32 {
            crate::serial_cost::below_control(cortex_m::peripheral::DWT::cycle_count)
        }
    }

    /// The capture through the RTIC lock: the link task copies a record or
    /// flips a flag under it (a few dozen cycles of the control priority).
    struct Locked<M>(M);

    impl<M: Mutex<T = &'static mut Capture>> hopper_control::link::Shared<Capture> for Locked<M> {
        fn with<R>(&mut self, f: impl FnOnce(&mut Capture) -> R) -> R {
            self.0.lock(|c| f(c))
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
        runner: PeriodRunner<Slot>,
        cycles: CycleCounter,
        log: Log,
        port: ControlPort,
        commands_out: Consumer<'static, Command<Slot>>,
        answers_in: Producer<'static, Answer<Slot>>,
        notes_in: Producer<'static, Note>,
        stats_in: Producer<'static, Stats>,
        logs_in: Producer<'static, LogItem>,
        link: Endpoint<Slot>,
        link_cycles: LinkCycles,
        commands_in: Producer<'static, Command<Slot>>,
        answers_out: Consumer<'static, Answer<Slot>>,
        notes_out: Consumer<'static, Note>,
        stats_out: Consumer<'static, Stats>,
        logs_out: Consumer<'static, LogItem>,
        link_rx: Consumer<'static, u8>,
        link_tx: LinkTx<'static>,
        serial: Serial<'static>,
    }

    #[init(local = [
        rxq: RxQueue = RxQueue::new(),
        txq: TxQueue = TxQueue::new(),
        capture: Capture = Capture::new(),
        commands: CommandQueue<Slot> = CommandQueue::new(),
        answers: AnswerQueue<Slot> = AnswerQueue::new(),
        notes: NoteQueue = NoteQueue::new(),
        stats: StatsQueue = StatsQueue::new(),
        logs: LogQueue = LogQueue::new(),
        bank: Bank = [None, None, None],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let mut cfg = HopperConfig::default();
        // TIM2 and TIM5 count the encoders over 32 bits.
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
        let (mut runner, spares) = match crate::control::runner_in_bank(cx.local.bank, cfg, TIMING)
        {
            Ok(r) => r,
            Err(e) => {
                crate::disable_amplifier();
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
        crate::DAC_ZERO_CODE.store(
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
        cycles.set_hz(board.io.sysclk_hz());
        if let Some(e) = board.stored.error {
            defmt::error!("calibration store: {=str}: the defaults run", e.name());
        }
        runner.load_calibration(board.stored.record());
        // The link task's copy of the configuration is the loaded one.
        let mut link = Endpoint::new(&runner).with_spares(spares);
        // The saved calibration (written by this init if a save waited).
        if let Some(ok) = board.stored.saved {
            link.save_done(ok, false);
            if ok {
                defmt::info!("calibration saved to flash");
            } else {
                defmt::error!("calibration save to flash failed");
            }
        }
        // The fault handlers' zero code is the calibrated one from here on.
        crate::DAC_ZERO_CODE.store(
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
        let (tx, rx) = make_channel!(LogItem, LOG_CAPACITY);
        if logger::spawn(rx).is_err() {
            defmt::error!("logger did not start: hop and fault logs are off");
        }
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
            "hopper-fw: board build ({=str}), control at {=u32} Hz, core clock {=u32} Hz, link on USART1 at {=u32} baud; disarmed until the host arms",
            board::CLOCK_PROFILE,
            board.io.control_hz(),
            board.io.sysclk_hz(),
            crate::serial::LINK_BAUD
        );
        let (commands_in, commands_out) = cx.local.commands.split();
        let (answers_in, answers_out) = cx.local.answers.split();
        let (notes_in, notes_out) = cx.local.notes.split();
        let (stats_in, stats_out) = cx.local.stats.split();
        let (logs_in, logs_out) = cx.local.logs.split();
        (
            Shared {
                capture: cx.local.capture,
            },
            Local {
                io: board.io,
                watchdog,
                dump: board.dump_button,
                runner,
                cycles,
                log: Log::new(tx),
                port: ControlPort::new(),
                commands_out,
                answers_in,
                notes_in,
                stats_in,
                logs_in,
                link,
                link_cycles: LinkCycles,
                commands_in,
                answers_out,
                notes_out,
                stats_out,
                logs_out,
                link_rx: rx_out,
                link_tx: LinkTx::new(tx_in),
                serial: board.serial,
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        #[cfg(feature = "fault-test")]
        crate::fault_test::hard_fault_off_the_stack();
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
    #[task(binds = ADC, priority = 3, local = [io, watchdog, dump, runner, cycles, log, port, commands_out, answers_in, notes_in, stats_in, logs_in, polls: u32 = 0], shared = [capture])]
    fn control(mut cx: control::Context) {
        let (t0, serial0) = crate::serial_cost::stamp(cortex_m::peripheral::DWT::cycle_count);
        if !cx.local.io.ack_control_irq() {
            return;
        }
        let runner = &mut *cx.local.runner;
        let p = runner.run_period(cx.local.io, cx.local.cycles);
        if p.feed_watchdog {
            cx.local.watchdog.feed();
        }
        let (port, commands, answers, notes, stats, logs) = (
            &mut *cx.local.port,
            &mut *cx.local.commands_out,
            &mut *cx.local.answers_in,
            &mut *cx.local.notes_in,
            &mut *cx.local.stats_in,
            &mut *cx.local.logs_in,
        );
        cx.shared
            .capture
            .lock(|c| port.after_period(runner, &p, c, commands, answers, notes, stats, logs));
        // A set or a routine may have moved the zero code: the fault
        // handlers write the one in use (one relaxed store).
        crate::DAC_ZERO_CODE.store(
            runner.hopper().config().calibration.dac_zero_code,
            core::sync::atomic::Ordering::Relaxed,
        );
        // A save waits in the RAM slot: `init` writes it after the reset
        // (never while armed: the port disarms first).
        if port.restart_due(runner) {
            crate::disable_amplifier();
            cortex_m::peripheral::SCB::sys_reset();
        }
        // The next conversion already finished: this period overran.
        runner.end_period(NVIC::is_pending(Interrupt::ADC));
        log::PERIODS.store(runner.periods(), core::sync::atomic::Ordering::Relaxed);
        if let Some(item) = p.log {
            cx.local.log.push(item);
        }
        *cx.local.polls = cx.local.polls.wrapping_add(1);
        if cx.local.polls.is_multiple_of(100) && cx.local.dump.pressed() {
            let _ = dump::spawn(cx.local.log.dropped());
        }
        rtic::pend(LINK_IRQ);
        let (irq_max, irq_count) = crate::serial_cost::max_and_count();
        port.set_serial_cost(irq_max, irq_count);
        // Entry to exit, less the serial interrupts that preempted it
        // (counted per byte in the budget, docs/link.md).
        let (t1, serial1) = crate::serial_cost::stamp(cortex_m::peripheral::DWT::cycle_count);
        let own = t1
            .wrapping_sub(t0)
            .wrapping_sub(serial1.wrapping_sub(serial0));
        port.add_isr_cost(own);
        crate::serial_cost::record_control(own);
    }

    /// The link task, below the control task, once a period: the notes and
    /// answers the control task published, the bytes received, decoded
    /// and answered, sets checked and their controllers built, frames
    /// encoded into the transmit ring; a save into the RAM slot for
    /// `init` to write after the reset the control task makes.
    #[task(binds = SDIO, priority = 2, local = [link, link_cycles, commands_in, answers_out, notes_out, stats_out, logs_out, link_rx, link_tx], shared = [capture])]
    fn link(cx: link::Context) {
        let link = &mut *cx.local.link;
        let rx = &mut *cx.local.link_rx;
        link.service(
            cx.local.notes_out,
            cx.local.stats_out,
            cx.local.logs_out,
            cx.local.answers_out,
            cx.local.commands_in,
            core::iter::from_fn(|| rx.dequeue()),
            &mut Locked(cx.shared.capture),
            cx.local.link_tx,
            cx.local.link_cycles,
        );
        if let Some(r) = link.take_save() {
            crate::flash::queue_save(r);
            link.save_done(true, true);
        }
    }

    /// The link's bytes in and out, above the control task: the USART has
    /// no receive FIFO (`serial`'s module docs). It times itself in core
    /// cycles.
    #[task(binds = USART1, priority = 4, local = [serial])]
    fn usart1(cx: usart1::Context) {
        let t0 = cortex_m::peripheral::DWT::cycle_count();
        cx.local.serial.on_interrupt();
        crate::serial_cost::record(cortex_m::peripheral::DWT::cycle_count().wrapping_sub(t0));
    }

    /// Logs hop ledgers and faults as the control task queues them.
    #[task(priority = 1)]
    async fn logger(_: logger::Context, mut rx: log::Receiver) {
        while let Ok(item) = rx.recv().await {
            log::print(&item);
        }
    }

    /// Prints the capture (the dump button), oldest first; it stays in
    /// place (the link's `dump` reads the same records).
    #[task(priority = 1, shared = [capture])]
    async fn dump(mut cx: dump::Context, log_dropped: u32) {
        let (n, frozen, fault_step) = cx
            .shared
            .capture
            .lock(|c| (c.len(), c.frozen(), c.fault_step().unwrap_or(0)));
        defmt::info!(
            "capture dump begins: {=usize} records, frozen by a fault: {=bool} (step {=u32})",
            n,
            frozen,
            fault_step
        );
        for i in 0..n {
            if let Some(r) = cx.shared.capture.lock(|c| c.get(i).copied()) {
                defmt::info!("{}", r);
            }
        }
        defmt::info!("capture dump ends ({=u32} log items dropped)", log_dropped);
    }
}

/// The on-target self-test (`--features selftest`): the board's `init`,
/// then one [`hopper_control::selftest`] step per control period on the
/// loopback harness (docs/board.md, "Self-test"), the verdicts over defmt.
#[cfg(all(target_os = "none", feature = "selftest", not(feature = "qemu-sim")))]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true)]
mod app {
    use crate::board::{self, BoardIo, Watchdog};
    use crate::control::CONTROL_HZ;
    use crate::serial::{RxQueue, TxQueue};
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
    #[allow(unsafe_code)] // GPIOC belongs to the board (PC13); these pins are free.
    fn harness_pins() {
        // SAFETY: GPIOC's other pins are only PC13 (an input the self-test
        // does not use); the writes below touch PC6..PC12 alone.
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

/// The QEMU application: the same period runner on the simulated hopper.
#[cfg(all(target_os = "none", feature = "qemu-sim", not(feature = "qemu-link")))]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true, dispatchers = [FSMC])]
mod app {
    use crate::control::{Capture, CONTROL_HZ, CONTROL_PERIOD_S, LOG_CAPACITY, TIMING};
    use crate::log::{self, Log};
    use cortex_m::peripheral::{SCB, SYST};
    use cortex_m_semihosting::debug;
    use hopper_control::hopper::{ApexLoop, Strategy};
    use hopper_control::laws::shaped;
    use hopper_control::runner::{LogItem, PeriodRunner};
    use hopper_plant::metrics::{hops_to_converge, steady_apex};
    use hopper_plant::mock::{firmware_config, SensorConfig, SimHal};
    use hopper_plant::{Event, Params, Plant};
    use rtic_sync::make_channel;

    /// The scenario the build asked for (`HOPPER_QEMU_SCENARIO`: `energy-apex`,
    /// the default, or `shaped`); any other name fails the build.
    const SHAPED: bool = match scenario(option_env!("HOPPER_QEMU_SCENARIO")) {
        Some(shaped) => shaped,
        None => panic!("HOPPER_QEMU_SCENARIO must be `energy-apex` or `shaped`"),
    };

    /// `Some(true)` for `shaped`, `Some(false)` for `energy-apex` or no
    /// value, `None` for anything else.
    const fn scenario(s: Option<&str>) -> Option<bool> {
        let Some(s) = s else {
            return Some(false);
        };
        if same(s.as_bytes(), b"shaped") {
            Some(true)
        } else if same(s.as_bytes(), b"energy-apex") {
            Some(false)
        } else {
            None
        }
    }

    /// Byte-wise equality in a `const fn`.
    #[allow(clippy::indexing_slicing)] // const evaluation, bounds checked by the loop.
    const fn same(a: &[u8], b: &[u8]) -> bool {
        if a.len() != b.len() {
            return false;
        }
        let mut i = 0;
        while i < a.len() {
            if a[i] != b[i] {
                return false;
            }
            i += 1;
        }
        true
    }

    /// The scripted scenario, default sensor noise with seed 1, design
    /// parameters. `energy-apex` (default): the apex-regulating energy law
    /// dropped from 0.10 m, 0.05 m target, 12 s, i.e. `hopper-sim run --params
    /// design --controller energy-apex --start-apex 0.10 --target-apex 0.05
    /// --duration 12` on the host. `shaped`: the shaped-torque law from
    /// 0.05 m to the thesis's 0.15 m, 10 s (`--controller shaped --start-apex
    /// 0.05 --target-apex 0.15 --duration 10`).
    pub const START_APEX_M: f64 = if SHAPED { 0.05 } else { 0.10 };
    /// Apex target, m.
    pub const TARGET_APEX_M: f64 = if SHAPED { 0.15 } else { 0.05 };
    /// Scenario name, as printed.
    const SCENARIO: &str = if SHAPED { "shaped" } else { "energy-apex" };
    /// Simulated time, s (12 or 10; `HOPPER_QEMU_SECONDS` at build time
    /// overrides it for quick profiling runs).
    pub const DURATION_S: u32 = crate::control::parse_u32(
        option_env!("HOPPER_QEMU_SECONDS"),
        if SHAPED { 10 } else { 12 },
    );
    /// Apexes kept for the summary.
    const MAX_APEXES: usize = 128;
    /// Periods the run goes on after a fault latched (showing the command
    /// stays at zero) before it stops.
    const SAFE_PERIODS_AFTER_FAULT: u32 = 100;

    /// The simulated hopper and what the summary reports.
    pub struct Sim {
        plant: Plant,
        hal: SimHal,
        apexes: heapless::Vec<f64, MAX_APEXES>,
        /// Period the first fault latched in, if any.
        fault_period: Option<u32>,
        /// Largest |current| commanded (DAC and enable) after the first fault, A.
        max_current_after_fault_a: f32,
    }

    #[shared]
    struct Shared {
        /// The capture: a static built in place, as the board's (32 KiB
        /// off `init`'s stack).
        capture: &'static mut Capture,
    }

    #[local]
    struct Local {
        runner: PeriodRunner,
        sim: Sim,
        counter: crate::qemu::Instructions,
        syst: SYST,
        log: Log,
    }

    #[init(local = [capture: Capture = Capture::new()])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;
        let mut core = cx.core;
        let counter = crate::qemu::start(&dp.RCC, &dp.GPIOB, dp.TIM5);

        let params = Params::design();
        let mut cfg = firmware_config(
            &params,
            &params,
            if SHAPED {
                Strategy::Shaped(shaped::Config::default())
            } else {
                Strategy::EnergyApex(ApexLoop::default())
            },
            TARGET_APEX_M,
            START_APEX_M,
        );
        // The scenario is the operator: no link (untethered), and one arm
        // request, decided at the first period like any other (the runner
        // boots disarmed).
        cfg.arming.untethered = true;
        let (Ok(plant), Ok(mut runner)) = (
            Plant::new(params, START_APEX_M),
            PeriodRunner::new(cfg, TIMING),
        ) else {
            defmt::error!("scenario set-up failed");
            debug::exit(debug::EXIT_FAILURE);
            #[allow(clippy::empty_loop)]
            loop {}
        };
        runner.arming_mut().request_arm();
        let hal = SimHal::new(&cfg.calibration, &SensorConfig::DEFAULT);
        let (tx, rx) = make_channel!(LogItem, LOG_CAPACITY);
        if logger::spawn(rx).is_err() {
            defmt::error!("logger did not start");
        }

        crate::qemu::start_systick(&mut core.SYST, crate::qemu::PERIOD_TICKS);
        defmt::println!(
            "hopper-fw: QEMU build, {=str} scenario, {=u32} Hz, {=u32} s",
            SCENARIO,
            CONTROL_HZ,
            DURATION_S
        );
        (
            Shared {
                capture: cx.local.capture,
            },
            Local {
                runner,
                sim: Sim {
                    plant,
                    hal,
                    apexes: heapless::Vec::new(),
                    fault_period: None,
                    max_current_after_fault_a: 0.0,
                },
                counter,
                syst: core.SYST,
                log: Log::new(tx),
            },
        )
    }

    /// Busy idle: QEMU 7.2 loses SysTick ticks while the core sleeps in `wfi`.
    #[idle]
    fn idle(_: idle::Context) -> ! {
        crate::qemu::paint_stack();
        loop {
            cortex_m::asm::nop();
        }
    }

    /// One control period through the runner, on the simulated sensors and
    /// amplifier, then the plant integrated to the next tick.
    ///
    /// The plant is integrated with SysTick stopped: the simulated world
    /// takes no time from the firmware's point of view, so it cannot delay
    /// the next control period however long an event search takes (soft
    /// `f64` on the M4F). A missed deadline then means the firmware's own
    /// work (the period, logging) overran.
    #[task(binds = SysTick, priority = 3, local = [runner, sim, counter, syst, log], shared = [capture])]
    fn control(mut cx: control::Context) {
        let sim = &mut *cx.local.sim;
        let runner = &mut *cx.local.runner;
        let p = {
            let mut io = sim.hal.io(&sim.plant);
            runner.run_period(&mut io, cx.local.counter)
        };
        cx.shared
            .capture
            .lock(|c| c.record(&p.out.record, !p.newly_latched.is_empty()));
        if let Some(item) = p.log {
            cx.local.log.push(item);
        }

        // The plant between this tick and the next (not part of the period).
        cx.local.syst.disable_counter();
        let current_a = sim.hal.mean_current_a(f64::from(CONTROL_PERIOD_S));
        let apexes = &mut sim.apexes;
        let advanced = sim
            .plant
            .advance(f64::from(CONTROL_PERIOD_S), current_a, &mut |e| {
                if let Event::Apex { toe_height_m, .. } = e {
                    defmt::println!("apex {=usize} {=f64}", apexes.len() + 1, toe_height_m);
                    let _ = apexes.push(toe_height_m);
                }
            });
        if advanced.is_err() {
            defmt::error!("plant integration failed");
            debug::exit(debug::EXIT_FAILURE);
        }
        cx.local.syst.enable_counter();
        // The next tick came before this one finished: a missed deadline.
        runner.end_period(SCB::is_pendst_pending());
        let period = runner.periods();
        if runner.hopper().supervisor().is_faulted() {
            let first = *sim.fault_period.get_or_insert(period);
            let commanded = sim.hal.commanded_current_a().abs() as f32;
            if period > first {
                sim.max_current_after_fault_a = sim.max_current_after_fault_a.max(commanded);
            }
            // Keep running a little to show the command stays at zero, then stop.
            if period >= first + SAFE_PERIODS_AFTER_FAULT {
                finish(sim, runner, cx.local.log);
            }
        }
        if period >= DURATION_S * CONTROL_HZ {
            finish(sim, runner, cx.local.log);
        }
    }

    /// Logs the summary and exits QEMU: success only if the hop converged
    /// and no fault or deadline miss occurred.
    fn finish(sim: &Sim, runner: &PeriodRunner, log: &Log) -> ! {
        let (stack_idle_b, stack_peak_b) = crate::qemu::stack_depths();
        let steady = steady_apex(&sim.apexes);
        let converged = hops_to_converge(&sim.apexes, TARGET_APEX_M, 0.02);
        let faults = runner.hopper().supervisor().faults();
        let cost = runner.step_cost();
        defmt::println!(
            "summary steady_apex_m={=f64} hops_to_converge={=i32} step_instr_min={=u32} step_instr_mean={=u32} step_instr_max={=u32} missed={=u32} faults={=u16} periods={=u32} fault_period={=i64} amp_enabled={=bool} max_current_after_fault_a={=f32} log_dropped={=u32} stack_idle_b={=u32} stack_peak_b={=u32} log_frame_instr_max={=u32}",
            steady.unwrap_or(-1.0),
            converged.map_or(-1, |k| i32::try_from(k).unwrap_or(i32::MAX)),
            cost.min,
            cost.mean(),
            cost.max,
            runner.missed(),
            faults.0,
            runner.periods(),
            sim.fault_period.map_or(-1, i64::from),
            sim.hal.amp_enabled(),
            sim.max_current_after_fault_a,
            log.dropped(),
            stack_idle_b,
            stack_peak_b,
            LOG_FRAME_MAX.load(core::sync::atomic::Ordering::Relaxed)
        );
        let ok = converged.is_some() && faults.is_empty() && runner.missed() == 0;
        debug::exit(if ok {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        });
        #[allow(clippy::empty_loop)]
        loop {}
    }

    /// Logs hop ledgers and faults as they happen.
    #[task(priority = 1)]
    async fn logger(_: logger::Context, mut rx: log::Receiver) {
        while let Ok(item) = rx.recv().await {
            // Timed: a defmt frame holds its logger's critical section
            // (interrupts masked) from start to end (docs/safety.md,
            // "Logging").
            let t0 = crate::qemu::tim5_now();
            log::print(&item);
            LOG_FRAME_MAX.fetch_max(
                crate::qemu::tim5_now().wrapping_sub(t0),
                core::sync::atomic::Ordering::Relaxed,
            );
        }
    }

    /// The largest log item's print, instructions (its frames and the
    /// interrupts masked meanwhile).
    static LOG_FRAME_MAX: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);
}

/// The QEMU link image (`--features qemu-link`): the virtual robot
/// (`hopper_plant::robot::VirtualRobot`, which `hopper-sim serve` runs too)
/// with the host link on USART1, which QEMU wires to its first `-serial`
/// (the xtask gives it a TCP socket). Its tasks are the board's: the
/// control period with the link's port at priority 3, the link task at 2,
/// the serial interrupt at 4. Like the board it boots disarmed and
/// tethered, so nothing moves until `hopper-link` arms it; the body is held
/// 0.05 m up until then (`VirtualRobot::held`). It runs until QEMU is
/// stopped, or `LINK_LIMIT_S` of robot time.
#[cfg(all(target_os = "none", feature = "qemu-link"))]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true, dispatchers = [FSMC])]
mod app {
    use crate::control::{Bank, Capture, Slot, CONTROL_HZ, CONTROL_PERIOD_S, TIMING};
    use crate::serial::{LinkTx, RxQueue, Serial, TxQueue};
    use cortex_m::peripheral::{SCB, SYST};
    use cortex_m_semihosting::debug;
    use heapless::spsc::{Consumer, Producer};
    use hopper_control::hopper::Strategy;
    use hopper_control::link::{
        Answer, AnswerQueue, Command, CommandQueue, Endpoint, LogQueue, Note, NoteQueue, Stats,
        StatsQueue,
    };
    use hopper_control::runner::LogItem;
    use hopper_plant::mock::{firmware_config, SensorConfig, SimHal};
    use hopper_plant::robot::{Miscalibration, VirtualRobot};
    use hopper_plant::Params;
    use rtic::Mutex;
    use stm32f4::stm32f405::Interrupt;

    /// Where the body is held until armed, m (toe height).
    const START_APEX_M: f64 = 0.05;
    /// The longest a session may run, s of robot time (then QEMU exits).
    const LINK_LIMIT_S: u32 = 600;
    /// PCLK2 on the HSI, Hz (QEMU has no RCC model, and ignores the baud
    /// rate anyway).
    const PCLK2_HZ: u32 = 16_000_000;
    /// The link task's interrupt, as on the board.
    const LINK_IRQ: Interrupt = Interrupt::SDIO;

    /// The capture, behind RTIC's lock for the link task.
    struct Locked<M>(M);

    impl<M: Mutex<T = &'static mut Capture>> hopper_control::link::Shared<Capture> for Locked<M> {
        fn with<R>(&mut self, f: impl FnOnce(&mut Capture) -> R) -> R {
            self.0.lock(|c| f(c))
        }
    }

    #[shared]
    struct Shared {
        /// The capture, frozen around a fault: a static built in place, as
        /// the board's (32 KiB; inside the robot, built in `init` and moved,
        /// it would take `init`'s stack past the room flip-link leaves).
        capture: &'static mut Capture,
    }

    /// The link image's flash: RAM (QEMU models no flash writes), kept for
    /// the run only.
    type Flash = hopper_store::Store<hopper_store::RamFlash<2, 2048>>;

    #[local]
    struct Local {
        robot: VirtualRobot<Slot>,
        commands_out: Consumer<'static, Command<Slot>>,
        answers_in: Producer<'static, Answer<Slot>>,
        notes_in: Producer<'static, Note>,
        stats_in: Producer<'static, Stats>,
        logs_in: Producer<'static, LogItem>,
        counter: crate::qemu::Instructions,
        syst: SYST,
        link: Endpoint<Slot>,
        link_counter: crate::qemu::Instructions,
        commands_in: Producer<'static, Command<Slot>>,
        answers_out: Consumer<'static, Answer<Slot>>,
        notes_out: Consumer<'static, Note>,
        stats_out: Consumer<'static, Stats>,
        logs_out: Consumer<'static, LogItem>,
        flash: Flash,
        link_rx: Consumer<'static, u8>,
        link_tx: LinkTx<'static>,
        serial: Serial<'static>,
    }

    #[init(local = [
        rxq: RxQueue = RxQueue::new(),
        txq: TxQueue = TxQueue::new(),
        capture_buf: Capture = Capture::new(),
        commands: CommandQueue<Slot> = CommandQueue::new(),
        answers: AnswerQueue<Slot> = AnswerQueue::new(),
        notes: NoteQueue = NoteQueue::new(),
        stats: StatsQueue = StatsQueue::new(),
        logs: LogQueue = LogQueue::new(),
        bank: Bank = [None, None, None],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;
        let mut core = cx.core;
        let counter = crate::qemu::start(&dp.RCC, &dp.GPIOB, dp.TIM5);

        let params = Params::design();
        // The CI session's mis-calibrated robot (as `hopper-sim serve`'s):
        // the firmware configured for the nominal machine, the plant the
        // real one; the session's bring-up routines must find the
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
        // As the board: no arming before a tare and homing.
        cfg.arming.require_tare = true;
        cfg.arming.require_home = true;
        let (Ok(plant), Ok((runner, spares))) = (
            mis.plant(params, START_APEX_M),
            crate::control::runner_in_bank(cx.local.bank, cfg, TIMING),
        ) else {
            defmt::error!("link image set-up failed");
            debug::exit(debug::EXIT_FAILURE);
            #[allow(clippy::empty_loop)]
            loop {}
        };
        let hal = mis.hal(
            SimHal::new(&cfg.calibration, &mis.sensors(SensorConfig::DEFAULT)),
            &plant,
        );
        let mut robot = VirtualRobot::new(plant, hal, runner, f64::from(CONTROL_PERIOD_S)).hold();
        // Its flash is erased at every start: nothing saved.
        let Ok(flash) = Flash::new(hopper_store::RamFlash::new(), 0..4096) else {
            defmt::error!("link image flash set-up failed");
            debug::exit(debug::EXIT_FAILURE);
            #[allow(clippy::empty_loop)]
            loop {}
        };
        robot.runner.load_calibration(None);
        // The link task's own endpoint (the robot's in-line one is for the
        // simulator's single thread).
        let link = Endpoint::simulated(&robot.runner).with_spares(spares);

        let (rx_in, rx_out) = cx.local.rxq.split();
        let (tx_in, tx_out) = cx.local.txq.split();
        let serial = Serial::new(dp.USART1, &dp.RCC, &dp.GPIOA, PCLK2_HZ, rx_in, tx_out);
        let (commands_in, commands_out) = cx.local.commands.split();
        let (answers_in, answers_out) = cx.local.answers.split();
        let (notes_in, notes_out) = cx.local.notes.split();
        let (stats_in, stats_out) = cx.local.stats.split();
        let (logs_in, logs_out) = cx.local.logs.split();

        crate::qemu::start_systick(&mut core.SYST, crate::qemu::PERIOD_TICKS);
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
                commands_out,
                answers_in,
                notes_in,
                stats_in,
                logs_in,
                counter,
                syst: core.SYST,
                link,
                link_counter: crate::qemu::Instructions::reader(),
                commands_in,
                answers_out,
                notes_out,
                stats_out,
                logs_out,
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
    #[task(binds = SysTick, priority = 3, local = [robot, commands_out, answers_in, notes_in, stats_in, logs_in, counter, syst], shared = [capture])]
    fn control(mut cx: control::Context) {
        let (t0, serial0) = crate::serial_cost::stamp(crate::qemu::tim5_now);
        let robot = &mut *cx.local.robot;
        let (commands, answers, notes, stats, logs, counter) = (
            &mut *cx.local.commands_out,
            &mut *cx.local.answers_in,
            &mut *cx.local.notes_in,
            &mut *cx.local.stats_in,
            &mut *cx.local.logs_in,
            &mut *cx.local.counter,
        );
        let (irq_max, irq_count) = crate::serial_cost::max_and_count();
        robot.port.set_serial_cost(irq_max, irq_count);
        cx.shared
            .capture
            .lock(|c| robot.control_period(c, commands, answers, notes, stats, logs, counter));
        cx.local.syst.disable_counter();
        if robot.advance(&mut |_| {}).is_err() {
            defmt::error!("plant integration failed");
            debug::exit(debug::EXIT_FAILURE);
        }
        cx.local.syst.enable_counter();
        robot.runner.end_period(SCB::is_pendst_pending());
        rtic::pend(LINK_IRQ);
        // The whole handler (the plant too) preempts the link task.
        let (t1, serial1) = crate::serial_cost::stamp(crate::qemu::tim5_now);
        crate::serial_cost::record_control(
            t1.wrapping_sub(t0)
                .wrapping_sub(serial1.wrapping_sub(serial0)),
        );
        if robot.runner.periods() >= LINK_LIMIT_S * CONTROL_HZ {
            defmt::println!("link image: {=u32} s limit reached", LINK_LIMIT_S);
            debug::exit(debug::EXIT_SUCCESS);
        }
    }

    /// The link task, below the control period (as the board's): a save
    /// goes to the RAM flash at once (the board defers it to its next
    /// boot).
    #[task(binds = SDIO, priority = 2, local = [link, link_counter, commands_in, answers_out, notes_out, stats_out, logs_out, flash, link_rx, link_tx], shared = [capture])]
    fn link(cx: link::Context) {
        let link = &mut *cx.local.link;
        let rx = &mut *cx.local.link_rx;
        link.service(
            cx.local.notes_out,
            cx.local.stats_out,
            cx.local.logs_out,
            cx.local.answers_out,
            cx.local.commands_in,
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
        let t0 = crate::qemu::tim5_now();
        cx.local.serial.on_interrupt();
        crate::serial_cost::record(crate::qemu::tim5_now().wrapping_sub(t0));
    }
}
