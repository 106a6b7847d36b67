//! `hopper-sim serve`: the virtual robot, the firmware on the simulated
//! hopper behind the link protocol on a TCP socket.

use crate::common::{resolve, BaseArgs};
use anyhow::{bail, Context, Result};
use clap::Parser;

#[derive(Parser)]
// The run's --start-apex means something else here: the robot starts
// standing unless it is given.
#[command(mut_arg("start_apex", |a| a.help(
    "Hold the body with the toe this high above the ground (m) until armed, then release it [default: standing on its toe, released 1 mm up]"
)))]
// The virtual robot runs until stopped and takes its faults from the
// operator (the simulated e-stop), so run's time and injections are
// refused here rather than ignored.
#[command(mut_arg("duration", |a| a.help(
    "Not for serve (refused): it runs until killed, or for --for SECONDS of robot time"
)))]
#[command(mut_arg("inject", |a| a.help(
    "Not for serve (refused): press the simulated e-stop with `hopper-link ... estop press`; `hopper-sim run --inject` injects faults"
)))]
#[command(mut_arg("scenario", |a| a.help(
    "Scenario file (TOML: plant, controller, sensors; see scenarios/). Flags given as well override it. Its start apex, duration and inject list are run's: serve refuses a file that sets them"
)))]
pub(crate) struct ServeArgs {
    #[command(flatten)]
    base: BaseArgs,
    /// Address to listen on, HOST:PORT (port 0: any free port; the address
    /// taken is printed).
    #[arg(long, value_name = "HOST:PORT")]
    tcp: String,
    /// Robot seconds per wall second (the host's heartbeats must still come
    /// within the 0.2 s link timeout of robot time: up to about 4 with
    /// hopper-link's 20 ms heartbeat).
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Stop after this much robot time, s [default: run until killed].
    #[arg(long = "for", value_name = "SECONDS")]
    limit: Option<f64>,
    /// A mis-calibrated load cell: it reads this much beyond the true
    /// spring force, N (for `hopper-link calibrate tare`).
    #[arg(long, default_value_t = 0.0, value_name = "N")]
    loadcell_bias_n: f64,
    /// A mis-calibrated potentiometer: it reads this much beyond the true
    /// leg compression, m.
    #[arg(long, default_value_t = 0.0, value_name = "M")]
    pot_bias_m: f64,
    /// Where the nut really is at boot, m below its upper stop (the
    /// firmware's incremental motor encoder takes it for 0: for
    /// `hopper-link calibrate home`).
    #[arg(long, default_value_t = 0.0, value_name = "M")]
    nut_start_m: f64,
    /// The real spring's rate off the configured one by this fraction, e.g.
    /// 0.15 (for `hopper-link calibrate spring`).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    spring_rate_error: f64,
    /// The firmware takes the boot height for this much more than it is, m
    /// (for `hopper-link calibrate height`).
    #[arg(
        long,
        default_value_t = 0.0,
        allow_negative_numbers = true,
        value_name = "M"
    )]
    height_zero_error_m: f64,
    /// A load cell whose gain is off by this fraction: it reads `F (1 + e)`
    /// for a spring force `F`, e.g. -0.05 reads 5% low (for `hopper-link
    /// calibrate weight`).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    loadcell_gain_error: f64,
    /// Keep the robot's flash in FILE (created on the first `hopper-link
    /// save`): a saved calibration then loads at the next start, as on a
    /// board [default: a flash that lasts as long as the simulator].
    #[arg(long, value_name = "FILE")]
    flash: Option<std::path::PathBuf>,
}

pub(crate) fn cmd_serve(a: ServeArgs) -> Result<()> {
    let file = a.base.scenario()?;
    if a.base.duration.is_some() {
        bail!("--duration is not for serve: the virtual robot runs until killed, or for --for SECONDS of robot time");
    }
    if !a.base.inject.is_empty() {
        bail!("--inject is not for serve: press the simulated e-stop with `hopper-link --tcp ADDR estop press`; `hopper-sim run --inject KIND@TIME` injects faults");
    }
    if let Some(f) = &file {
        let o = &f.settings;
        for (set, key) in [
            (o.start_apex_m.is_some(), "start_apex_m"),
            (o.duration_s.is_some(), "duration_s"),
            (o.inject.as_ref().is_some_and(|l| !l.is_empty()), "inject"),
        ] {
            if set {
                bail!(
                    "{}: `{key}` is not for serve (the virtual robot starts standing, or held up by --start-apex, runs until killed and takes no injections)",
                    f.origin
                );
            }
        }
    }
    let settings = resolve(file.as_ref(), &a.base)?;
    settings.check().map_err(anyhow::Error::msg)?;
    if !(a.speed.is_finite() && a.speed > 0.0 && a.speed <= 100.0) {
        bail!("--speed {} must be in (0, 100]", a.speed);
    }
    if let Some(l) = a.limit {
        if !(l.is_finite() && l > 0.0) {
            bail!("--for {l} must be a positive number of seconds");
        }
    }
    // Standing, as a robot is powered up (released 1 mm above the ground,
    // it settles in about 0.3 s), unless --start-apex holds it up there
    // until armed.
    let held = a.base.start_apex.is_some();
    let start_apex_m = a.base.start_apex.unwrap_or(0.001);
    if !(a.loadcell_bias_n.is_finite() && a.loadcell_bias_n.abs() <= 200.0) {
        bail!(
            "--loadcell-bias-n {} must be within +-200 N",
            a.loadcell_bias_n
        );
    }
    if !(a.pot_bias_m.is_finite() && a.pot_bias_m.abs() <= 0.01) {
        bail!("--pot-bias-m {} must be within +-0.01 m", a.pot_bias_m);
    }
    let cfg = settings.run_config(0.0);
    if !(a.nut_start_m.is_finite() && (0.0..=cfg.params.stroke_m).contains(&a.nut_start_m)) {
        bail!(
            "--nut-start-m {} must be within the stroke, 0 ..= {} m",
            a.nut_start_m,
            cfg.params.stroke_m
        );
    }
    if !(a.spring_rate_error.is_finite() && a.spring_rate_error.abs() <= 0.5) {
        bail!(
            "--spring-rate-error {} must be within +-0.5",
            a.spring_rate_error
        );
    }
    if !(a.height_zero_error_m.is_finite() && a.height_zero_error_m.abs() <= 0.1) {
        bail!(
            "--height-zero-error-m {} must be within +-0.1 m",
            a.height_zero_error_m
        );
    }
    if !(a.loadcell_gain_error.is_finite() && a.loadcell_gain_error.abs() <= 0.5) {
        bail!(
            "--loadcell-gain-error {} must be within +-0.5",
            a.loadcell_gain_error
        );
    }
    // The firmware is configured for the nominal machine, started where it
    // believes; the plant is the real one.
    let mis = hopper_sil::robot::Miscalibration {
        loadcell_bias_n: a.loadcell_bias_n,
        pot_bias_m: a.pot_bias_m,
        nut_start_m: a.nut_start_m,
        spring_rate_error: a.spring_rate_error,
        height_zero_error_m: a.height_zero_error_m,
        loadcell_gain_error: a.loadcell_gain_error,
    };
    let (runner, hal) = settings
        .controller_spec()
        .and_then(|mut spec| {
            spec.sensors = mis.sensors(spec.sensors);
            spec.runner(
                &cfg.params,
                mis.believed_start_apex_m(start_apex_m),
                cfg.control_dt_s,
                false,
            )
        })
        .map_err(anyhow::Error::msg)?;
    let plant = mis
        .plant(cfg.params, start_apex_m)
        .map_err(|e| anyhow::anyhow!("plant: {e:?}"))?;
    let hal = mis.hal(hal, &plant);
    let robot = hopper_sil::robot::VirtualRobot::new(plant, hal, runner, cfg.control_dt_s);
    let mut robot = if held { robot.hold() } else { robot };
    let (flash, record) =
        hal_sim::serve::Flash::open(a.flash.as_deref()).map_err(anyhow::Error::msg)?;
    hal_sim::serve::load_at_boot(&mut robot, record.as_deref());
    let listener = std::net::TcpListener::bind(&a.tcp)
        .with_context(|| format!("cannot listen on {}", a.tcp))?;
    let addr = listener.local_addr().context("socket address")?;
    println!(
        "hopper-sim: virtual robot listening on {addr} ({} controller, {} parameters, {:.0} Hz, {}x real time, {}); connect with `hopper-link --tcp {addr} status`",
        settings.controller.name(),
        settings.params_name,
        1.0 / cfg.control_dt_s,
        a.speed,
        if held {
            format!("held {start_apex_m} m up until armed")
        } else {
            "standing".to_string()
        }
    );
    use std::io::Write as _;
    let _ = std::io::stdout().flush();
    hal_sim::serve::serve(
        robot,
        flash,
        &listener,
        hal_sim::serve::ServeOptions {
            speed: a.speed,
            limit_s: a.limit,
            dt_s: cfg.control_dt_s,
        },
    )
    .map_err(anyhow::Error::msg)
}
