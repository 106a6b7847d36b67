//! `hopper-qemu-planar`: the planar machine's controller (Raibert's, the
//! control crate's `planar::raibert`) on QEMU's `netduinoplus2`, closing
//! the loop on Appendix A's actuated runner (`hopper_sil::planar`, the
//! same loop `hopper-sim planar run --controller raibert` runs on the
//! host). SysTick paces the control task; the estimator's and the
//! controller's step is counted
//! in instructions (TIM5 under `-icount shift=0`); the plant is integrated
//! with SysTick stopped. The run (`scenarios/qemu/planar.toml`) ends with
//! a semihosting exit; `cargo xtask qemu` runs it and checks its strides
//! against the host's (the `qemu-planar:` line).
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(unsafe_code)]

/// Host stand-in: this binary only does something on the microcontroller.
#[cfg(not(target_os = "none"))]
fn main() {
    println!("hopper-qemu-planar is firmware: build it with --target thumbv7em-none-eabihf");
}

#[cfg(target_os = "none")]
use defmt_semihosting as _;

#[cfg(target_os = "none")]
hopper_app::fault_handlers!(hopper_app::qemu::exit_failure);

/// The planar QEMU application.
#[cfg(target_os = "none")]
#[rtic::app(device = stm32f4::stm32f405, peripherals = true)]
mod app {
    use cortex_m::peripheral::{SCB, SYST};
    use cortex_m_semihosting::debug;
    use hopper_app::control::CONTROL_HZ;
    use hopper_control::planar::raibert::RaibertConfig;
    use hopper_plant::planar::PlanarEvent;
    use hopper_sil::planar::{LegLaw, PlanarLoop, DT_S};

    // `PLANAR_PROFILE`, `PLANAR_TARGET_APEX_M`, `PLANAR_DURATION_S`,
    // `PLANAR_THRUST` and its `PlanarLeg`: `scenarios/qemu/planar.toml`,
    // read by the build script.
    include!(concat!(env!("OUT_DIR"), "/planar_scenario.rs"));

    /// The controller's period must be the plant's step.
    const _: () = assert!(CONTROL_HZ == 10_000);

    /// The run and what the summary reports.
    pub struct Run {
        lp: PlanarLoop<PlanarLeg>,
        period: u32,
        /// The last apex's time and hip position.
        last_apex: Option<(f64, f64)>,
        strides: u32,
        step_min: u32,
        step_max: u32,
        step_sum: u64,
        missed: u32,
        fell: bool,
        overhead: u32,
    }

    #[shared]
    struct Shared {}

    #[local]
    struct Local {
        run: Run,
        syst: SYST,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let dp = cx.device;
        let mut core = cx.core;
        let _counter = hopper_app::qemu::start(&dp.RCC, &dp.GPIOB, dp.TIM5);
        let a = hopper_app::qemu::tim5_now();
        let b = hopper_app::qemu::tim5_now();
        let mut cfg = RaibertConfig::table_2_2();
        cfg.target_apex_m = PLANAR_TARGET_APEX_M;
        let Ok(lp) =
            PlanarLoop::new(cfg, speed_at(0.0)).and_then(|lp| PlanarLeg::drive(lp, PLANAR_THRUST))
        else {
            defmt::error!(
                "planar set-up failed (scenarios/qemu/planar.toml: thrust `{=str}`)",
                PLANAR_THRUST
            );
            debug::exit(debug::EXIT_FAILURE);
            #[allow(clippy::empty_loop)]
            loop {}
        };
        hopper_app::qemu::start_systick(&mut core.SYST, hopper_app::qemu::PERIOD_TICKS);
        defmt::println!(
            "hopper-fw: QEMU build, planar raibert scenario, {=u32} Hz, {=u32} s, thrust {=str}",
            CONTROL_HZ,
            PLANAR_DURATION_S,
            PLANAR_THRUST
        );
        (
            Shared {},
            Local {
                run: Run {
                    lp,
                    period: 0,
                    last_apex: None,
                    strides: 0,
                    step_min: u32::MAX,
                    step_max: 0,
                    step_sum: 0,
                    missed: 0,
                    fell: false,
                    overhead: b.wrapping_sub(a),
                },
                syst: core.SYST,
            },
        )
    }

    /// The speed command at `t_s`, m/s.
    fn speed_at(t_s: f64) -> f64 {
        PLANAR_PROFILE
            .iter()
            .rev()
            .find(|(t, _)| *t <= t_s)
            .map_or(0.0, |&(_, v)| v)
    }

    /// Busy idle: QEMU 7.2 loses SysTick ticks while the core sleeps in `wfi`.
    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::nop();
        }
    }

    /// One control period: the firmware's planar period (counted, and
    /// traced by `cargo xtask qemu`: the estimate, the hip's and the leg's
    /// laws, the guard, both motors' currents and their windings' heat),
    /// then the plant over the period with SysTick stopped.
    #[task(binds = SysTick, priority = 3, local = [run, syst])]
    fn control(cx: control::Context) {
        let run = &mut *cx.local.run;
        let t = f64::from(run.period) * DT_S;
        let speed = speed_at(t);
        let lp = &mut run.lp;
        // What the machine's sensors read (the plant's state quantised to
        // each sensor's resolution): the plant's side, not counted.
        let readings = world_with_systick_stopped(cx.local.syst, || lp.sense());
        // The command as a board's would come, in the firmware's `f32`.
        let speed_mps = speed as f32;
        let t0 = hopper_app::qemu::tim5_now();
        let period = lp.period_mut();
        let est = period.estimate_from(&readings, DT_S as f32);
        let cmd = period.control(&est, speed_mps, DT_S as f32);
        let spent = hopper_app::qemu::tim5_now()
            .wrapping_sub(t0)
            .saturating_sub(run.overhead);
        run.step_min = run.step_min.min(spent);
        run.step_max = run.step_max.max(spent);
        run.step_sum += u64::from(spent);
        let last_apex = &mut run.last_apex;
        let strides = &mut run.strides;
        let fell = world_with_systick_stopped(cx.local.syst, || {
            let mut apex = None;
            lp.advance(cmd, 0.0, &mut |e| {
                if let PlanarEvent::Apex { t_s, apex: a } = e {
                    apex = Some((t_s, a.z_m));
                }
            });
            let st = lp.state();
            if let Some((t_s, z_m)) = apex {
                let apex_m = z_m - lp.params().leg_length_m;
                if let Some((t0, x0)) = *last_apex {
                    *strides += 1;
                    defmt::println!(
                        "stride {=u32} {=f64} {=f64}",
                        *strides,
                        apex_m,
                        (st.x_m - x0) / (t_s - t0)
                    );
                }
                *last_apex = Some((t_s, st.x_m));
            }
            let half_leg = 0.5 * lp.params().leg_length_m;
            st.z_m < half_leg || !st.z_m.is_finite() || st.phi_rad.abs() > 0.785
        });
        if SCB::is_pendst_pending() {
            run.missed += 1;
        }
        run.period += 1;
        run.fell |= fell || run.lp.fault().is_some();
        if run.fell || run.period >= PLANAR_DURATION_S * CONTROL_HZ {
            finish(run);
        }
    }

    /// The simulated world's work (`f`), with SysTick stopped, out of line:
    /// the trace `cargo xtask qemu` weighs in cycles leaves functions so
    /// named out by address, so QEMU logs none of the plant's code.
    #[inline(never)]
    fn world_with_systick_stopped<R>(
        syst: &mut cortex_m::peripheral::SYST,
        f: impl FnOnce() -> R,
    ) -> R {
        hopper_app::qemu::with_systick_stopped(syst, f)
    }

    /// Logs the summary and exits QEMU: success only without a fall or a
    /// missed deadline.
    fn finish(run: &Run) -> ! {
        let mean = run.step_sum / u64::from(run.period.max(1));
        defmt::println!(
            "summary strides={=u32} step_instr_min={=u32} step_instr_mean={=u64} step_instr_max={=u32} missed={=u32} fell={=bool} periods={=u32}",
            run.strides,
            run.step_min,
            mean,
            run.step_max,
            run.missed,
            run.fell,
            run.period
        );
        debug::exit(if !run.fell && run.missed == 0 {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        });
        #[allow(clippy::empty_loop)]
        loop {}
    }
}
