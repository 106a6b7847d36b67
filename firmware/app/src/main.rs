//! `hopper-fw`: the RTIC 2 controller firmware for the hopper, on an STM32F405.
//!
//! Two builds of the same control step ([`hopper_control::hopper::Hopper`]):
//!
//! * `--features board` (the default): the real board. A hardware timer
//!   (TIM4) triggers the ADC's injected conversions at `CONTROL_HZ`; their
//!   end-of-conversion interrupt runs the control task with fresh samples.
//!   See [`board`] for clocks, pins and the watchdog.
//! * `--features qemu-sim` (takes precedence): QEMU's `netduinoplus2`. The
//!   `no_std` plant and sensor models of `hal-sim` stand in for the hardware
//!   behind the same [`hopper_control::hal::HopperIo`] trait; SysTick paces
//!   the control task; the scripted scenario ends with a semihosting exit.
//!
//! On the host this crate compiles to a stub `main` that says so, which keeps
//! `cargo clippy --workspace --all-targets` working.
//!
//! # Tasks
//! | Task      | Priority | Trigger |
//! |-----------|----------|---------|
//! | `control` | 3 (highest) | board: ADC injected end of conversion (TIM4 at `CONTROL_HZ`); QEMU: SysTick at `CONTROL_HZ` |
//! | `logger`  | 1        | spawned by `control` when a hop ends, a fault latches or a dump is asked for |
//! | `idle`    | 0        | busy loop (no `wfi`: QEMU 7.2 loses SysTick ticks while sleeping) |
//!
//! # Safety
//! At reset the amplifier-enable pin (PB0) floats and the external pull-down
//! keeps the amplifier off; `init` drives it low before anything else. The
//! panic handler and the HardFault handler drive it low first thing.
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(unsafe_code)]

/// Host stand-in: this binary only does something on the microcontroller.
#[cfg(not(target_os = "none"))]
fn main() {
    println!("hopper-fw is firmware: build it with --target thumbv7em-none-eabihf");
}

#[cfg(target_os = "none")]
pub mod control;

#[cfg(all(target_os = "none", not(feature = "qemu-sim")))]
mod board;

#[cfg(all(target_os = "none", not(feature = "qemu-sim")))]
use defmt_rtt as _;

#[cfg(all(target_os = "none", feature = "qemu-sim"))]
use defmt_semihosting as _;

/// Drives the amplifier-enable pin (PB0) low with one atomic BSRR write.
///
/// Usable from any context, including the panic and fault handlers: it needs
/// no owned peripheral. If GPIOB is not clocked yet the write is ignored and
/// the external pull-down keeps the amplifier off.
#[cfg(target_os = "none")]
fn disable_amplifier() {
    // SAFETY: `GPIOB::ptr()` is the fixed address of the GPIOB register block.
    // Writing BSRR only resets the pins whose BR bits are 1 (here PB0) and is a
    // single store, so it cannot race with other users of GPIOB.
    #[allow(unsafe_code)] // Needed to reach GPIOB without owning it (panic path).
    let gpiob = unsafe { &*stm32f4::stm32f405::GPIOB::ptr() };
    gpiob.bsrr().write(|w| w.br0().set_bit());
}

/// Panic: disable the amplifier before anything else, then stop (QEMU: exit
/// with failure).
#[cfg(target_os = "none")]
#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    disable_amplifier();
    cortex_m::interrupt::disable();
    disable_amplifier();
    #[cfg(feature = "qemu-sim")]
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::nop();
    }
}

/// HardFault: the same as a panic, without touching the (possibly corrupt) stack much.
#[cfg(target_os = "none")]
#[cortex_m_rt::exception]
#[allow(unsafe_code)] // cortex-m-rt requires the HardFault handler to be `unsafe fn`.
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    disable_amplifier();
    #[cfg(feature = "qemu-sim")]
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::nop();
    }
}

/// What the control task hands to the logger.
#[cfg(target_os = "none")]
#[derive(Clone, Copy, defmt::Format)]
pub enum LogItem {
    /// A hop ended (the firmware's own ledger).
    Hop(hopper_control::telemetry::HopLedger),
    /// A fault latched, with the control period it latched in.
    Faults {
        /// Control period number.
        step: u32,
        /// All latched faults (bit set, see `Fault::ALL`).
        faults: hopper_control::supervisor::Faults,
    },
}

#[cfg(target_os = "none")]
impl LogItem {
    /// What a period gives the logger: newly latched faults first (they
    /// matter more than a hop ledger in the same period), else a finished hop.
    fn after_step(
        out: &hopper_control::hopper::StepOutput,
        faults_before: hopper_control::supervisor::Faults,
    ) -> Option<Self> {
        if out.faults != faults_before {
            return Some(LogItem::Faults {
                step: out.record.step,
                faults: out.faults,
            });
        }
        out.hop.map(LogItem::Hop)
    }
}

/// Messages waiting for the logger.
#[cfg(target_os = "none")]
pub type LogQueue = heapless::Deque<LogItem, 16>;

/// The board application.
#[cfg(all(target_os = "none", not(feature = "qemu-sim")))]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true, dispatchers = [FSMC])]
mod app {
    use crate::board::{self, BoardIo, DumpButton, Watchdog};
    use crate::control::{Capture, CONTROL_HZ, CONTROL_PERIOD_S, OVERRUN_LIMIT};
    use crate::{LogItem, LogQueue};
    use cortex_m::peripheral::NVIC;
    use hopper_control::hal::HopperIo;
    use hopper_control::hopper::{Hopper, HopperConfig};
    use hopper_control::watchdog::{Decision, FeedPolicy};
    use stm32f4::stm32f405::Interrupt;

    #[shared]
    struct Shared {
        /// Per-step records, drained on request.
        capture: Capture,
        /// Hop ledgers and faults for the logger.
        log: LogQueue,
    }

    #[local]
    struct Local {
        io: BoardIo,
        watchdog: Watchdog,
        dump: DumpButton,
        hopper: Hopper,
        feed_policy: FeedPolicy,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let mut cfg = HopperConfig::default();
        // TIM2 and TIM5 count the encoders over 32 bits.
        cfg.calibration.motor_counter_bits = board::ENCODER_COUNTER_BITS;
        cfg.calibration.height_counter_bits = board::ENCODER_COUNTER_BITS;
        let board = board::init(cx.device, CONTROL_HZ, cfg.calibration.dac_zero_code);
        // Hopper::new only fails on an invalid configuration; the default is
        // valid (unit-tested). Should it fail, the control task never runs,
        // the watchdog is not fed, and the amplifier stays disabled.
        let Ok(mut hopper) = Hopper::new(cfg) else {
            defmt::error!("invalid controller configuration: amplifier stays off");
            crate::disable_amplifier();
            #[allow(clippy::empty_loop)]
            loop {}
        };
        let watchdog = board.watchdog;
        if watchdog.caused_last_reset() {
            // The control loop stopped or misbehaved last time: start faulted,
            // amplifier off, until someone looks (a reset of the latch).
            defmt::error!("watchdog reset: amplifier stays off (overrun latched)");
            hopper.supervisor_mut().report_overrun();
        }
        let feed_policy = FeedPolicy::for_hopper(hopper.config());
        defmt::info!("hopper-fw: board build, control at {=u32} Hz", CONTROL_HZ);
        (
            Shared {
                capture: Capture::new(),
                log: LogQueue::new(),
            },
            Local {
                io: board.io,
                watchdog,
                dump: board.dump_button,
                hopper,
                feed_policy,
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::nop();
        }
    }

    /// The control period: fresh ADC samples are in; read, step, write.
    #[task(binds = ADC, priority = 3, local = [io, watchdog, dump, hopper, feed_policy, polls: u32 = 0, late_in_a_row: u32 = 0], shared = [capture, log])]
    fn control(mut cx: control::Context) {
        if !cx.local.io.ack_control_irq() {
            return;
        }
        let before = cx.local.hopper.supervisor().faults();
        let out = cx.local.hopper.run_period(cx.local.io, CONTROL_PERIOD_S);
        // The next conversion already finished: this period overran. A few in
        // a row mean the loop cannot keep its rate: go safe.
        if NVIC::is_pending(Interrupt::ADC) {
            *cx.local.late_in_a_row += 1;
            if *cx.local.late_in_a_row >= OVERRUN_LIMIT {
                cx.local.hopper.supervisor_mut().report_overrun();
            }
        } else {
            *cx.local.late_in_a_row = 0;
        }
        // Fed only here, after a step whose output is consistent (see
        // `FeedPolicy`): if the control task stops or misbehaves, the MCU
        // resets with the amplifier disabled.
        match cx.local.feed_policy.after_step(&out) {
            Decision::Feed => cx.local.watchdog.feed(),
            Decision::Starve(_) => {
                let zero = cx.local.hopper.config().calibration.dac_zero_code;
                let _ = cx.local.io.write_dac(zero);
                let _ = cx.local.io.set_amp_enabled(false);
            }
        }
        cx.shared.capture.lock(|c| c.push(out.record));
        let item = LogItem::after_step(&out, before);
        *cx.local.polls = cx.local.polls.wrapping_add(1);
        let dump = cx.local.polls.is_multiple_of(100) && cx.local.dump.pressed();
        if let Some(item) = item {
            cx.shared.log.lock(|q| {
                let _ = q.push_back(item);
            });
        }
        if item.is_some() || dump {
            let _ = logger::spawn(dump);
        }
    }

    /// Logs hop ledgers and faults; on request, dumps the capture buffer.
    #[task(priority = 1, shared = [capture, log])]
    async fn logger(mut cx: logger::Context, dump: bool) {
        while let Some(item) = cx.shared.log.lock(|q| q.pop_front()) {
            match item {
                LogItem::Hop(h) => defmt::info!("hop {}", h),
                LogItem::Faults { step, faults } => {
                    defmt::warn!("faults latched at step {=u32}: {}", step, faults)
                }
            }
        }
        if dump {
            defmt::info!("capture dump begins");
            while let Some(r) = cx.shared.capture.lock(|c| c.pop()) {
                defmt::info!("{}", r);
            }
            let dropped = cx.shared.capture.lock(|c| c.dropped());
            defmt::info!("capture dump ends ({=u32} older records dropped)", dropped);
        }
    }
}

/// The QEMU application: the same control step on the simulated hopper.
#[cfg(all(target_os = "none", feature = "qemu-sim"))]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true, dispatchers = [FSMC])]
mod app {
    use crate::control::{Capture, StepStats, CONTROL_HZ, CONTROL_PERIOD_S, OVERRUN_LIMIT};
    use crate::{LogItem, LogQueue};
    use cortex_m::peripheral::syst::SystClkSource;
    use cortex_m::peripheral::{SCB, SYST};
    use cortex_m_semihosting::debug;
    use hal_sim::metrics::{hops_to_converge, steady_apex};
    use hal_sim::mock::{firmware_config, SensorConfig, SimHal};
    use hal_sim::{Event, Params, Plant};
    use hopper_control::hal::HopperIo;
    use hopper_control::hopper::{ApexLoop, Hopper, StepPart, Strategy};
    use hopper_control::laws::shaped;
    use stm32f4::stm32f405::TIM5;

    /// QEMU clocks SysTick (and counts guest time) at the netduinoplus2's
    /// 168 MHz CPU clock, whatever the RCC says; with `-icount shift=0` one
    /// tick is 1/168 us of virtual time.
    const SYSTICK_HZ: u32 = 168_000_000;
    const _: () = assert!(SYSTICK_HZ.is_multiple_of(CONTROL_HZ));

    /// Whether the build asked for the `shaped` scenario
    /// (`HOPPER_QEMU_SCENARIO=shaped`; anything else: `energy-apex`).
    const SHAPED: bool = is_shaped(option_env!("HOPPER_QEMU_SCENARIO"));

    const fn is_shaped(s: Option<&str>) -> bool {
        let Some(s) = s else {
            return false;
        };
        let (a, b) = (s.as_bytes(), b"shaped");
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

    /// The simulated hopper and the statistics of the run (the controller
    /// itself is a resource of its own, as on the board).
    pub struct Sim {
        plant: Plant,
        hal: SimHal,
        apexes: heapless::Vec<f64, MAX_APEXES>,
        step_instr: StepStats,
        parts: [StepStats; 6],
        timer_overhead: u32,
        missed: u32,
        missed_in_a_row: u32,
        /// Period the first fault latched in, if any.
        fault_period: Option<u32>,
        /// Largest |current| commanded (DAC and enable) after the first fault, A.
        max_current_after_fault_a: f32,
        period: u32,
    }

    #[shared]
    struct Shared {
        capture: Capture,
        log: LogQueue,
    }

    #[local]
    struct Local {
        hopper: Hopper,
        sim: Sim,
        tim5: TIM5,
        syst: SYST,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;
        let mut core = cx.core;
        // AMP_EN (PB0) low before anything else, as on the board.
        dp.RCC.ahb1enr().modify(|_, w| w.gpioben().enabled());
        let _ = dp.RCC.ahb1enr().read();
        dp.GPIOB.bsrr().write(|w| w.br0().set_bit());
        dp.GPIOB.moder().modify(|_, w| w.moder0().output());

        // TIM5: free-running 32-bit counter. QEMU runs it at 1 GHz of virtual
        // time, so under `-icount shift=0` it counts guest instructions.
        dp.RCC.apb1enr().modify(|_, w| w.tim5en().enabled());
        let _ = dp.RCC.apb1enr().read();
        let tim5 = dp.TIM5;
        tim5.psc().write(|w| w.psc().set(0));
        tim5.arr().write(|w| w.arr().set(u32::MAX));
        tim5.egr().write(|w| w.ug().set_bit());
        tim5.cr1().modify(|_, w| w.cen().enabled());
        // Cost of reading the counter twice back to back, subtracted from
        // every measurement.
        let a = tim5.cnt().read().bits();
        let b = tim5.cnt().read().bits();
        let timer_overhead = b.wrapping_sub(a);

        let params = Params::design();
        let cfg = firmware_config(
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
        let (Ok(plant), Ok(hopper)) = (Plant::new(params, START_APEX_M), Hopper::new(cfg)) else {
            defmt::error!("scenario set-up failed");
            debug::exit(debug::EXIT_FAILURE);
            #[allow(clippy::empty_loop)]
            loop {}
        };
        let hal = SimHal::new(&cfg.calibration, &SensorConfig::DEFAULT);

        core.SYST.set_clock_source(SystClkSource::Core);
        core.SYST.set_reload(SYSTICK_HZ / CONTROL_HZ - 1);
        core.SYST.clear_current();
        core.SYST.enable_interrupt();
        core.SYST.enable_counter();
        defmt::println!(
            "hopper-fw: QEMU build, {=str} scenario, {=u32} Hz, {=u32} s",
            SCENARIO,
            CONTROL_HZ,
            DURATION_S
        );
        (
            Shared {
                capture: Capture::new(),
                log: LogQueue::new(),
            },
            Local {
                hopper,
                sim: Sim {
                    plant,
                    hal,
                    apexes: heapless::Vec::new(),
                    step_instr: StepStats::new(),
                    parts: [StepStats::new(); 6],
                    timer_overhead,
                    missed: 0,
                    missed_in_a_row: 0,
                    fault_period: None,
                    max_current_after_fault_a: 0.0,
                    period: 0,
                },
                tim5,
                syst: core.SYST,
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

    /// One control period: sample the simulated sensors, run the control
    /// step (timed), write the DAC, then integrate the plant to the next tick.
    ///
    /// The plant is integrated with SysTick stopped: the simulated world
    /// takes no time from the firmware's point of view, so it cannot delay
    /// the next control period however long an event search takes (soft
    /// `f64` on the M4F). `missed` then counts periods where the firmware's
    /// own work (control step, I/O, logging) overran.
    #[task(binds = SysTick, priority = 3, local = [hopper, sim, tim5, syst], shared = [capture, log])]
    fn control(mut cx: control::Context) {
        let sim = &mut *cx.local.sim;
        let hopper = &mut *cx.local.hopper;
        let tim5 = &*cx.local.tim5;
        let raw = sim.hal.sample(&sim.plant);
        let before = hopper.supervisor().faults();
        // Odd periods time the control step proper, from the raw sample to the
        // DAC code (the `Supervise` mark; the hop ledger and the telemetry
        // record come after it); even periods time it part by part (the marks
        // cost a few instructions each, so they are kept out of the
        // whole-step figure).
        let out = if sim.period % 2 == 1 {
            let t0 = tim5.cnt().read().bits();
            let mut t_dac = t0;
            let out = hopper.step_marked(Some(&raw), CONTROL_PERIOD_S, &mut |p: StepPart| {
                if p == StepPart::Supervise {
                    t_dac = tim5.cnt().read().bits();
                }
            });
            sim.step_instr
                .add(t_dac.wrapping_sub(t0).saturating_sub(sim.timer_overhead));
            out
        } else {
            let mut last = tim5.cnt().read().bits();
            let overhead = sim.timer_overhead;
            let parts = &mut sim.parts;
            hopper.step_marked(Some(&raw), CONTROL_PERIOD_S, &mut |p: StepPart| {
                let now = tim5.cnt().read().bits();
                if let Some(s) = parts.get_mut(p as usize) {
                    s.add(now.wrapping_sub(last).saturating_sub(overhead));
                }
                last = tim5.cnt().read().bits();
            })
        };
        {
            let mut io = sim.hal.io(&sim.plant);
            // The mock I/O cannot fail unless a test injects a fault.
            let _ = io.write_dac(out.dac_code);
            let _ = io.set_amp_enabled(out.command.amp_enable);
        }
        cx.shared.capture.lock(|c| c.push(out.record));
        let item = LogItem::after_step(&out, before);
        if let Some(item) = item {
            cx.shared.log.lock(|q| {
                let _ = q.push_back(item);
            });
            let _ = logger::spawn();
        }

        // The plant between this tick and the next (not part of the step).
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
        sim.period += 1;
        if SCB::is_pendst_pending() {
            // The next tick came before this one finished: a missed deadline.
            sim.missed += 1;
            sim.missed_in_a_row += 1;
            if sim.missed_in_a_row >= OVERRUN_LIMIT {
                // The loop cannot keep its rate: go safe (latched until reset).
                hopper.supervisor_mut().report_overrun();
            }
        } else {
            sim.missed_in_a_row = 0;
        }
        if hopper.supervisor().is_faulted() {
            let first = *sim.fault_period.get_or_insert(sim.period);
            let commanded = sim.hal.commanded_current_a().abs() as f32;
            if sim.period > first {
                sim.max_current_after_fault_a = sim.max_current_after_fault_a.max(commanded);
            }
            // Keep running a little to show the command stays at zero, then stop.
            if sim.period >= first + SAFE_PERIODS_AFTER_FAULT {
                finish(sim, hopper, &mut cx.shared.log);
            }
        }
        if sim.period >= DURATION_S * CONTROL_HZ {
            finish(sim, hopper, &mut cx.shared.log);
        }
    }

    /// Logs the summary and exits QEMU: success only if the hop converged
    /// and no fault or deadline miss occurred.
    fn finish(sim: &Sim, hopper: &Hopper, log: &mut impl rtic::Mutex<T = LogQueue>) -> ! {
        while let Some(item) = log.lock(|q| q.pop_front()) {
            log_item(item);
        }
        let steady = steady_apex(&sim.apexes);
        let converged = hops_to_converge(&sim.apexes, TARGET_APEX_M, 0.02);
        let faults = hopper.supervisor().faults();
        let names = [
            "convert",
            "estimate",
            "energy",
            "law",
            "supervise",
            "telemetry",
        ];
        for (name, p) in names.iter().zip(&sim.parts) {
            defmt::println!(
                "part {=str} min={=u32} mean={=u32} max={=u32}",
                name,
                p.min,
                p.mean(),
                p.max
            );
        }
        defmt::println!(
            "summary steady_apex_m={=f64} hops_to_converge={=i32} step_instr_min={=u32} step_instr_mean={=u32} step_instr_max={=u32} missed={=u32} faults={=u16} periods={=u32} fault_period={=i64} amp_enabled={=bool} max_current_after_fault_a={=f32}",
            steady.unwrap_or(-1.0),
            converged.map_or(-1, |k| i32::try_from(k).unwrap_or(i32::MAX)),
            sim.step_instr.min,
            sim.step_instr.mean(),
            sim.step_instr.max,
            sim.missed,
            faults.0,
            sim.period,
            sim.fault_period.map_or(-1, i64::from),
            sim.hal.amp_enabled(),
            sim.max_current_after_fault_a
        );
        let ok = converged.is_some() && faults.is_empty() && sim.missed == 0;
        debug::exit(if ok {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        });
        #[allow(clippy::empty_loop)]
        loop {}
    }

    fn log_item(item: LogItem) {
        match item {
            LogItem::Hop(h) => defmt::println!("hop {}", h),
            LogItem::Faults { step, faults } => {
                defmt::println!("faults latched at step {=u32}: {}", step, faults)
            }
        }
    }

    /// Logs hop ledgers and faults as they happen.
    #[task(priority = 1, shared = [log])]
    async fn logger(mut cx: logger::Context) {
        while let Some(item) = cx.shared.log.lock(|q| q.pop_front()) {
            log_item(item);
        }
    }
}
