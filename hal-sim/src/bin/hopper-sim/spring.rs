//! `hopper-sim spring`: design a leg spring (thesis section 3.2), optionally
//! checked against a simulated hop.

use anyhow::{bail, Result};
use clap::Args;
use hal_sim::run;

/// `hopper-sim spring`: the thesis's worked example by default.
#[derive(Args)]
pub(crate) struct SpringArgs {
    /// Spring rate, N/m.
    #[arg(long, default_value_t = 10_000.0, value_name = "N_PER_M")]
    stiffness_n_per_m: f64,
    /// Wire material (Table 3.2): music-wire, oil-tempered, hard-drawn,
    /// chrome-vanadium, chrome-silicon.
    #[arg(long, default_value = "music-wire", value_parser = clap::builder::PossibleValuesParser::new(
        hal_sim::spring::MATERIALS.map(|m| m.name)
    ))]
    material: String,
    /// Wire diameter, mm.
    #[arg(long, default_value_t = 5.53, value_name = "MM")]
    wire_mm: f64,
    /// Outer coil diameter, mm.
    #[arg(long, default_value_t = 52.0, value_name = "MM")]
    outer_mm: f64,
    /// Free length, mm.
    #[arg(long, default_value_t = 235.0, value_name = "MM")]
    free_length_mm: f64,
    /// The longest solid length allowed, mm [default: no limit].
    #[arg(long, value_name = "MM")]
    max_solid_mm: Option<f64>,
    /// The shortest allowable stroke required, mm.
    #[arg(long, default_value_t = 100.0, value_name = "MM")]
    min_stroke_mm: f64,
    /// Also run a hop on the design machine with this spring (its rate with
    /// whole coils): the shaped controller from 0.05 m to this apex, 10 s,
    /// and compare its peak spring force with the allowable forces.
    #[arg(long, value_name = "APEX_M")]
    check_hop: Option<f64>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// A simulated hop's spring loads against a spring design.
#[derive(serde::Serialize)]
struct HopCheck {
    controller: &'static str,
    target_apex_m: f64,
    steady_apex_m: Option<f64>,
    spring_rate_n_per_m: f64,
    peak_spring_force_n: f64,
    peak_deflection_m: f64,
    fatigue_force_n: f64,
    allowable_stroke_m: f64,
    within: bool,
}

pub(crate) fn cmd_spring(a: &SpringArgs) -> Result<()> {
    use hal_sim::spring::{design, Material, SpringSpec};
    let Some(material) = Material::by_name(&a.material) else {
        bail!("unknown material `{}`", a.material);
    };
    let mm = |v: f64| v * 1e-3;
    let spec = SpringSpec {
        stiffness_n_per_m: a.stiffness_n_per_m,
        material,
        wire_m: mm(a.wire_mm),
        outer_m: mm(a.outer_mm),
        free_length_m: mm(a.free_length_mm),
        max_solid_m: a.max_solid_mm.map(mm),
        min_stroke_m: Some(mm(a.min_stroke_mm)),
    };
    let d = design(&spec).map_err(anyhow::Error::msg)?;
    let check = match a.check_hop {
        None => None,
        Some(apex) => {
            if !(apex.is_finite() && (0.01..=0.5).contains(&apex)) {
                bail!("--check-hop {apex} must be an apex within 0.01..=0.5 m");
            }
            let cli = hal_sim::scenario::Overrides {
                controller: Some(hopper_control::laws::ControllerKind::Shaped),
                target_apex_m: Some(apex),
                start_apex_m: Some(0.05),
                duration_s: Some(10.0),
                ..Default::default()
            };
            let mut settings = hal_sim::scenario::Settings::resolve(None, &cli);
            settings.params.spring_stiffness_n_per_m = d.rate_n_per_m;
            settings.check().map_err(anyhow::Error::msg)?;
            let cfg = settings.run_config(1.0 / settings.control_hz);
            let mut ctl = settings
                .controller_spec()
                .and_then(|spec| spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s))
                .map_err(anyhow::Error::msg)?;
            let r = run::run(&cfg, &settings.params_name, &mut ctl).map_err(anyhow::Error::msg)?;
            let peak = r
                .samples
                .iter()
                .map(|s| s.spring_force_n)
                .fold(0.0, f64::max);
            let deflection = peak / d.rate_n_per_m;
            Some(HopCheck {
                controller: "shaped",
                target_apex_m: apex,
                steady_apex_m: r.summary.steady_apex_m,
                spring_rate_n_per_m: d.rate_n_per_m,
                peak_spring_force_n: peak,
                peak_deflection_m: deflection,
                fatigue_force_n: d.fatigue_force_n,
                allowable_stroke_m: d.allowable_stroke_m,
                within: peak <= d.fatigue_force_n && deflection <= d.allowable_stroke_m,
            })
        }
    };
    if a.json {
        let v = serde_json::json!({ "design": d, "hop_check": check });
        say!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    for l in d.lines() {
        say!("{l}");
    }
    say!(
        "limits: {}",
        if d.meets_limits {
            "met (solid length, stroke)"
        } else {
            "NOT met: see the solid length and the allowable stroke"
        }
    );
    if let Some(c) = &check {
        say!(
            "hop check: shaped to {:.3} m (steady {}) on the design machine with a {:.0} N/m spring: peak spring force {:.0} N ({:.0}% of the fatigue force), deflection {:.1} mm of {:.1} mm allowed: {}",
            c.target_apex_m,
            c.steady_apex_m.map_or("none".to_string(), |a| format!("{a:.4} m")),
            c.spring_rate_n_per_m,
            c.peak_spring_force_n,
            100.0 * c.peak_spring_force_n / c.fatigue_force_n,
            c.peak_deflection_m * 1e3,
            c.allowable_stroke_m * 1e3,
            if c.within { "within" } else { "EXCEEDED" }
        );
    }
    Ok(())
}
