//! `hopper-sim identify`: fit plant parameters to a recorded hop (thesis
//! section 4.5).

use anyhow::{bail, Result};
use clap::Args;
use hal_sim::params_toml;
use std::path::PathBuf;

/// `hopper-sim identify`.
#[derive(Args)]
pub(crate) struct IdentifyArgs {
    /// The log's directory: trajectory.csv (`hopper-sim run --out`) or
    /// telemetry.csv (`hopper-link record`), starting at the release from
    /// rest.
    #[arg(long, value_name = "DIR")]
    log: PathBuf,
    /// What the recorded hop was: passive (fits planarizer_friction_n and
    /// leg_friction_n) or open-torque (fits current_limit_a, the effective
    /// stance torque over k_t, and nut_mass_kg).
    #[arg(long, default_value = "passive", value_parser = ["passive", "open-torque"])]
    experiment: String,
    /// The torque the open-torque hop commanded, N m.
    #[arg(long, default_value_t = 1.0)]
    torque: f64,
    /// What is known of the machine: a preset or a TOML file (the fit
    /// starts from its values and keeps the rest) [default: design].
    #[arg(long)]
    params: Option<String>,
    /// Directory for identify.png and identify.svg: measured against fitted.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print the estimates as JSON under the parameter files' field names.
    #[arg(long)]
    json: bool,
}

pub(crate) fn cmd_identify(a: &IdentifyArgs) -> Result<()> {
    use hal_sim::identify::{identify, read_log, write_plot, Experiment};
    let base = match &a.params {
        Some(p) => params_toml::load(p).map_err(anyhow::Error::msg)?,
        None => params_toml::PlantSet::preset("design")
            .ok_or_else(|| anyhow::anyhow!("no design preset"))?,
    };
    let experiment = match a.experiment.as_str() {
        "open-torque" => {
            if !(a.torque.is_finite() && a.torque > 0.0 && a.torque <= 5.0) {
                bail!("--torque {} must be within 0 ..= 5 N m", a.torque);
            }
            Experiment::OpenTorque {
                torque_nm: a.torque,
            }
        }
        _ => Experiment::Passive,
    };
    let log = read_log(&a.log).map_err(anyhow::Error::msg)?;
    let bar =
        indicatif::ProgressBar::new_spinner().with_finish(indicatif::ProgressFinish::AndClear);
    bar.set_message(format!("fitting {} samples", log.t_s.len()));
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let id = identify(&log, &base.params, experiment).map_err(anyhow::Error::msg)?;
    bar.finish_and_clear();
    let written = match &a.out {
        Some(dir) => write_plot(
            &log,
            &id,
            &format!("identify ({}): {}", a.experiment, log.file),
            dir,
        )
        .map_err(anyhow::Error::msg)?,
        None => Vec::new(),
    };
    if a.json {
        let mut v = serde_json::Map::new();
        for e in &id.estimates {
            v.insert(e.field.into(), serde_json::json!(e.value));
        }
        if let Some(t) = id.stance_torque_nm {
            v.insert("stance_torque_nm".into(), serde_json::json!(t));
        }
        v.insert("fit".into(), serde_json::to_value(&id)?);
        say!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    say!(
        "identify: {} hop, {} samples over {:.3} s ({}), from the {} parameters",
        a.experiment,
        log.t_s.len(),
        log.t_s.last().copied().unwrap_or(0.0),
        log.file,
        base.name
    );
    for e in &id.estimates {
        say!(
            "  {} = {:.4} +- {:.4} (from {:.4})",
            e.field,
            e.value,
            e.std,
            e.start
        );
    }
    if let Some(t) = id.stance_torque_nm {
        say!("  effective stance torque {t:.4} N m (k_t x current_limit_a)");
    }
    say!(
        "  fit: toe-height residual {:.3} mm RMS over {} samples, {} simulations",
        id.rms_residual_m * 1e3,
        id.samples,
        id.simulations
    );
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}
