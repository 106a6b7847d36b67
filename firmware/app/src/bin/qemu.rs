//! `hopper-qemu`: the QEMU scenario image, on QEMU's `netduinoplus2`. The
//! `no_std` plant and sensor models of `hopper-plant` stand in for the
//! hardware behind the same [`hopper_control::hal::HopperIo`] trait;
//! SysTick paces the control task; the scripted scenario
//! (`HOPPER_QEMU_SCENARIO` at build time: `energy-apex` or `shaped`) ends
//! with a semihosting exit. `cargo xtask qemu` runs it.
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(unsafe_code)]

/// Host stand-in: this binary only does something on the microcontroller.
#[cfg(not(target_os = "none"))]
fn main() {
    println!("hopper-qemu is firmware: build it with --target thumbv7em-none-eabihf");
}

#[cfg(target_os = "none")]
use defmt_semihosting as _;

#[cfg(target_os = "none")]
hopper_app::fault_handlers!(hopper_app::qemu::exit_failure);

/// The QEMU application: the same period runner on the simulated hopper.
#[cfg(target_os = "none")]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true)]
mod app {
    use cortex_m::peripheral::{SCB, SYST};
    use cortex_m_semihosting::debug;
    use hopper_app::control::{Capture, Locked, CONTROL_HZ, CONTROL_PERIOD_S, TIMING};
    use hopper_app::log::{self, Log};
    use hopper_control::hopper::{ApexLoop, Strategy};
    use hopper_control::laws::shaped;
    use hopper_control::runner::PeriodRunner;
    use hopper_plant::metrics::{hops_to_converge, steady_apex};
    use hopper_plant::{Event, Params, Plant};
    use hopper_robot_link::{ControlLoop, Unlinked};
    use hopper_sil::sim_io::{firmware_config, SensorConfig, SimHal};
    use stm32f4::stm32f405::Interrupt;

    // The scenario (`SCENARIO`, `SHAPED`, `START_APEX_M`, `TARGET_APEX_M`,
    // `DURATION_S`): `scenarios/qemu/$HOPPER_QEMU_SCENARIO.toml`, read by
    // the build script; the xtask's golden check runs the same file on the
    // host.
    include!(concat!(env!("OUT_DIR"), "/qemu_scenario.rs"));

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
        firmware: ControlLoop,
        sim: Sim,
        counter: hopper_app::qemu::Instructions,
        syst: SYST,
        log: Log,
        log_rx: log::Receiver,
    }

    #[init(local = [capture: Capture = Capture::new(), log_queue: log::LogQueue = log::LogQueue::new()])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;
        let mut core = cx.core;
        let counter = hopper_app::qemu::start(&dp.RCC, &dp.GPIOB, dp.TIM5);

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
        // The scenario's own settings, by name, as the host's run sets them;
        // a name or value the table refuses stops the run.
        for &(name, value) in PARAMS {
            if let Err(e) = hopper_control::params::set(&mut cfg, name, value) {
                defmt::error!("scenario parameter {=str} = {=f32}: {}", name, value, e);
                debug::exit(debug::EXIT_FAILURE);
            }
        }
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
        let (log_tx, log_rx) = cx.local.log_queue.split();

        hopper_app::qemu::start_systick(&mut core.SYST, hopper_app::qemu::PERIOD_TICKS);
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
                firmware: ControlLoop::new(runner),
                sim: Sim {
                    plant,
                    hal,
                    apexes: heapless::Vec::new(),
                    fault_period: None,
                    max_current_after_fault_a: 0.0,
                },
                counter,
                syst: core.SYST,
                log: Log::new(log_tx, LOGGER_IRQ),
                log_rx,
            },
        )
    }

    /// Busy idle: QEMU 7.2 loses SysTick ticks while the core sleeps in `wfi`.
    #[idle]
    fn idle(_: idle::Context) -> ! {
        hopper_app::qemu::paint_stack();
        // Does a critical section (what a log frame takes) hold off a task
        // at the control task's priority? Pend one inside it and see.
        critical_section::with(|_| {
            cortex_m::peripheral::NVIC::pend(PROBE_IRQ);
            cortex_m::asm::isb();
            CS_MASKS_CONTROL.store(
                !PROBE_RAN.load(core::sync::atomic::Ordering::Relaxed),
                core::sync::atomic::Ordering::Relaxed,
            );
        });
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
    #[task(binds = SysTick, priority = 3, local = [firmware, sim, counter, syst, log], shared = [capture])]
    fn control(cx: control::Context) {
        cx.local.counter.enter();
        let sim = &mut *cx.local.sim;
        let firmware = &mut *cx.local.firmware;
        // No link: the scenario is the operator.
        let p = {
            let mut io = sim.hal.io(&sim.plant);
            firmware.period(
                &mut io,
                cx.local.counter,
                &mut Locked(cx.shared.capture),
                &mut Unlinked::default(),
            )
        };
        let runner = &mut firmware.runner;
        if let Some(item) = p.log {
            cx.local.log.push(&item);
        }

        // The plant between this tick and the next (not part of the period).
        let current_a = sim.hal.mean_current_a(f64::from(CONTROL_PERIOD_S));
        let apexes = &mut sim.apexes;
        let plant = &mut sim.plant;
        let advanced = hopper_app::qemu::with_systick_stopped(cx.local.syst, || {
            plant.advance(f64::from(CONTROL_PERIOD_S), current_a, &mut |e| {
                if let Event::Apex { toe_height_m, .. } = e {
                    defmt::println!("apex {=usize} {=f64}", apexes.len() + 1, toe_height_m);
                    let _ = apexes.push(toe_height_m);
                }
            })
        });
        if advanced.is_err() {
            defmt::error!("plant integration failed");
            debug::exit(debug::EXIT_FAILURE);
        }
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
        let (stack_idle_b, stack_peak_b) = hopper_app::qemu::stack_depths();
        let steady = steady_apex(&sim.apexes);
        let converged = hops_to_converge(&sim.apexes, TARGET_APEX_M, 0.02);
        let faults = runner.hopper().supervisor().faults();
        let cost = runner.step_cost();
        defmt::println!(
            "summary steady_apex_m={=f64} hops_to_converge={=i32} step_instr_min={=u32} step_instr_mean={=u32} step_instr_max={=u32} missed={=u32} faults={=u16} periods={=u32} fault_period={=i64} amp_enabled={=bool} max_current_after_fault_a={=f32} log_dropped={=u32} stack_idle_b={=u32} stack_peak_b={=u32} log_frame_instr_max={=u32} cs_masks_control={=bool}",
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
            LOG_FRAME_MAX.load(core::sync::atomic::Ordering::Relaxed),
            CS_MASKS_CONTROL.load(core::sync::atomic::Ordering::Relaxed)
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

    /// The logger task's vector (a spare peripheral's).
    const LOGGER_IRQ: Interrupt = Interrupt::FSMC;
    /// The critical-section probe's vector (a spare peripheral's).
    const PROBE_IRQ: Interrupt = Interrupt::CAN1_TX;
    /// The probe ran.
    static PROBE_RAN: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);
    /// A critical section held off the probe at the control task's
    /// priority (the summary's `cs_masks_control`).
    static CS_MASKS_CONTROL: core::sync::atomic::AtomicBool =
        core::sync::atomic::AtomicBool::new(true);

    /// Runs once, pended by idle inside a critical section, at the
    /// control task's priority.
    #[task(binds = CAN1_TX, priority = 3)]
    fn cs_probe(_: cs_probe::Context) {
        PROBE_RAN.store(true, core::sync::atomic::Ordering::Relaxed);
    }

    /// Logs hop ledgers and faults as the control task queues them.
    #[task(binds = FSMC, priority = 1, local = [log_rx])]
    fn logger(cx: logger::Context) {
        while let Some(item) = cx.local.log_rx.dequeue() {
            // Timed: a defmt frame holds the image's critical section
            // (the tasks at priorities 1-2 masked, not the control task)
            // from start to end (docs/safety.md, "Logging").
            let t0 = hopper_app::qemu::tim5_now();
            log::print_always(&item);
            LOG_FRAME_MAX.fetch_max(
                hopper_app::qemu::tim5_now().wrapping_sub(t0),
                core::sync::atomic::Ordering::Relaxed,
            );
        }
    }

    /// The largest log item's print, instructions (its frames and the
    /// interrupts masked meanwhile).
    static LOG_FRAME_MAX: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);
}
