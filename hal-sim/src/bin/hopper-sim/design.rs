//! `hopper-sim design`: the actuator studies of thesis section 3.1 (`motors`,
//! `leads`, `would-hop`).

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;

#[derive(Subcommand)]
pub(crate) enum DesignCmd {
    /// Table 3.1: the energy each candidate motor adds in the first stance
    /// (k = 10 kN/m, 5 mm lead), at the table's stall torque and, where a
    /// catalogue motor was found, with its datasheet constants.
    Motors {
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Figures 3.1-3.3: the design motor on its torque-speed curve through
    /// leads of 2 ..= 10 mm (k = 10 kN/m): the energy added in the first
    /// stance, the first apex, and with --out the plots.
    Leads {
        /// Directory for lead-study.png and lead-study.svg (created if
        /// missing).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// The machine that would hop: the smallest single change (friction,
    /// torque limit, lead, spring rate, preload) that makes the identified
    /// machine hold a 5 cm hop under shaped and under open-loop torque, and
    /// with --out the feasibility map over friction and torque limit.
    WouldHop {
        /// Directory for feasibility.png and feasibility.svg (with
        /// --endurance: would-hop-endurance.png and .svg, endurance over the
        /// screw lead and over the spring rate).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Instead: the smallest single change of the design machine (lead,
        /// spring rate, the housing's thermal resistance, a catalogue motor)
        /// with which the heat-aware shaped hops 5 cm and 15 cm this long,
        /// s, without the motor derating (docs/endurance.md).
        #[arg(long)]
        endurance: Option<f64>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

pub(crate) fn cmd_design(cmd: &DesignCmd) -> Result<()> {
    use hal_sim::design::{first_stance, table_3_1, CATALOGUE, DESIGN_MOTOR, STUDY_LEADS_M};
    match cmd {
        DesignCmd::Motors { json } => {
            let table = table_3_1()
                .iter()
                .map(|m| first_stance(m, 0.005).map(|f| (*m, f)))
                .collect::<Result<Vec<_>, _>>()
                .map_err(anyhow::Error::msg)?;
            let catalogue = CATALOGUE
                .iter()
                .map(|m| first_stance(m, 0.005).map(|f| (*m, f)))
                .collect::<Result<Vec<_>, _>>()
                .map_err(anyhow::Error::msg)?;
            if *json {
                let row = |(m, f): &(hal_sim::design::Motor, hal_sim::design::FirstStance)| {
                    serde_json::json!({
                        "motor": m, "stall_torque_nm": m.stall_torque_nm(),
                        "no_load_speed_rad_s": m.no_load_speed_rad_s(), "first_stance": f
                    })
                };
                let v = serde_json::json!({
                    "table_3_1": table.iter().map(row).collect::<Vec<_>>(),
                    "catalogue": catalogue.iter().map(row).collect::<Vec<_>>(),
                });
                say!("{}", serde_json::to_string_pretty(&v)?);
                return Ok(());
            }
            say!("Table 3.1: energy added in the first stance (k = 10 kN/m, 5 mm lead, dropped from 0.15 m, the stall torque commanded on the motor's torque-speed line)");
            say!(
                "  {:<15} {:>10} {:>10} {:>10} {:>12} {:>11}",
                "motor",
                "stall N m",
                "thesis J",
                "here J",
                "first apex m",
                "peak rad/s"
            );
            for (m, f) in &table {
                say!(
                    "  {:<15} {:>10.3} {:>10.1} {:>10.2} {:>12.4} {:>11.0}",
                    m.thesis_name,
                    m.stall_torque_nm(),
                    m.thesis_energy_j,
                    f.motor_work_j,
                    f.first_apex_m,
                    f.peak_speed_rad_s
                );
            }
            say!("catalogue motors (datasheet constants, 24 V, the rotor plus the transmission's inertia):");
            for (m, f) in &catalogue {
                say!(
                    "  {} for \"{}\": stall {:.3} N m, no-load {:.0} rad/s: {:.2} J, first apex {:.4} m (thesis {:.1} J)",
                    m.model,
                    m.thesis_name,
                    m.stall_torque_nm(),
                    m.no_load_speed_rad_s(),
                    f.motor_work_j,
                    f.first_apex_m,
                    m.thesis_energy_j
                );
            }
        }
        DesignCmd::WouldHop {
            endurance: Some(duration_s),
            json,
            out,
        } => {
            use hal_sim::endurance::{
                plot_changes, single_changes, unchanged, ENDURANCE_APEXES_M, SINGLE_CHANGES,
            };
            let bar = indicatif::ProgressBar::new_spinner()
                .with_finish(indicatif::ProgressFinish::AndClear);
            bar.set_message(format!(
                "{} runs of {duration_s} s ({SINGLE_CHANGES} single changes, 5 and 15 cm){}",
                2 * SINGLE_CHANGES,
                if out.is_some() {
                    ", and the design's 2 for the plot"
                } else {
                    ""
                }
            ));
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            let changes = single_changes(*duration_s).map_err(anyhow::Error::msg)?;
            let written = match out {
                Some(dir) => {
                    let design_run = unchanged(*duration_s).map_err(anyhow::Error::msg)?;
                    hal_sim::out_dir::write_whole(dir, |staging| {
                        plot_changes(&changes, &design_run, *duration_s, staging)
                    })
                    .map_err(anyhow::Error::msg)?
                }
                None => Vec::new(),
            };
            bar.finish_and_clear();
            if *json {
                say!("{}", serde_json::to_string_pretty(&changes)?);
                return Ok(());
            }
            say!(
                "single changes of the design machine, heat-aware shaped, thermal protection on, {duration_s} s at {} and {} m (smallest change first):",
                ENDURANCE_APEXES_M[0],
                ENDURANCE_APEXES_M[1]
            );
            for c in &changes {
                let at = |i: usize| {
                    let e = c.endurance_s[i]
                        .map_or(format!("no derating in {duration_s} s"), |t| {
                            format!("derates at {t:.0} s")
                        });
                    if c.held[i] {
                        e
                    } else {
                        format!("{e}, apex not held")
                    }
                };
                let what = match c.motor {
                    Some(m) => format!("motor {m} [k_t/sqrt(R)]"),
                    None => c.name.to_string(),
                };
                say!(
                    "  {:<36} {:>9.4} -> {:>9.4}: 5 cm {}; 15 cm {}{}",
                    what,
                    c.design,
                    c.value,
                    at(0),
                    at(1),
                    if c.enough { "  <- enough" } else { "" }
                );
            }
            match changes.iter().find(|c| c.enough) {
                Some(c) => match c.motor {
                    Some(m) => say!(
                        "smallest single change that hops both for {duration_s} s: the motor {m}"
                    ),
                    None => say!(
                        "smallest single change that hops both for {duration_s} s: {} {} -> {}",
                        c.name,
                        c.design,
                        c.value
                    ),
                },
                None => say!(
                    "no single change tried hops both for {duration_s} s (docs/endurance.md: the bound says why)"
                ),
            }
            for f in &written {
                say!("  wrote {}", f.display());
            }
        }
        DesignCmd::WouldHop { out, json, .. } => {
            use hal_sim::design::{
                feasibility_map, smallest_changes, write_feasibility_plot, Holder,
            };
            let bar = indicatif::ProgressBar::new_spinner()
                .with_finish(indicatif::ProgressFinish::AndClear);
            bar.set_message("searching single changes and the maps (about 1,000 runs of 15 s)");
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            let started = std::time::Instant::now();
            let mut smallest = smallest_changes(true).map_err(anyhow::Error::msg)?;
            smallest.extend(smallest_changes(false).map_err(anyhow::Error::msg)?);
            let maps = match out {
                Some(_) => [true, false]
                    .iter()
                    .flat_map(|&p| Holder::ALL.iter().map(move |&h| (h, p)))
                    .map(|(h, p)| feasibility_map(h, p))
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(anyhow::Error::msg)?,
                None => Vec::new(),
            };
            bar.finish_and_clear();
            let written = match out {
                Some(dir) => write_feasibility_plot(&maps, dir).map_err(anyhow::Error::msg)?,
                None => Vec::new(),
            };
            if *json {
                say!("{}", serde_json::to_string_pretty(&smallest)?);
                return Ok(());
            }
            say!(
                "the smallest single change that makes the identified machine hold a 5 cm hop (released from 0.05 m, 15 s each; searched in {:.1} s):",
                started.elapsed().as_secs_f64()
            );
            for s in &smallest {
                let (name, unit) = s.change.label();
                let found = match (s.holds_at, s.apex_m) {
                    (Some(v), Some(a)) => format!("{v:.3} {unit} (steady apex {a:.4} m)"),
                    _ => format!("none of {} values tried holds it", s.tried),
                };
                say!(
                    "  {:<24} {:<12} {:<19} identified {:.3} {unit} -> {found}",
                    name,
                    s.holder.name(),
                    if s.thermal_protection {
                        "thermal protection"
                    } else {
                        "mechanics only"
                    },
                    s.identified
                );
            }
            for p in &written {
                say!("  wrote {}", p.display());
            }
        }
        DesignCmd::Leads { out, json } => {
            let study = STUDY_LEADS_M
                .iter()
                .map(|&l| first_stance(&DESIGN_MOTOR, l))
                .collect::<Result<Vec<_>, _>>()
                .map_err(anyhow::Error::msg)?;
            let written = match out {
                Some(dir) => hal_sim::design::write_lead_plot(&DESIGN_MOTOR, &study, dir)
                    .map_err(anyhow::Error::msg)?,
                None => Vec::new(),
            };
            if *json {
                say!("{}", serde_json::to_string_pretty(&study)?);
                return Ok(());
            }
            say!("lead study: the design motor (2.0 N m stall, 808 rad/s no-load) on its torque-speed curve, k = 10 kN/m, dropped from 0.15 m");
            say!(
                "  {:>8} {:>14} {:>12} {:>14} {:>11} {:>10}",
                "lead mm",
                "motor work J",
                "first apex m",
                "apex gain J",
                "peak rad/s",
                "stance ms"
            );
            for f in &study {
                say!(
                    "  {:>8.0} {:>14.2} {:>12.4} {:>14.2} {:>11.0} {:>10.1}",
                    f.lead_m * 1e3,
                    f.motor_work_j,
                    f.first_apex_m,
                    f.hop_energy_gain_j,
                    f.peak_speed_rad_s,
                    f.stance_s * 1e3
                );
            }
            for p in &written {
                say!("  wrote {}", p.display());
            }
        }
    }
    Ok(())
}
