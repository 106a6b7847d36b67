//! `hopper-sim`: run the vertical hopper in simulation, print parameter sets.
//!
//! ```text
//! hopper-sim run [--params design|identified|PATH.toml] [--controller NAME]
//!                [--target-apex M] [--torque NM] [--noise off|default] [--seed N]
//!                [--start-apex M] [--duration S] [--out DIR] [--json]
//! hopper-sim params show design|identified
//! ```

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use hal_sim::controller::{ControllerSpec, CONTROLLER_NAMES};
use hal_sim::mock::SensorConfig;
use hal_sim::params::Params;
use hal_sim::params_toml;
use hal_sim::run::{self, RunConfig};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "hopper-sim",
    version,
    about = "Simulate the electrically actuated one-legged hopper (vertical model, thesis ch. 2.1)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Drop the hopper from a start apex and run a controller; prints a summary.
    Run(RunArgs),
    /// Parameter sets.
    Params {
        #[command(subcommand)]
        cmd: ParamsCmd,
    },
}

#[derive(Subcommand)]
enum ParamsCmd {
    /// Print a preset as TOML that `--params PATH.toml` accepts.
    Show {
        /// Preset: design | identified
        preset: String,
    },
}

#[derive(Parser)]
struct RunArgs {
    /// Plant parameters: a preset (design, identified) or a TOML file.
    #[arg(long, default_value = "design")]
    params: String,
    /// Controller: passive, step-open, step-closed, open-torque, energy,
    /// energy-apex (apex-regulating energy law), velocity, modified-torque.
    /// Each is the firmware's control crate on the simulated sensors.
    #[arg(long, default_value = "passive")]
    controller: String,
    /// Desired apex (toe height) H_D, m; sets the energy target E_D.
    #[arg(long, default_value_t = 0.05, allow_negative_numbers = true)]
    target_apex: f64,
    /// Motor torque for open-torque and modified-torque, N m (default 1.0).
    #[arg(long, allow_negative_numbers = true)]
    torque: Option<f64>,
    /// Sensor noise: default (load cell 2 N, potentiometer 0.1 mm, 1 sigma) or off.
    #[arg(long, default_value = "default", value_parser = ["default", "off"])]
    noise: String,
    /// Seed of the sensor noise (same seed, same run).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Start toe height above the ground (released at rest), m.
    #[arg(long, default_value_t = 0.15, allow_negative_numbers = true)]
    start_apex: f64,
    /// Simulated time, s.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    duration: f64,
    /// Control rate, Hz.
    #[arg(long, default_value_t = 10_000.0)]
    control_hz: f64,
    /// Trajectory sample rate for the CSV and plot, Hz.
    #[arg(long, default_value_t = 1000.0)]
    sample_hz: f64,
    /// Directory for trajectory.csv and hop.png (created if missing).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print exactly one JSON object (the summary) on stdout.
    #[arg(long)]
    json: bool,
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.cmd {
        Cmd::Run(args) => cmd_run(args),
        Cmd::Params {
            cmd: ParamsCmd::Show { preset },
        } => cmd_params_show(&preset),
    };
    if let Err(e) = result {
        eprintln!("hopper-sim: error: {e:#}");
        std::process::exit(2);
    }
}

fn cmd_params_show(preset: &str) -> Result<()> {
    let Some(p) = Params::preset(preset) else {
        bail!(
            "unknown preset `{preset}`: expected one of {:?}",
            Params::PRESET_NAMES
        );
    };
    print!("{}", params_toml::to_toml(&p, preset));
    Ok(())
}

fn cmd_run(a: RunArgs) -> Result<()> {
    // Validate everything before touching the file system.
    let (params, params_name) = params_toml::load(&a.params).map_err(anyhow::Error::msg)?;
    if !CONTROLLER_NAMES.contains(&a.controller.as_str()) {
        bail!(
            "unknown controller `{}`: expected one of {CONTROLLER_NAMES:?}",
            a.controller
        );
    }
    if !(a.control_hz.is_finite() && a.control_hz > 0.0) {
        bail!(
            "--control-hz {} must be a positive number of Hz",
            a.control_hz
        );
    }
    if !(a.sample_hz.is_finite() && a.sample_hz > 0.0) {
        bail!(
            "--sample-hz {} must be a positive number of Hz",
            a.sample_hz
        );
    }
    let cfg = RunConfig {
        params,
        start_apex_m: a.start_apex,
        duration_s: a.duration,
        control_dt_s: 1.0 / a.control_hz,
        sample_dt_s: if a.out.is_some() {
            1.0 / a.sample_hz
        } else {
            0.0
        },
    };
    cfg.validate().map_err(anyhow::Error::msg)?;
    let spec = ControllerSpec {
        target_apex_m: a.target_apex,
        torque_nm: a.torque,
        sensors: SensorConfig {
            noise: a.noise == "default",
            seed: a.seed,
            ..SensorConfig::DEFAULT
        },
        ..ControllerSpec::new(&a.controller)
    };
    let mut ctl = spec
        .build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s)
        .map_err(anyhow::Error::msg)?;
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
    if cfg.duration_s < 60.0 {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let duration_s = cfg.duration_s;
    let result = run::run_with_progress(&cfg, &params_name, &mut ctl, &mut |done, total| {
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
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create output directory {}", dir.display()))?;
        let csv_path = dir.join("trajectory.csv");
        let mut f = std::io::BufWriter::new(
            std::fs::File::create(&csv_path)
                .with_context(|| format!("cannot create {}", csv_path.display()))?,
        );
        run::write_csv(&result.samples, &mut f)
            .with_context(|| format!("cannot write {}", csv_path.display()))?;
        std::io::Write::flush(&mut f)
            .with_context(|| format!("cannot write {}", csv_path.display()))?;
        written.push(csv_path);
        let png = dir.join("hop.png");
        let title = format!(
            "{} hopping, {} parameters, start apex {:.3} m",
            s.controller, s.params, s.start_apex_m
        );
        hal_sim::plot::hop_plot(&result.samples, &title, s.target_apex_m, &png)
            .map_err(anyhow::Error::msg)?;
        written.push(png);
    }

    if a.json {
        println!("{}", serde_json::to_string(s)?);
        return Ok(());
    }
    let l = &s.ledger;
    let fmt_opt = |v: Option<f64>, unit: &str, scale: f64| match v {
        Some(x) => format!("{:.4} {unit}", x * scale),
        None => "-".to_string(),
    };
    println!(
        "hopper-sim: {} controller, {} parameters, released from {:.3} m, {:.2} s simulated",
        s.controller, s.params, s.start_apex_m, s.duration_s
    );
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
    println!("  hops (stances)     {}", s.hops);
    println!(
        "  apex heights [m]   {}",
        if shown.is_empty() {
            "-".into()
        } else {
            shown.join(" ")
        }
    );
    if let Some(t) = s.target_apex_m {
        println!(
            "  target apex        {t:.4} m, {}",
            match s.hops_to_converge {
                Some(k) => format!("within 2% from hop {k} on"),
                None => "not converged (within 2%)".to_string(),
            }
        );
    }
    println!(
        "  faults             {}",
        if s.faults.is_empty() {
            "none".to_string()
        } else {
            format!(
                "{} (first at {:.4} s)",
                s.faults.join(", "),
                s.first_fault_s.unwrap_or(0.0)
            )
        }
    );
    println!(
        "  steady apex        {}",
        fmt_opt(s.steady_apex_m, "m", 1.0)
    );
    println!(
        "  mean stance time   {}",
        fmt_opt(s.stance_time_s, "ms", 1000.0)
    );
    println!("  hopping stopped at {}", fmt_opt(s.stopped_at_s, "s", 1.0));
    println!(
        "  energy [J]         start {:.3}, end {:.3}; motor work {:+.3}, friction {:.3}, damping {:.3},",
        s.initial_energy_j, s.final_energy_j, l.motor_work_j, l.friction_j, l.damping_j
    );
    println!(
        "                     touchdown {:.3}, liftoff {:.3}, stop impacts {:.3}, settling {:.3}; residual {:.2e}",
        l.touchdown_loss_j, l.liftoff_loss_j, l.stop_impact_loss_j, l.settle_loss_j, s.energy_residual_j
    );
    println!(
        "  motor              peak speed {:.0} rad/s ({:.0}% of no-load {:.0} rad/s), peak current {:.1} A, peak stroke {:.1} mm",
        s.peak_motor_speed_rad_s,
        100.0 * s.peak_motor_speed_rad_s / s.no_load_speed_rad_s,
        s.no_load_speed_rad_s,
        s.peak_current_a,
        s.peak_stroke_m * 1000.0
    );
    for p in &written {
        println!("  wrote {}", p.display());
    }
    Ok(())
}
