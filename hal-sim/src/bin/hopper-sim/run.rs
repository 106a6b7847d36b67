//! `hopper-sim run`: drop the hopper from a start apex, run a controller and
//! print a summary (optionally the trajectory CSV and plot).

use crate::common::{resolve, BaseArgs};
use anyhow::{bail, Result};
use clap::Parser;
use hal_sim::run;
use std::path::PathBuf;

#[derive(Parser)]
pub(crate) struct RunArgs {
    #[command(flatten)]
    base: BaseArgs,
    /// Trajectory sample rate for the CSV and plot, Hz.
    #[arg(long, default_value_t = 1000.0)]
    sample_hz: f64,
    /// Directory for trajectory.csv, hop.png and telemetry.mcap (Foxglove,
    /// PlotJuggler), created if missing.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print exactly one JSON object (the summary) on stdout.
    #[arg(long)]
    json: bool,
    /// Print the per-hop energy ledger (motor work, friction, touchdown,
    /// liftoff and stop-impact losses, actuator energy left at the apex) as
    /// a table. The JSON summary always has it (`hop_ledger`, `steady_hop`).
    #[arg(long)]
    ledger: bool,
    /// Hardware in the loop: run the firmware on a robot image built for
    /// it (`hopper-hil`, on a board or in QEMU) over its link, one frame
    /// each way per control period; the plant, sensor and amplifier
    /// models run here. Needs --tcp or --serial. Slower than real time.
    #[arg(long, requires = "hil_line")]
    hil: bool,
    /// The HIL image's link on TCP (QEMU's `-serial tcp:...`), HOST:PORT.
    #[arg(long, group = "hil_line", requires = "hil", value_name = "ADDR")]
    tcp: Option<String>,
    /// The HIL image's link on a serial port (a board's USB-UART), e.g.
    /// /dev/ttyACM0.
    #[arg(long, group = "hil_line", requires = "hil", value_name = "PORT")]
    serial: Option<String>,
    /// Baud rate of --serial.
    #[arg(long, default_value_t = 921_600, requires = "serial")]
    baud: u32,
    /// How long the HIL image may take to answer a period before the run
    /// stops (a lost frame), s.
    #[arg(long, default_value_t = 5.0, requires = "hil")]
    hil_timeout_s: f64,
}

/// The HIL image's line and the answer timeout.
fn hil_line(a: &RunArgs) -> Result<hal_sim::hil::Connection> {
    if !(a.hil_timeout_s.is_finite() && a.hil_timeout_s > 0.0) {
        bail!(
            "--hil-timeout-s {} must be a positive number of seconds",
            a.hil_timeout_s
        );
    }
    let timeout = std::time::Duration::from_secs_f64(a.hil_timeout_s);
    match (&a.tcp, &a.serial) {
        (Some(addr), _) => hal_sim::hil::Connection::tcp(addr, timeout),
        (None, Some(port)) => hal_sim::hil::Connection::serial(port, a.baud, timeout),
        (None, None) => Err("--hil needs --tcp ADDR or --serial PORT".to_string()),
    }
    .map_err(anyhow::Error::msg)
}

pub(crate) fn cmd_run(a: RunArgs) -> Result<()> {
    // Validate everything before touching the file system.
    let file = a.base.scenario()?;
    let settings = resolve(file.as_ref(), &a.base)?;
    let params_name = settings.params_name.clone();
    if !(a.sample_hz.is_finite() && a.sample_hz > 0.0) {
        bail!(
            "--sample-hz {} must be a positive number of Hz",
            a.sample_hz
        );
    }
    settings.check().map_err(anyhow::Error::msg)?;
    let cfg = settings.run_config(if a.out.is_some() {
        1.0 / a.sample_hz
    } else {
        0.0
    });
    let spec = settings.controller_spec().map_err(anyhow::Error::msg)?;
    let mut ctl: Box<dyn hal_sim::controller::PlantDriver> = if a.hil {
        let connection = hil_line(&a)?;
        Box::new(
            spec.build_hil(&cfg.params, cfg.start_apex_m, cfg.control_dt_s, connection)
                .map_err(anyhow::Error::msg)?,
        )
    } else {
        Box::new(
            spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s)
                .map_err(anyhow::Error::msg)?,
        )
    };
    // A progress bar on stderr for runs long enough to wait for; indicatif
    // draws nothing when stderr is not a terminal.
    let bar = indicatif::ProgressBar::new(1000);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} simulating [{bar:40}] {msg} ({eta} left)",
        )
        .map_err(anyhow::Error::msg)?
        .progress_chars("=> "),
    );
    // (A HIL run is slower than real time: its bar always shows.)
    if cfg.duration_s < 60.0 && !a.hil {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let duration_s = cfg.duration_s;
    let result = run::run_with_progress(&cfg, &params_name, &mut *ctl, &mut |done, total| {
        bar.set_position(done * 1000 / total.max(1));
        bar.set_message(format!(
            "{:.1} / {duration_s} s",
            duration_s * done as f64 / total.max(1) as f64
        ));
    })
    .map_err(anyhow::Error::msg)?;
    bar.finish_and_clear();
    let s = &result.summary;

    let mut written = Vec::new();
    if let Some(dir) = &a.out {
        let title = format!(
            "{} hopping, {} parameters, start apex {:.3} m",
            s.controller, s.params, s.start_apex_m
        );
        written = hal_sim::out_dir::write_whole(dir, |staging| {
            let csv_path = staging.join("trajectory.csv");
            let io = |e: std::io::Error| {
                format!("cannot write {}: {e}", dir.join("trajectory.csv").display())
            };
            let mut f = std::io::BufWriter::new(std::fs::File::create(&csv_path).map_err(io)?);
            run::write_csv(&result.samples, &mut f).map_err(io)?;
            std::io::Write::flush(&mut f).map_err(io)?;
            hal_sim::plot::hop_plot_with_heat(
                &result.samples,
                &title,
                s.target_apex_m,
                s.thermal.map(|t| hal_sim::plot::HeatLevels {
                    derate_c: t.derate_winding_c,
                    trip_c: t.trip_winding_c,
                    protect: t.protect,
                }),
                &staging.join("hop.png"),
            )?;
            hal_sim::run::write_mcap(&staging.join("telemetry.mcap"), &result, &ctl.parameters())?;
            Ok(vec![
                "trajectory.csv".into(),
                "hop.png".into(),
                "telemetry.mcap".into(),
            ])
        })
        .map_err(anyhow::Error::msg)?;
    }

    if a.json {
        say!("{}", serde_json::to_string(s)?);
        return Ok(());
    }
    let l = &s.ledger;
    let fmt_opt = |v: Option<f64>, unit: &str, scale: f64| match v {
        Some(x) => format!("{:.4} {unit}", x * scale),
        None => "-".to_string(),
    };
    say!(
        "hopper-sim: {} controller, {} parameters, released from {:.3} m, {:.2} s simulated",
        s.controller,
        s.params,
        s.start_apex_m,
        s.duration_s
    );
    if let Some(m) = settings.motor {
        match s.thermal {
            Some(t) => say!(
                "  motor              {}: {}; {:.1} A continuous under the firmware's thermal model",
                m.name,
                m.source,
                t.config.continuous_current_a()
            ),
            None => say!("  motor              {}: {}", m.name, m.source),
        }
    }
    let n = s.apex_heights_m.len();
    let shown: Vec<String> = if n <= 14 {
        s.apex_heights_m.iter().map(|h| format!("{h:.4}")).collect()
    } else {
        let head = s.apex_heights_m[..10].iter().map(|h| format!("{h:.4}"));
        let tail = s.apex_heights_m[n - 3..].iter().map(|h| format!("{h:.4}"));
        head.chain(std::iter::once("...".to_string()))
            .chain(tail)
            .collect()
    };
    say!("  hops (stances)     {}", s.hops);
    say!(
        "  apex heights [m]   {}",
        if shown.is_empty() {
            "-".into()
        } else {
            shown.join(" ")
        }
    );
    if let Some(t) = s.target_apex_m {
        say!(
            "  target apex        {t:.4} m, {}",
            match s.hops_to_converge {
                Some(k) => format!("within 2% from hop {k} on"),
                None => match s.thermal.and_then(|t| t.first_derated_s) {
                    Some(d) => format!(
                        "not converged (within 2%); the motor's current limit derated from {d:.2} s (motor heat)"
                    ),
                    None => "not converged (within 2%)".to_string(),
                },
            }
        );
    }
    say!(
        "  faults             {}",
        if s.faults.is_empty() {
            "none".to_string()
        } else {
            format!(
                "{} (first at {:.4} s)",
                s.faults
                    .iter()
                    .map(|f| format!("{} at {:.4} s", f.name, f.time_s))
                    .collect::<Vec<_>>()
                    .join(", "),
                s.first_fault_s.unwrap_or(0.0)
            )
        }
    );
    if let Some(t) = &s.thermal {
        say!("  motor heat         {}", hal_sim::controller::heat_line(t));
    }
    say!(
        "  steady apex        {}",
        fmt_opt(s.steady_apex_m, "m", 1.0)
    );
    say!(
        "  mean stance time   {}",
        fmt_opt(s.stance_time_s, "ms", 1000.0)
    );
    say!("  hopping stopped at {}", fmt_opt(s.stopped_at_s, "s", 1.0));
    say!(
        "  energy [J]         start {:.3}, end {:.3}; motor work {:+.3}, friction {:.3}, damping {:.3},",
        s.initial_energy_j, s.final_energy_j, l.motor_work_j, l.friction_j, l.damping_j
    );
    say!(
        "                     touchdown {:.3}, liftoff {:.3}, stop impacts {:.3}, settling {:.3}; residual {:.2e}",
        l.touchdown_loss_j, l.liftoff_loss_j, l.stop_impact_loss_j, l.settle_loss_j, s.energy_residual_j
    );
    say!(
        "  motor              peak speed {:.0} rad/s ({:.0}% of no-load {:.0} rad/s), peak current {:.1} A, peak stroke {:.1} mm",
        s.peak_motor_speed_rad_s,
        100.0 * s.peak_motor_speed_rad_s / s.no_load_speed_rad_s,
        s.no_load_speed_rad_s,
        s.peak_current_a,
        s.peak_stroke_m * 1000.0
    );
    if let Some(h) = &s.steady_hop {
        say!(
            "  steady hop [J]     motor work {:.2}, friction {:.2}, touchdown {:.2}, liftoff {:.2}, stop impacts {:.2}; at apex rotor {:.2}, spring {:.2} (mean of the last 5 hops)",
            h.motor_work_j,
            h.friction_j,
            h.touchdown_loss_j,
            h.liftoff_loss_j,
            h.stop_impact_loss_j,
            h.actuator_kinetic_j,
            h.actuator_spring_j,
        );
    }
    if a.ledger {
        say!("  per-hop energy ledger, J (previous apex to this apex; rotor and spring: actuator energy left at this apex; copper: heat in the winding, with the toe down and in flight)");
        say!(
            "  {:>4} {:>8} {:>8} {:>8} {:>8} {:>9} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8}",
            "hop",
            "time s",
            "apex m",
            "motor",
            "friction",
            "touchdown",
            "liftoff",
            "stops",
            "rotor",
            "spring",
            "copper",
            "stance",
            "flight"
        );
        for (i, h) in s.hop_ledger.iter().enumerate() {
            say!(
                "  {:>4} {:>8.3} {:>8.4} {:>8.3} {:>8.3} {:>9.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.2} {:>8.2} {:>8.2}",
                i + 1,
                h.apex_time_s,
                h.apex_m,
                h.motor_work_j,
                h.friction_j,
                h.touchdown_loss_j,
                h.liftoff_loss_j,
                h.stop_impact_loss_j,
                h.actuator_kinetic_j,
                h.actuator_spring_j,
                h.copper_loss_j,
                h.stance_copper_loss_j,
                h.flight_copper_loss_j
            );
        }
    }
    if let Some(h) = &s.hil {
        say!(
            "  hardware in loop   {} periods (+{} to configure and arm, {} parameters set); control interrupt mean {:.0}, max {} {}; {:.1} B/period out, {:.1} in; {:.0} periods/s ({:.3}x real time)",
            h.periods,
            h.setup_periods,
            h.params_set,
            h.isr_mean,
            h.isr_max,
            h.isr_unit,
            h.bytes_out_per_period,
            h.bytes_in_per_period,
            h.frames_per_s,
            h.realtime_factor
        );
    }
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}
