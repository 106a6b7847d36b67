//! `hopper-sim planar`: the planar one-legged runner of thesis section 2.2
//! (`run`, `figures`, `stability`).

use anyhow::{bail, Result};
use clap::Subcommand;
use std::path::PathBuf;

/// Appendix A's terms on Table 2.2's runner (`--model appendix-a`).
#[derive(clap::Args)]
pub(crate) struct AppendixArgs {
    /// Appendix A: the trunk's centre ahead of the hip (body frame), m.
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    trunk_offset_x: Option<f64>,
    /// Appendix A: the trunk's centre above the hip (body frame), m.
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    trunk_offset_z: Option<f64>,
    /// Appendix A: the leg's centre from the hip along the leg, m.
    #[arg(long, value_name = "M")]
    leg_com: Option<f64>,
    /// Appendix A: the unsprung mass at the toe, kg.
    #[arg(long, value_name = "KG")]
    toe_mass: Option<f64>,
    /// Appendix A: the leg spring's damper, N s/m.
    #[arg(long, value_name = "NS_PER_M")]
    leg_damping: Option<f64>,
    /// Appendix A: the hip spring's damper, N m s/rad.
    #[arg(long, value_name = "NMS_PER_RAD")]
    hip_damping: Option<f64>,
    /// Appendix A: planarizer dry friction on the hip's motion, N.
    #[arg(long, value_name = "N")]
    planarizer_friction: Option<f64>,
    /// Appendix A: dry friction on the leg's sliding in stance, N.
    #[arg(long, value_name = "N")]
    leg_friction: Option<f64>,
    /// Appendix A: dry friction torque at the hip, N m.
    #[arg(long, value_name = "NM")]
    hip_friction: Option<f64>,
}

impl AppendixArgs {
    /// The runner `--model` names, with these terms; each term refused by
    /// its flag when out of range or given without `--model appendix-a`.
    fn model(&self, name: &str) -> Result<hal_sim::planar_sim::Model> {
        use hopper_plant::planar::{PlanarError, PlanarParams};
        use hopper_plant::planar_general::{GeneralParams, TERM_LIMITS};
        type Set = fn(&mut GeneralParams, f64);
        let terms: [(&str, &str, Option<f64>, Set); 9] = [
            (
                "--trunk-offset-x",
                "trunk_offset_x_m",
                self.trunk_offset_x,
                |p, v| p.trunk_offset_x_m = v,
            ),
            (
                "--trunk-offset-z",
                "trunk_offset_z_m",
                self.trunk_offset_z,
                |p, v| p.trunk_offset_z_m = v,
            ),
            ("--leg-com", "leg_com_from_hip_m", self.leg_com, |p, v| {
                p.leg_com_from_hip_m = v
            }),
            ("--toe-mass", "toe_mass_kg", self.toe_mass, |p, v| {
                p.toe_mass_kg = v
            }),
            (
                "--leg-damping",
                "leg_damping_ns_per_m",
                self.leg_damping,
                |p, v| p.leg_damping_ns_per_m = v,
            ),
            (
                "--hip-damping",
                "hip_damping_nms_per_rad",
                self.hip_damping,
                |p, v| p.hip_damping_nms_per_rad = v,
            ),
            (
                "--planarizer-friction",
                "planarizer_friction_n",
                self.planarizer_friction,
                |p, v| p.planarizer_friction_n = v,
            ),
            (
                "--leg-friction",
                "leg_friction_n",
                self.leg_friction,
                |p, v| p.leg_friction_n = v,
            ),
            (
                "--hip-friction",
                "hip_friction_nm",
                self.hip_friction,
                |p, v| p.hip_friction_nm = v,
            ),
        ];
        if name != "appendix-a" {
            if let Some((flag, ..)) = terms.iter().find(|t| t.2.is_some()) {
                bail!("{flag} is an Appendix A term: it needs --model appendix-a");
            }
            return Ok(hal_sim::planar_sim::Model::Section22);
        }
        let mut g = GeneralParams::from_section_2_2(&PlanarParams::table_2_2());
        for (_, _, v, set) in &terms {
            if let Some(v) = v {
                set(&mut g, *v);
            }
        }
        if let Err(PlanarError::NotPositive(f) | PlanarError::OutOfRange(f)) = g.validate() {
            let flag = terms.iter().find(|t| t.1 == f).map_or(f, |t| t.0);
            let value = terms
                .iter()
                .find(|t| t.1 == f)
                .and_then(|t| t.2)
                .map_or(String::new(), |v| format!(" {v}"));
            let range = TERM_LIMITS.iter().find(|l| l.field == f).map_or(
                String::from("out of range"),
                |l| {
                    // The leg's centre must also lie on the leg.
                    let max = if f == "leg_com_from_hip_m" {
                        l.max.min(g.leg_length_m)
                    } else {
                        l.max
                    };
                    format!("must be within {} ..= {} {}", l.min, max, l.unit)
                },
            );
            bail!("{flag}{value} {range}");
        }
        Ok(hal_sim::planar_sim::Model::AppendixA(g))
    }
}

// Parsed once per process: the variants' sizes cost nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
pub(crate) enum PlanarCmd {
    /// Run from the passive design's apex (T_step 0.5 s, rho 0.125): the
    /// apexes, their drift from the design's, what the touchdowns took.
    Run {
        /// Running speed, m/s.
        #[arg(long, default_value_t = 2.0)]
        speed: f64,
        /// The stabiliser's gain K_c (eq 2.79), N s/m; 0: passive (with
        /// raibert: on top of its thrust, toward the commanded speed).
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        kc: f64,
        /// Simulated time, s.
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// Start from the passive design's apex (eqs 2.76-2.78) or from the
        /// gait's fixed point of the apex return map (`planar stability`).
        #[arg(long, value_parser = ["design", "fixed-point"], default_value = "design")]
        start: String,
        /// The runner: section-2-2 (Table 2.2) or appendix-a (Table 2.2
        /// with Appendix A's terms, set by the flags below; all zero by
        /// default, which is the section 2.2 runner again).
        #[arg(long, value_parser = ["section-2-2", "appendix-a"], default_value = "section-2-2")]
        model: String,
        #[command(flatten)]
        appendix: AppendixArgs,
        /// Directory for trajectory.csv (every millisecond) and
        /// run.png/.svg (created if missing); with raibert strides.csv,
        /// run.png/.svg (speed, pitch, apex, foot placement, hip current) and run.html
        /// (the machine drawn from the trajectory, played in a browser).
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// The controller: passive (the thesis's runner, its hip spring and
        /// the stabiliser) or raibert (the hip actuated: the leg's thrust
        /// (--thrust), foot placement and attitude control on the Appendix A machine
        /// with Table 2.2's masses; --speed-profile, --target-apex and
        /// --inject apply).
        #[arg(long, value_parser = ["passive", "raibert"], default_value = "passive")]
        controller: String,
        /// raibert: the speed command, TIME:SPEED,... (s, m/s) from time 0
        /// [default: 0:SPEED, the --speed given].
        #[arg(long, value_name = "T:V,...")]
        speed_profile: Option<String>,
        /// raibert: the toe's apex to hold, m.
        #[arg(long, default_value_t = 0.15)]
        target_apex: f64,
        /// raibert: push the body, push@TIME:IMPULSE (s, N s, forward
        /// positive; held for 0.05 s); repeatable.
        #[arg(long = "inject", value_name = "push@T:N")]
        inject: Vec<String>,
        /// raibert: the machine from a planar robot file (TOML: [machine],
        /// [hip], [leg], [sensors]; an entry left out keeps the design's; see
        /// `planar robot-template`).
        #[arg(long, value_name = "FILE")]
        robot: Option<PathBuf>,
        /// raibert: how the leg is driven: a vertical controller's name
        /// (`energy-apex`, `shaped`, ...: the leg's motor turns its ball
        /// screw as on the vertical hopper, and that law runs it) or
        /// `force` (Raibert's thrust, a force along the leg in stance)
        /// [default: energy-apex].
        #[arg(long, value_name = "LAW")]
        thrust: Option<String>,
    },
    #[cfg(feature = "live-page")]
    /// Run the hip-actuated machine under Raibert's controller live, paced
    /// by the wall clock, and serve a page that draws it as it runs (the
    /// drawing of `planar run --out`'s run.html), with its speed against
    /// the command, its pitch and its strides. Prints the page's address.
    /// With --tcp, the machine behind the host link instead, for
    /// `hopper-link` and its cockpit.
    Serve {
        /// Where the page listens, ADDR:PORT (port 0: any free one).
        #[arg(long, default_value = "127.0.0.1:8090")]
        http: String,
        /// Serve the machine behind the host link on this socket,
        /// HOST:PORT, in place of the page (port 0: any free one; the
        /// address taken is printed): disarmed, its body held on the boom
        /// with the toe at the target apex until `hopper-link --tcp ADDR
        /// arm` lets it go; the speed profile runs from then, and the run
        /// ends after --duration of robot time.
        #[arg(long, value_name = "HOST:PORT")]
        tcp: Option<String>,
        /// How many times faster than real time the run goes.
        #[arg(long, default_value_t = 1.0)]
        time_scale: f64,
        /// The speed command, TIME:SPEED,... (s, m/s) from time 0.
        #[arg(long, value_name = "T:V,...", default_value = "0:0,3:0.5,8:1.0,13:0")]
        speed_profile: String,
        /// The toe's apex to hold, m.
        #[arg(long, default_value_t = 0.15)]
        target_apex: f64,
        /// The stabiliser's gain K_c (eq 2.79) on top of the thrust, N s/m.
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        kc: f64,
        /// Push the body, push@TIME:IMPULSE (s, N s, forward positive;
        /// held for 0.05 s); repeatable.
        #[arg(long = "inject", value_name = "push@T:N")]
        inject: Vec<String>,
        /// The machine from a planar robot file (`planar robot-template`).
        #[arg(long, value_name = "FILE")]
        robot: Option<PathBuf>,
        /// How the leg is driven: a vertical controller's name through its
        /// ball screw, or `force`.
        #[arg(long, value_name = "LAW", default_value = "energy-apex")]
        thrust: String,
        /// Simulated time, s (at most 600).
        #[arg(long, default_value_t = 60.0)]
        duration: f64,
    },
    /// Print the design machine as a planar robot file (every entry with
    /// its unit, range and meaning), to edit and run with `planar run
    /// --controller raibert --robot FILE`.
    RobotTemplate,
    /// Figures 2.18-2.22 (fig-2-18.png/.svg ...) into DIR.
    Figures {
        /// Directory (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
    /// The apex return map: each gait's fixed point by Newton iteration
    /// and how much a deviation grows per hop (the largest |eigenvalue| of
    /// the map's Jacobian off the energy family), over speeds x K_c.
    Stability {
        /// Speeds, m/s (comma-separated).
        #[arg(long, value_delimiter = ',', default_values_t = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0])]
        speeds: Vec<f64>,
        /// Stabiliser gains K_c, N s/m (comma-separated; 0 is passive).
        #[arg(long, allow_hyphen_values = true, value_delimiter = ',', default_values_t = [-1000.0, -500.0, 0.0, 250.0, 500.0, 750.0, 1000.0, 1250.0, 1500.0, 2000.0, 2500.0, 3000.0])]
        kc: Vec<f64>,
        /// Directory for stability.csv and stability.png/.svg.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

fn planar_summary(r: &hal_sim::planar_sim::PlanarRun) -> String {
    let n = r.apex_heights_m.len();
    // A long run's apexes: the first 12 and the last 4.
    let apexes: Vec<String> = r
        .apex_heights_m
        .iter()
        .enumerate()
        .filter(|(k, _)| *k < 12 || *k + 4 >= n)
        .map(|(k, a)| {
            if k + 4 == n && n > 16 {
                format!("... {a:.4}")
            } else {
                format!("{a:.4}")
            }
        })
        .collect();
    let start = match r.start {
        hal_sim::planar_sim::Start::Design => format!("design {:.4}", r.design_apex_m),
        hal_sim::planar_sim::Start::FixedPoint => format!(
            "fixed point {:.4}, design {:.4}",
            r.start_apex_m, r.design_apex_m
        ),
    };
    let (model, lifts) = if r.model == "appendix-a" {
        (
            " (Appendix A)",
            format!(", {:.3} J by the liftoffs' pick-up", r.liftoff_loss_j),
        )
    } else {
        ("", String::new())
    };
    format!(
        "planar{model}: {} m/s, K_c {} N s/m: {} touchdowns ({:.3} J taken by their impacts{lifts}), {}; {n} apexes (m, {start}): {}; largest drift {:.4} m; largest leg force {:.0} N, stabiliser force {:.0} N",
        r.speed_mps,
        r.gain_ns_per_m,
        r.touchdowns,
        r.touchdown_loss_j,
        if r.fell { "fell" } else { "still running" },
        apexes.join(" "),
        r.apex_drift_m,
        r.max_leg_force_n,
        r.max_stabiliser_force_n
    )
}

fn cmd_planar_stability(
    speeds: &[f64],
    gains: &[f64],
    out: Option<&std::path::Path>,
    json: bool,
) -> Result<()> {
    use hal_sim::planar_stability::scan;
    if speeds.is_empty() || speeds.len() > 40 {
        bail!("--speeds takes 1 to 40 speeds");
    }
    if gains.is_empty() || gains.len() > 100 {
        bail!("--kc takes 1 to 100 gains");
    }
    if speeds.len() * gains.len() > 400 {
        bail!(
            "--speeds x --kc is {} fixed points; at most 400 (each takes up to a few seconds)",
            speeds.len() * gains.len()
        );
    }
    for &v in speeds {
        if !(v.is_finite() && v > 0.0 && v <= 10.0) {
            bail!("--speeds {v} must be within 0 (excluded) ..= 10 m/s");
        }
    }
    for &k in gains {
        if !(k.is_finite() && k.abs() <= 10_000.0) {
            bail!("--kc {k} must be within -10000 ..= 10000 N s/m");
        }
    }
    let bar = indicatif::ProgressBar::new((speeds.len() * gains.len()) as u64)
        .with_finish(indicatif::ProgressFinish::AndClear);
    bar.set_style(
        indicatif::ProgressStyle::with_template("fixed points {pos}/{len} {wide_bar} {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let rows = scan(speeds, gains, &mut || bar.inc(1));
    bar.finish_and_clear();
    let written = match out {
        Some(dir) => hal_sim::planar_stability::write_outputs(dir, &rows, gains)
            .map_err(anyhow::Error::msg)?,
        None => Vec::new(),
    };
    if json {
        say!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({ "kc_ns_per_m": gains, "speeds": rows })
            )?
        );
        return Ok(());
    }
    let opt = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{x:.3}"));
    let range =
        |r: Option<[f64; 2]>| r.map_or("none".to_string(), |r| format!("{} ..= {}", r[0], r[1]));
    say!("growth = largest |eigenvalue| of the apex map's Jacobian off the energy family (below 1: attracting)");
    say!(
        "{:>6} {:>8} {:>8} {:>9} {:>8} {:>22} {:>14}",
        "speed",
        "apex",
        "passive",
        "best K_c",
        "growth",
        "K_c lowering growth",
        "K_c attracting"
    );
    for row in &rows {
        // The passive gait's apex, else the first found.
        let apex = gains
            .iter()
            .position(|&g| g == 0.0)
            .and_then(|k| row.points[k].as_ref())
            .or_else(|| row.points.iter().flatten().next())
            .map(|f| format!("{:.4}", f.apex[0]));
        say!(
            "{:>4.1} m/s {:>6} m {:>8} {:>9} {:>8} {:>22} {:>14}",
            row.speed_mps,
            apex.unwrap_or_else(|| "-".into()),
            opt(row.passive_growth),
            row.best_gain_ns_per_m
                .map_or("-".into(), |g| format!("{g}")),
            opt(row.best_growth),
            range(row.helps_ns_per_m),
            range(row.attracts_ns_per_m)
        );
    }
    if speeds.len() * gains.len() <= 12 {
        for row in &rows {
            for (g, f) in gains.iter().zip(&row.points) {
                match f {
                    Some(f) => {
                        let eig: Vec<String> = f
                            .eigenvalues
                            .iter()
                            .map(|z| {
                                if z[1].abs() < 1e-9 {
                                    format!("{:.4}", z[0])
                                } else {
                                    format!("{:.4}{:+.4}i", z[0], z[1])
                                }
                            })
                            .collect();
                        say!(
                            "{} m/s, K_c {g}: apex {:.4} m, |P(a)-a| {:.1e}, eigenvalues {}",
                            row.speed_mps,
                            f.apex[0],
                            f.residual,
                            eig.join(" ")
                        );
                    }
                    None => say!("{} m/s, K_c {g}: no fixed point found", row.speed_mps),
                }
            }
        }
    }
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}

/// What `planar run --controller raibert` runs: the flags as given.
struct RaibertPlan<'a> {
    /// `--speed-profile` (or the `--speed` held).
    profile: &'a str,
    /// `--inject`.
    inject: &'a [String],
    /// `--duration`, s.
    duration: f64,
    /// `--thrust`.
    thrust: &'a str,
}

/// What `plan` and `cfg` run on the machine (the design's, or `robot`'s
/// file): the command, the pushes and the leg's drive its flags name;
/// one clear error for a bad one.
fn raibert_setup(
    robot: Option<&std::path::Path>,
    plan: &RaibertPlan<'_>,
    cfg: hopper_control::planar::raibert::RaibertConfig,
) -> Result<hal_sim::planar_raibert::PlanarRunSpec> {
    use hal_sim::planar_raibert::{PlanarRunSpec, Push, SpeedProfile, Thrust};
    use hopper_control::laws::ControllerKind;
    let thrust = match hopper_sil::planar::thrust_named(plan.thrust) {
        Ok(None) => Thrust::Force,
        Ok(Some(strategy)) => Thrust::Screw(strategy),
        Err(_) => bail!(
            "--thrust {}: not `force` nor a vertical controller ({})",
            plan.thrust,
            ControllerKind::ALL
                .iter()
                .map(|k| k.name())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let machine = match robot {
        Some(path) => hal_sim::planar_robot::load(path).map_err(anyhow::Error::msg)?,
        None => hopper_sil::planar::PlanarMachine::design(),
    };
    let profile = SpeedProfile::parse(plan.profile).map_err(anyhow::Error::msg)?;
    let pushes = plan
        .inject
        .iter()
        .map(|i| Push::parse(i))
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(anyhow::Error::msg)?;
    let spec = PlanarRunSpec {
        pushes,
        thrust,
        ..PlanarRunSpec::new(machine, profile, plan.duration, cfg)
    };
    spec.check().map_err(anyhow::Error::msg)?;
    Ok(spec)
}

/// Raibert's controller for `planar run` and `planar serve`, from
/// `--target-apex` and `--kc`; one clear error for a bad one.
fn raibert_config(
    target_apex: f64,
    kc: f64,
) -> Result<hopper_control::planar::raibert::RaibertConfig> {
    if !(target_apex.is_finite() && (0.02..=0.5).contains(&target_apex)) {
        bail!("--target-apex {target_apex} must be within 0.02 ..= 0.5 m");
    }
    if !(kc.is_finite() && kc.abs() <= 1e4) {
        bail!("--kc {kc} must be within -10000 ..= 10000 N s/m");
    }
    let mut cfg = hopper_control::planar::raibert::RaibertConfig::table_2_2();
    cfg.target_apex_m = target_apex as f32;
    cfg.stabiliser_gain_ns_per_m = kc as f32;
    Ok(cfg)
}

/// `planar run --controller raibert`: the run, its strides and its
/// figures against their bounds.
fn cmd_planar_raibert(
    robot: Option<&std::path::Path>,
    cfg: hopper_control::planar::raibert::RaibertConfig,
    plan: &RaibertPlan<'_>,
    out: Option<&std::path::Path>,
    json: bool,
) -> Result<()> {
    use hal_sim::planar_raibert as pr;
    let kc = f64::from(cfg.stabiliser_gain_ns_per_m);
    let spec = raibert_setup(robot, plan, cfg)?;
    let r = spec.simulate().map_err(anyhow::Error::msg)?;
    let (machine, profile) = (&spec.machine, &spec.profile);
    let written = match out {
        Some(dir) => pr::write_run(dir, &r, profile).map_err(anyhow::Error::msg)?,
        None => Vec::new(),
    };
    if json {
        say!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(());
    }
    let settle = |s: &pr::Settling| {
        format!(
            "{:>6.2} s  {:>5.2} m/s  {}  {}",
            s.at_s,
            s.command_mps,
            s.hops.map_or("never".into(), |h| format!("{h:>2} hops")),
            s.steady_mps
                .map_or("-".into(), |v| format!("steady {v:.3} m/s"))
        )
    };
    say!(
        "planar (Appendix A, hip actuated): raibert controller{}, {:.1} s simulated, {} strides",
        if kc == 0.0 {
            String::new()
        } else {
            format!(" with the stabiliser K_c {kc} N s/m")
        },
        r.duration_s,
        r.strides.len()
    );
    if let Some(path) = robot {
        let p = &machine.params;
        say!(
            "  machine            {}: body {} kg, leg {} kg, l0 {} m; hip {:.1} N m at {:.1} A",
            path.display(),
            p.trunk_mass_kg,
            p.leg_mass_kg,
            p.leg_length_m,
            machine.hip.torque_limit_nm(),
            machine.hip.current_limit_a
        );
    }
    say!(
        "  speed steps (within 10% of the command, or 0.05 m/s at standstill, within {} hops):",
        pr::SETTLE_HOPS
    );
    for s in &r.steps {
        say!("    {}", settle(s));
    }
    for s in &r.pushes {
        say!(
            "  push at {:.2} s      speed back within the band: {}; largest pitch after it {:.2} deg",
            s.at_s,
            s.hops.map_or("never".into(), |h| format!("{h} hops")),
            s.max_pitch_deg
        );
    }
    say!(
        "  pitch              largest {:.2} deg (bound {} deg; the strides after a push left out)",
        r.max_pitch_deg,
        pr::PITCH_BOUND_DEG
    );
    say!(
        "  apex               target {:.3} m; largest error from stride {} on {:.1}% (bound {:.0}%)",
        r.target_apex_m,
        pr::APEX_FROM_HOP + 1,
        100.0 * r.apex_max_error,
        100.0 * pr::APEX_BAND
    );
    say!(
        "  fall               {}",
        match (r.fell_at_s, &r.stopped_by) {
            (None, _) => "none".to_string(),
            (Some(t), None) => format!("fell at {t:.2} s"),
            (Some(t), Some(why)) =>
                format!("stopped at {t:.2} s by the guard ({why}): both actuators at zero"),
        }
    );
    say!(
        "  hip motor          peak {:.1} A (limit {:.1} A); copper loss {:.0} J ({:.1} W mean); winding at most {:.1} C (derates from {:.0} C)",
        r.hip.peak_current_a,
        machine.hip.current_limit_a,
        r.hip.copper_loss_j,
        r.hip.copper_loss_j / r.duration_s.max(1e-9),
        r.hip.max_winding_c,
        hopper_control::thermal::ThermalConfig::default().derate_winding_c
    );
    if let Some(l) = &r.leg {
        say!(
            "  leg motor          {} through the ball screw: peak {:.1} A (limit {:.1} A); work on the screw {:.0} J, copper loss {:.0} J ({:.1} W mean); winding at most {:.1} C (derates from {:.0} C)",
            l.law,
            l.peak_current_a,
            l.current_limit_a,
            l.motor_work_j,
            l.copper_loss_j,
            l.copper_loss_j / r.duration_s.max(1e-9),
            l.max_winding_c,
            hopper_control::thermal::ThermalConfig::default().derate_winding_c
        );
    }
    say!(
        "  verdict            {}",
        if r.passes() {
            "every figure within its bound"
        } else {
            "OUT OF BOUNDS"
        }
    );
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}

pub(crate) fn cmd_planar(cmd: &PlanarCmd) -> Result<()> {
    match cmd {
        #[cfg(feature = "live-page")]
        PlanarCmd::Serve {
            http,
            tcp,
            time_scale,
            speed_profile,
            target_apex,
            kc,
            inject,
            robot,
            thrust,
            duration,
        } => {
            let cfg = raibert_config(*target_apex, *kc)?;
            let plan = RaibertPlan {
                profile: speed_profile,
                inject,
                duration: *duration,
                thrust,
            };
            let spec = raibert_setup(robot.as_deref(), &plan, cfg)?;
            match tcp {
                Some(tcp) => crate::planar_serve::serve_link(tcp, *time_scale, spec)?,
                None => crate::planar_serve::serve(http, *time_scale, spec)?,
            }
        }
        PlanarCmd::Run {
            speed,
            kc,
            duration,
            start,
            model,
            appendix,
            out,
            json,
            controller,
            speed_profile,
            target_apex,
            inject,
            robot,
            thrust,
        } => {
            if controller == "raibert" {
                let cfg = raibert_config(*target_apex, *kc)?;
                let held = format!("0:{speed}");
                let plan = RaibertPlan {
                    profile: speed_profile.as_deref().unwrap_or(&held),
                    inject,
                    duration: *duration,
                    thrust: thrust.as_deref().unwrap_or("energy-apex"),
                };
                return cmd_planar_raibert(robot.as_deref(), cfg, &plan, out.as_deref(), *json);
            }
            if speed_profile.is_some() || !inject.is_empty() || robot.is_some() || thrust.is_some()
            {
                bail!("--speed-profile, --inject, --robot and --thrust need --controller raibert (the passive runner runs at --speed)");
            }
            use hal_sim::planar_sim::{simulate_model, Start};
            let start = if start == "fixed-point" {
                Start::FixedPoint
            } else {
                Start::Design
            };
            let model = appendix.model(model)?;
            let r = simulate_model(*speed, *kc, *duration, start, &model)
                .map_err(anyhow::Error::msg)?;
            let written = match out {
                Some(dir) => hal_sim::planar_sim::write_run(dir, &r).map_err(anyhow::Error::msg)?,
                None => Vec::new(),
            };
            if *json {
                say!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                say!("{}", planar_summary(&r));
                for p in &written {
                    say!("  wrote {}", p.display());
                }
            }
        }
        PlanarCmd::Stability {
            speeds,
            kc,
            out,
            json,
        } => cmd_planar_stability(speeds, kc, out.as_deref(), *json)?,
        PlanarCmd::RobotTemplate => say!("{}", hal_sim::planar_robot::template().trim_end()),
        PlanarCmd::Figures { out } => {
            let (written, runs) =
                hal_sim::planar_sim::write_figures(out).map_err(anyhow::Error::msg)?;
            for r in &runs {
                say!("{}", planar_summary(r));
            }
            for p in &written {
                say!("  wrote {}", p.display());
            }
        }
    }
    Ok(())
}
