//! How long every law hops before the motor derates, at every apex
//! (`hopper-sim endurance`; docs/endurance.md): the table and its plot,
//! beside the bound on any controller (`hal_sim::heat_bound`).

use crate::controller::ControllerSpec;
use crate::params::Params;
use crate::run::{run, RunConfig};
use hopper_control::laws::{shaped, ControllerKind};
use hopper_control::params as p;
use plotters::prelude::*;
use std::path::Path;

/// The apexes of the table, m.
pub const APEXES_M: [f64; 5] = [0.03, 0.05, 0.08, 0.10, 0.15];

/// The name of `shaped`'s heat-aware mode in the table.
pub const HEAT_AWARE: &str = "shaped, heat-aware";

/// One law at one apex.
#[derive(Clone, Debug, PartialEq)]
pub struct Cell {
    /// The law (a controller name, or [`HEAT_AWARE`]).
    pub law: String,
    /// Target and start apex, m.
    pub apex_m: f64,
    /// Time to the derating temperature, s (`None`: not within the run).
    pub endurance_s: Option<f64>,
    /// Mean copper loss per hop from 3 to 8 s, J (`None`: no hop then).
    pub copper_per_hop_j: Option<f64>,
    /// Mean apex from 3 to 8 s, m.
    pub mean_apex_m: Option<f64>,
    /// Whether that mean is within 2 % of the target.
    pub held: bool,
}

/// A run long enough to judge the hops from 3 to 8 s, and at most an hour.
fn check_duration(duration_s: f64) -> Result<(), String> {
    if duration_s.is_finite() && (MIN_DURATION_S..=3600.0).contains(&duration_s) {
        Ok(())
    } else {
        Err(format!(
            "the run must last {MIN_DURATION_S} to 3600 s (apexes are judged from 3 to 8 s), got {duration_s}"
        ))
    }
}

/// Firmware parameters set by name, as [`ControllerSpec::params`] takes them.
type Settings = Vec<(&'static p::Param, f32)>;

/// The heat-aware mode's settings, by parameter.
pub fn heat_aware_settings() -> Settings {
    let c = shaped::Config::heat_aware();
    vec![
        (&p::SHAPED_SWITCH_FRACTION, c.switch_fraction),
        (&p::SHAPED_BRAKE_FRACTION, c.brake_fraction),
        (&p::SHAPED_BRAKING_MARGIN, c.braking_margin),
        (&p::SHAPED_TRACKING_TIME_S, c.tracking_time_s),
        (
            &p::SHAPED_LEAST_EFFORT_RETURN,
            f32::from(u8::from(c.least_effort_return)),
        ),
    ]
}

/// The shortest run the table and the design search take, s: whether an
/// apex is held is judged on the hops from 3 to 8 s.
pub const MIN_DURATION_S: f64 = 8.0;

/// Every law but passive, then the heat-aware mode, at every apex of
/// [`APEXES_M`], `duration_s` each (at least [`MIN_DURATION_S`]), in
/// parallel; `preset` names the plant, `motor` a catalogue motor on it
/// (its thermal data in the firmware; None: the preset's own).
pub fn table(
    preset: &str,
    motor: Option<&crate::motors::CatalogueMotor>,
    duration_s: f64,
) -> Result<Vec<Cell>, String> {
    use rayon::prelude::*;
    check_duration(duration_s)?;
    let params = Params::preset(preset).ok_or_else(|| format!("no preset {preset}"))?;
    let mut laws: Vec<(String, &'static str, Settings)> = ControllerKind::ALL
        .iter()
        // The thesis's laws and this project's own (a law added to the
        // registry is run by name: `hopper-sim run --controller`).
        .filter(|k| **k != ControllerKind::Passive && k.is_builtin())
        .map(|k| (k.name().to_string(), k.name(), Vec::new()))
        .collect();
    laws.push((HEAT_AWARE.to_string(), "shaped", heat_aware_settings()));
    let (params, laws) = match motor {
        Some(m) => {
            let laws = laws
                .into_iter()
                .map(|(law, name, own)| (law, name, m.apply(&params, own).1))
                .collect();
            (m.on(&params), laws)
        }
        None => (params, laws),
    };
    let jobs: Vec<(usize, f64)> = (0..laws.len())
        .flat_map(|l| APEXES_M.iter().map(move |a| (l, *a)))
        .collect();
    jobs.par_iter()
        .map(|&(l, apex_m)| {
            let (law, name, set) = &laws[l];
            cell(&params, preset, law, name, set, apex_m, duration_s)
        })
        .collect()
}

/// One run of `controller` (with `settings`) on `params` (from `preset`),
/// released at and aiming for `apex_m`, `duration_s` long, as a [`Cell`]
/// named `law`: the table's and the design search's one way to judge a
/// run.
fn cell(
    params: &Params,
    preset: &str,
    law: &str,
    controller: &str,
    settings: &Settings,
    apex_m: f64,
    duration_s: f64,
) -> Result<Cell, String> {
    let mut cfg = RunConfig::new(*params);
    cfg.start_apex_m = apex_m;
    cfg.duration_s = duration_s;
    cfg.sample_dt_s = 0.0;
    let spec = ControllerSpec {
        target_apex_m: apex_m,
        params: settings.clone(),
        preset: Params::preset_name(preset),
        ..ControllerSpec::new(controller)
    };
    let mut c = spec.build(params, apex_m, cfg.control_dt_s)?;
    let s = run(&cfg, preset, &mut c)?.summary;
    let hops: Vec<_> = s
        .hop_ledger
        .iter()
        .filter(|h| (3.0..=8.0).contains(&h.apex_time_s))
        .collect();
    let n = hops.len() as f64;
    let mean = |f: fn(&crate::run::HopEnergy) -> f64| {
        (n > 0.0).then(|| hops.iter().map(|h| f(h)).sum::<f64>() / n)
    };
    let mean_apex_m = mean(|h| h.apex_m);
    Ok(Cell {
        law: law.to_string(),
        apex_m,
        endurance_s: s.thermal.and_then(|t| t.endurance_s),
        copper_per_hop_j: mean(|h| h.copper_loss_j),
        mean_apex_m,
        held: mean_apex_m.is_some_and(|m| (m - apex_m).abs() < 0.02 * apex_m),
    })
}

/// The table as Markdown: endurance and copper per hop, with the mean apex
/// where the target is not held.
pub fn markdown(cells: &[Cell]) -> String {
    let mut out = String::from("| law |");
    for a in APEXES_M {
        out += &format!(" {:.0} cm |", a * 100.0);
    }
    out += "\n|---|";
    out += &"---|".repeat(APEXES_M.len());
    out += "\n";
    let mut laws: Vec<&str> = Vec::new();
    for c in cells {
        if !laws.contains(&c.law.as_str()) {
            laws.push(&c.law);
        }
    }
    for law in laws {
        out += &format!("| {law} |");
        for c in cells.iter().filter(|c| c.law == law) {
            let e = c
                .endurance_s
                .map_or("none".to_string(), |t| format!("{t:.1} s"));
            let j = c
                .copper_per_hop_j
                .map_or("-".to_string(), |j| format!("{j:.0} J"));
            let miss = match (c.held, c.mean_apex_m) {
                (true, _) => String::new(),
                (false, Some(m)) => format!(" (apex {m:.3})"),
                (false, None) => " (stops hopping)".to_string(),
            };
            out += &format!(" {e}, {j}{miss} |");
        }
        out += "\n";
    }
    out
}

/// Draws endurance against apex (endurance.png, endurance.svg in `dir`,
/// titled `caption`):
/// one line per law through the apexes it holds (hollow markers where it
/// does not), and the bound's longest endurance (`bound`: apex m,
/// endurance s) dashed.
pub fn plot(
    cells: &[Cell],
    bound: &[(f64, f64)],
    caption: &str,
    dir: &Path,
) -> Result<Vec<String>, String> {
    crate::plot::ensure_font()?;
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let mut laws: Vec<&str> = Vec::new();
    for c in cells {
        if !laws.contains(&c.law.as_str()) {
            laws.push(&c.law);
        }
    }
    let top = cells
        .iter()
        .filter_map(|c| c.endurance_s)
        .chain(bound.iter().map(|b| b.1))
        .fold(60.0_f64, f64::max)
        * 1.1;
    macro_rules! draw {
        ($area:expr) => {{
            let area = $area;
            area.fill(&WHITE)?;
            let mut chart = ChartBuilder::on(&area)
                .caption(caption, ("sans-serif", 20))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(55)
                .build_cartesian_2d(0.02..0.16_f64, 0.0..top)?;
            chart
                .configure_mesh()
                .x_desc("apex held [m] (start = target)")
                .y_desc("endurance [s]")
                .draw()?;
            if !bound.is_empty() {
                chart
                    .draw_series(DashedLineSeries::new(
                        bound.iter().copied(),
                        8,
                        5,
                        BLACK.stroke_width(2),
                    ))?
                    .label("bound: the least-heat hop (any controller)")
                    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
            }
            for (i, law) in laws.iter().enumerate() {
                let colour = if law.contains("heat-aware") {
                    RGBColor(0, 80, 200).to_rgba()
                } else {
                    Palette99::pick(i).to_rgba()
                };
                let mine: Vec<&Cell> = cells.iter().filter(|c| c.law == *law).collect();
                let held: Vec<(f64, f64)> = mine
                    .iter()
                    .filter(|c| c.held)
                    .filter_map(|c| c.endurance_s.map(|e| (c.apex_m, e)))
                    .collect();
                let width = if law.contains("heat-aware") { 3 } else { 1 };
                chart
                    .draw_series(LineSeries::new(held.clone(), colour.stroke_width(width)))?
                    .label(*law)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(width))
                    });
                chart.draw_series(
                    held.iter()
                        .map(|&(x, y)| Circle::new((x, y), 4, colour.filled())),
                )?;
                chart.draw_series(
                    mine.iter()
                        .filter(|c| !c.held)
                        .filter_map(|c| c.endurance_s.map(|e| (c.apex_m, e)))
                        .map(|(x, y)| Circle::new((x, y), 4, colour.stroke_width(1))),
                )?;
            }
            crate::plot::hollow_marker_key(
                &mut chart,
                "hollow marker: target not held (mean apex 3-8 s off by > 2 %)",
            )?;
            crate::plot::legend(&mut chart, SeriesLabelPosition::UpperRight)?;
            area.present()?;
            Ok(())
        }};
    }
    crate::plot::png_and_svg(
        dir,
        "endurance",
        (1000, 650),
        "the endurance plot",
        |a| draw!(a),
        |a| draw!(a),
    )
}

/// The bound's longest endurance per apex from a CSV file with columns
/// `apex_m` and `endurance_s` (a header line first; `endurance_s` empty
/// where it is indefinite, left out of the plot).
pub fn read_bound(path: &Path) -> Result<Vec<(f64, f64)>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, header)) if header.trim().starts_with("apex_m") => {}
        _ => {
            return Err(format!(
                "{}:1: expected the header `apex_m,endurance_s`",
                path.display()
            ))
        }
    }
    let mut out = Vec::new();
    for (n, line) in lines {
        let mut f = line.split(',');
        let (Some(a), Some(e)) = (f.next(), f.next()) else {
            return Err(format!(
                "{}:{}: expected apex_m,endurance_s",
                path.display(),
                n + 1
            ));
        };
        let bad = || {
            format!(
                "{}:{}: not a finite, non-negative number in `{line}`",
                path.display(),
                n + 1
            )
        };
        let number = |s: &str| {
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v >= 0.0)
                .ok_or_else(bad)
        };
        let a = number(a)?;
        if e.trim().is_empty() {
            continue;
        }
        out.push((a, number(e)?));
    }
    Ok(out)
}

/// One single change of the design machine, tried for endurance.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Change {
    /// What changed: `screw_lead_m`, `spring_stiffness_n_per_m` (plant
    /// parameters), `thermal.housing_to_ambient_k_per_w` (a heat sink or
    /// fan on the motor's housing; the winding's own data unchanged) or
    /// `motor` (a catalogue motor, [`crate::motors`]).
    pub name: &'static str,
    /// The design value, in the changed quantity's unit (m, N/m or K/W;
    /// for a motor its motor constant `k_t / sqrt(R)`, N m/sqrt(W)).
    pub design: f64,
    /// The value tried, in the same unit.
    pub value: f64,
    /// The catalogue motor's name where `name` is `motor`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motor: Option<&'static str>,
    /// Time to the derating at each apex of [`ENDURANCE_APEXES_M`], s
    /// (`None`: it did not derate within the run).
    pub endurance_s: [Option<f64>; 2],
    /// Whether each apex was held (mean apex 3-8 s within 2 %).
    pub held: [bool; 2],
    /// Whether it hopped both apexes for the whole run without derating.
    pub enough: bool,
}

/// The apexes the endurance design search must hold, m: a 5 cm and a
/// 15 cm hop.
pub const ENDURANCE_APEXES_M: [f64; 2] = [0.05, 0.15];

/// What a single change changes.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Knob {
    /// The screw lead, m.
    Lead,
    /// The spring rate, N/m.
    Spring,
    /// The housing's thermal resistance to ambient, K/W.
    Housing,
    /// The motor, by its motor constant.
    Motor(&'static crate::motors::CatalogueMotor),
}

impl Knob {
    /// [`Change::name`].
    fn name(self) -> &'static str {
        match self {
            Knob::Lead => "screw_lead_m",
            Knob::Spring => "spring_stiffness_n_per_m",
            Knob::Housing => p::THERMAL_HOUSING_TO_AMBIENT.name,
            Knob::Motor(_) => "motor",
        }
    }
}

/// A change to try: the knob, its design value, the value tried.
type Try = (Knob, f64, f64);

/// A motor's motor constant `k_t / sqrt(R)`, N m/sqrt(W): torque for the
/// square root of the copper loss.
fn motor_constant(m: &crate::design::Motor) -> f64 {
    m.torque_constant_nm_per_a / m.resistance_ohm.sqrt()
}

/// Runs each change for `duration_s` at both apexes with the heat-aware
/// `shaped`, in parallel.
fn run_changes(tries: &[Try], duration_s: f64) -> Result<Vec<Change>, String> {
    use rayon::prelude::*;
    check_duration(duration_s)?;
    let design = Params::design();
    tries
        .par_iter()
        .map(|&(knob, design_value, value)| {
            let (mut params, mut set) = (design, heat_aware_settings());
            match knob {
                Knob::Motor(m) => (params, set) = m.apply(&design, set),
                Knob::Lead => params.screw_lead_m = value,
                Knob::Spring => params.spring_stiffness_n_per_m = value,
                Knob::Housing => set.push((&p::THERMAL_HOUSING_TO_AMBIENT, value as f32)),
            }
            let mut endurance_s = [None; 2];
            let mut held = [false; 2];
            for (i, apex_m) in ENDURANCE_APEXES_M.into_iter().enumerate() {
                let c = cell(&params, "design", "", "shaped", &set, apex_m, duration_s)?;
                (endurance_s[i], held[i]) = (c.endurance_s, c.held);
            }
            Ok(Change {
                name: knob.name(),
                design: design_value,
                value,
                motor: match knob {
                    Knob::Motor(m) => Some(m.name),
                    _ => None,
                },
                endurance_s,
                held,
                enough: held.iter().all(|h| *h) && endurance_s.iter().all(Option::is_none),
            })
        })
        .collect()
}

/// The screw leads tried, as factors of the design's.
const LEAD_FACTORS: [f64; 8] = [0.6, 0.8, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0];
/// The spring rates tried, as factors of the design's.
const SPRING_FACTORS: [f64; 4] = [0.5, 0.7, 1.4, 2.0];
/// The housing's thermal resistances to ambient tried, K/W.
const HOUSING_K_PER_W: [f64; 4] = [2.0, 1.0, 0.5, 0.1];

/// How many changes [`single_changes`] tries (each at both apexes).
pub const SINGLE_CHANGES: usize =
    LEAD_FACTORS.len() + SPRING_FACTORS.len() + HOUSING_K_PER_W.len() + crate::motors::MOTORS.len()
        - 1;

/// Tries each single change of the design machine (screw lead, spring
/// rate, the housing's thermal resistance to ambient, the catalogue
/// motors) with the heat-aware `shaped`, thermal protection on, released
/// at 5 and 15 cm for `duration_s` each; in order of how far each is from
/// the design (the ratio's logarithm), in parallel.
pub fn single_changes(duration_s: f64) -> Result<Vec<Change>, String> {
    let design = Params::design();
    let lead = design.screw_lead_m;
    let spring = design.spring_stiffness_n_per_m;
    let housing = f64::from(p::THERMAL_HOUSING_TO_AMBIENT.default);
    let mut tries: Vec<Try> = Vec::new();
    for f in LEAD_FACTORS {
        tries.push((Knob::Lead, lead, lead * f));
    }
    for f in SPRING_FACTORS {
        tries.push((Knob::Spring, spring, spring * f));
    }
    for r in HOUSING_K_PER_W {
        tries.push((Knob::Housing, housing, r));
    }
    let own = motor_constant(&crate::motors::MOTORS[0].motor);
    for m in &crate::motors::MOTORS[1..] {
        tries.push((Knob::Motor(m), own, motor_constant(&m.motor)));
    }
    tries.sort_by(|a, b| (a.2 / a.1).ln().abs().total_cmp(&(b.2 / b.1).ln().abs()));
    run_changes(&tries, duration_s)
}

/// The design machine itself as a [`Change`] of nothing (the screw lead
/// at its design value), for the plot of [`plot_changes`].
pub fn unchanged(duration_s: f64) -> Result<Change, String> {
    let lead = Params::design().screw_lead_m;
    run_changes(&[(Knob::Lead, lead, lead)], duration_s)?
        .pop()
        .ok_or_else(|| "no run".to_string())
}

/// Draws endurance over the screw lead and over the spring rate, at 5 and
/// 15 cm (would-hop-endurance.png and .svg in `dir`): the leads and
/// spring rates among `changes` ([`single_changes`]) and `design`
/// ([`unchanged`]) in both panels.
pub fn plot_changes(
    changes: &[Change],
    design_run: &Change,
    duration_s: f64,
    dir: &Path,
) -> Result<Vec<String>, String> {
    crate::plot::ensure_font()?;
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let design = Params::design();
    let top = duration_s * 1.12;
    // (panel title, axis label, quantity, unit scale, design value)
    let panels = [
        (
            "screw lead",
            "screw lead [mm]",
            "screw_lead_m",
            1e3,
            design.screw_lead_m,
        ),
        (
            "spring rate",
            "spring rate [kN/m]",
            "spring_stiffness_n_per_m",
            1e-3,
            design.spring_stiffness_n_per_m,
        ),
    ];
    let colours = [RGBColor(0, 80, 200), RGBColor(200, 40, 40)];
    macro_rules! draw {
        ($area:expr) => {{
            let area = $area;
            area.fill(&WHITE)?;
            let (title, rest) = area.split_vertically(40);
            title.draw_text(
                &format!(
                    "Time to the motor's derating, heat-aware shaped, design machine, one change at a time ({duration_s} s runs)"
                ),
                &("sans-serif", 18).into_text_style(&title),
                (12, 12),
            )?;
            let halves = rest.split_evenly((1, 2));
            for ((panel, xdesc, quantity, scale, design_value), half) in
                panels.iter().zip(halves.iter())
            {
                let mut points: Vec<&Change> = changes
                    .iter()
                    .filter(|c| c.name == *quantity)
                    .chain(std::iter::once(design_run))
                    .collect();
                let x_of = |c: &Change| {
                    if c.name == *quantity {
                        c.value * scale
                    } else {
                        design_value * scale
                    }
                };
                points.sort_by(|a, b| x_of(a).total_cmp(&x_of(b)));
                let xs: Vec<f64> = points.iter().map(|c| x_of(c)).collect();
                let (lo, hi) = crate::plot::extent(xs.iter().copied());
                let pad = 0.05 * (hi - lo).max(1e-9);
                let mut chart = ChartBuilder::on(half)
                    .caption(*panel, ("sans-serif", 18))
                    .margin(12)
                    .x_label_area_size(40)
                    .y_label_area_size(55)
                    .build_cartesian_2d((lo - pad)..(hi + pad), 0.0..top)?;
                chart
                    .configure_mesh()
                    .x_desc(*xdesc)
                    .y_desc("time to the derating [s]")
                    .draw()?;
                let x_design = design_value * scale;
                chart.draw_series(DashedLineSeries::new(
                    [(x_design, 0.0), (x_design, top)],
                    6,
                    4,
                    RGBColor(120, 120, 120).stroke_width(1),
                ))?;
                chart
                    .draw_series(DashedLineSeries::new(
                        [(lo - pad, duration_s), (hi + pad, duration_s)],
                        8,
                        5,
                        BLACK.stroke_width(1),
                    ))?
                    .label(format!("{duration_s} s: no derating in the run (drawn at the run's length)"))
                    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
                for (i, apex_m) in ENDURANCE_APEXES_M.iter().enumerate() {
                    let colour = colours[i];
                    let line: Vec<(f64, f64, bool)> = points
                        .iter()
                        .zip(&xs)
                        .map(|(c, x)| (*x, c.endurance_s[i].unwrap_or(duration_s), c.held[i]))
                        .collect();
                    chart
                        .draw_series(LineSeries::new(
                            line.iter().filter(|p| p.2).map(|p| (p.0, p.1)),
                            colour.stroke_width(2),
                        ))?
                        .label(format!("{:.0} cm hop", apex_m * 100.0))
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                        });
                    chart.draw_series(line.iter().map(|&(x, y, held)| {
                        if held {
                            Circle::new((x, y), 4, colour.filled())
                        } else {
                            Circle::new((x, y), 4, colour.stroke_width(1))
                        }
                    }))?;
                }
                crate::plot::hollow_marker_key(
                    &mut chart,
                    "hollow, off the line: apex not held; grey dashes: the design",
                )?;
                crate::plot::legend(&mut chart, SeriesLabelPosition::MiddleRight)?;
            }
            area.present()?;
            Ok(())
        }};
    }
    crate::plot::png_and_svg(
        dir,
        "would-hop-endurance",
        (1300, 560),
        "the endurance design plot",
        |a| draw!(a),
        |a| draw!(a),
    )
}

#[cfg(test)]
mod tests {
    /// The QEMU image's heat-aware scenario runs the heat-aware mode: its
    /// `[params]` are [`heat_aware_settings`], the one declaration (the
    /// file cannot name the Rust type, so a test keeps them equal).
    #[test]
    fn the_qemu_heat_aware_scenario_is_the_heat_aware_mode() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../scenarios/qemu/heat-aware.toml"
        );
        let s = crate::scenario::load(std::path::Path::new(path)).unwrap_or_else(|e| panic!("{e}"));
        let mut got: Vec<_> = s
            .settings
            .firmware_params
            .unwrap_or_default()
            .into_iter()
            .map(|(p, v)| (p.name, v))
            .collect();
        let mut want: Vec<_> = heat_aware_settings()
            .into_iter()
            .map(|(p, v)| (p.name, v))
            .collect();
        got.sort_by(|a, b| a.0.cmp(b.0));
        want.sort_by(|a, b| a.0.cmp(b.0));
        assert_eq!(got, want);
    }

    use super::*;

    #[test]
    fn a_motor_change_runs_on_that_motor_and_the_plot_draws_the_runs() {
        let pittman = &crate::motors::MOTORS[2];
        let own = motor_constant(&crate::motors::MOTORS[0].motor);
        let lead = Params::design().screw_lead_m;
        let runs = run_changes(
            &[
                (Knob::Motor(pittman), own, motor_constant(&pittman.motor)),
                (Knob::Lead, lead, 1.5 * lead),
            ],
            MIN_DURATION_S,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(runs[0].name, "motor");
        assert_eq!(runs[0].motor, Some("pittman-14204"));
        assert!(runs[0].value > runs[0].design);
        // Both hold both apexes for 8 s, too short to derate.
        for c in &runs {
            assert_eq!(c.held, [true, true], "{c:?}");
            assert_eq!(c.endurance_s, [None, None], "{c:?}");
            assert!(c.enough, "{c:?}");
        }
        let design = unchanged(MIN_DURATION_S).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(design.value, design.design);
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let files = plot_changes(&runs, &design, MIN_DURATION_S, dir.path())
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(files.len(), 2);
        let svg = std::fs::read_to_string(dir.path().join("would-hop-endurance.svg"))
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(svg.contains("screw lead") && svg.contains("spring rate"));
        assert_eq!(SINGLE_CHANGES, 18);
    }
}
