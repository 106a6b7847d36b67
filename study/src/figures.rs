//! Simulation counterparts of the thesis's figures (`hopper-sim figures`).
//!
//! Every figure is named after the thesis figure it stands beside
//! (`fig-2-4.png`, `fig-2-4.svg`, ...) and is drawn from a run of the
//! firmware's own control crate on the simulated plant ([`crate::run::run`],
//! 10 kHz control, 1 kHz samples), except Figures 4.4-4.6:
//!
//! * **Figures 2.4-2.13** (thesis section 2.1.3): one pair per stance law,
//!   design parameters (Table 2.1), `E_D` = the energy of a 0.15 m apex
//!   (69.98 J, the thesis's 70 J), released at rest from a 0.10 m apex, 5 s.
//!   The even figure shows the state variables `z`, `zd`, `p`, `pd` against
//!   time, the odd one the phase plot `zd` over `z` and the total energy.
//!   The thesis's text does not give the start height (its figures are not
//!   in `thesis.md`); 0.10 m below a 0.15 m target lets a law show whether
//!   it climbs to `E_D`.
//! * **Figures 4.7-4.9** (section 4.4): passive, open-loop torque and
//!   modified torque with the identified parameters (section 4.5), released
//!   from 0.15 m, 3 s: hopping height, actuator position (not for passive,
//!   as in the thesis), total energy, and the energy change of every stance
//!   and flight phase.
//! * **Figures 4.4-4.6** (section 4.3): the flight PD's step response, from a
//!   dedicated simulation of eq 4.2 `theta_dd = (k_m / J_e) i` (no spring, no
//!   friction, the motor alone as in the thesis's bench test) with the
//!   firmware's PD ([`flight_pd::FlightPd`]) at 10 kHz, the current held over
//!   each period and the motor integrated exactly between periods; each with
//!   and without the amplifier's current limit. The hal-sim plant is not used
//!   here because in flight its spring preload holds the nut on its stop, so a
//!   step there would measure the stop, not the loop.

use crate::controller::ControllerSpec;
use crate::params::Params;
use crate::plant::Plant;
use crate::plot::ensure_font;
use crate::run::{self, Phase, RunConfig, Sample, Summary};
use crate::sim_io::SensorConfig;
use hopper_control::laws::{flight_pd, Actuator};
use hopper_control::pd_design::{self, PdGains};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Every figure [`write_all`] draws (each as `.png` and `.svg`).
pub const FIGURE_NAMES: [&str; 16] = [
    "fig-2-4", "fig-2-5", "fig-2-6", "fig-2-7", "fig-2-8", "fig-2-9", "fig-2-10", "fig-2-11",
    "fig-2-12", "fig-2-13", "fig-4-4", "fig-4-5", "fig-4-6", "fig-4-7", "fig-4-8", "fig-4-9",
];

/// Settings of [`write_all`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FigureOptions {
    /// Short runs (0.3 s of hopping) so that tests stay fast; the figures
    /// then show only the first hop.
    pub quick: bool,
}

/// What [`write_all`] produced.
#[derive(Clone, Debug, Default)]
pub struct FiguresReport {
    /// Files written, in order.
    pub files: Vec<PathBuf>,
    /// One line per figure with the numbers the thesis comparison quotes.
    pub notes: Vec<String>,
}

/// The file names (PNG and SVG) [`write_all`] writes.
pub fn expected_files() -> Vec<String> {
    FIGURE_NAMES
        .iter()
        .flat_map(|n| [format!("{n}.png"), format!("{n}.svg")])
        .collect()
}

/// Simulate and draw every figure into `out` (created if missing), whole or
/// not at all ([`crate::out_dir::write_whole`]).
pub fn write_all(out: &Path, opts: &FigureOptions) -> Result<FiguresReport, String> {
    // Fail on an unusable directory before spending time simulating, and
    // without creating anything yet: the nearest existing ancestor must be a
    // directory.
    if let Some(a) = out.ancestors().find(|a| a.exists()) {
        if !a.is_dir() {
            return Err(format!(
                "cannot create output directory {}: {} is not a directory",
                out.display(),
                a.display()
            ));
        }
    }
    ensure_font()?;
    let mut report = FiguresReport::default();
    let mut figs = Vec::new();
    chapter2_figures(opts, &mut figs, &mut report.notes)?;
    step_response_figures(&mut figs, &mut report.notes)?;
    chapter4_figures(opts, &mut figs, &mut report.notes)?;
    report.files = crate::out_dir::write_whole(out, |staging| {
        let mut names = Vec::new();
        for f in &figs {
            for (ext, render) in [("png", render_png as Render), ("svg", render_svg)] {
                let name = format!("{}.{ext}", f.file);
                render(f, &staging.join(&name))
                    .map_err(|e| format!("cannot draw {}: {e}", out.join(&name).display()))?;
                names.push(name);
            }
        }
        Ok(names)
    })?;
    Ok(report)
}

/// Draws one figure into one file.
type Render = fn(&Figure, &Path) -> Result<(), String>;

// ---------------------------------------------------------------- figure model

/// (x, y) points of one series, in the panel's units.
type Points = Vec<(f64, f64)>;

/// How a series is drawn.
#[derive(Clone, Copy, Debug)]
enum Kind {
    Solid,
    Dashed,
    Markers,
}

/// One series of a panel.
struct Line {
    label: String,
    points: Vec<(f64, f64)>,
    color: RGBColor,
    kind: Kind,
}

/// One chart: its own axes and one legend.
struct Panel {
    caption: String,
    x_label: &'static str,
    y_label: &'static str,
    lines: Vec<Line>,
    /// Where the legend goes (clear of the data).
    legend: SeriesLabelPosition,
}

/// A whole figure: panels stacked in `rows` x `cols`.
struct Figure {
    file: &'static str,
    title: String,
    rows: usize,
    cols: usize,
    size: (u32, u32),
    panels: Vec<Panel>,
}

const C_MAIN: RGBColor = RGBColor(31, 119, 180);
const C_SECOND: RGBColor = RGBColor(214, 39, 40);
const C_THIRD: RGBColor = RGBColor(44, 160, 44);

fn line(label: &str, points: Vec<(f64, f64)>, color: RGBColor, kind: Kind) -> Line {
    Line {
        label: label.to_string(),
        points,
        color,
        kind,
    }
}

/// The actuator (nut) position panel, mm against time.
fn nut_position_panel(samples: &[Sample]) -> Panel {
    Panel {
        caption: "Actuator (nut) position, positive compresses the spring".into(),
        legend: SeriesLabelPosition::UpperRight,
        x_label: "time [s]",
        y_label: "p [mm]",
        lines: vec![line(
            "p",
            time_series(samples, |s| s.p_m * 1e3),
            C_MAIN,
            Kind::Solid,
        )],
    }
}

/// The total-energy panel (eq 2.44), J against time, with an optional
/// reference line (e.g. `E_D`).
fn energy_panel(samples: &[Sample], reference: Option<Line>) -> Panel {
    let mut lines = vec![line(
        "E",
        time_series(samples, |s| s.energy_j),
        C_MAIN,
        Kind::Solid,
    )];
    lines.extend(reference);
    Panel {
        caption: "Total energy (eq 2.44)".into(),
        legend: SeriesLabelPosition::UpperRight,
        x_label: "time [s]",
        y_label: "E [J]",
        lines,
    }
}

fn time_series(samples: &[Sample], get: fn(&Sample) -> f64) -> Vec<(f64, f64)> {
    samples.iter().map(|s| (s.t_s, get(s))).collect()
}

// ---------------------------------------------------------------- chapter 2

/// Start apex of the chapter 2 runs, m.
const CH2_START_APEX_M: f64 = 0.10;
/// Apex whose energy is the thesis's `E_D = 70 J`, m.
const CH2_TARGET_APEX_M: f64 = 0.15;
/// Start apex of the chapter 4 runs, m.
const CH4_START_APEX_M: f64 = 0.15;

fn durations(opts: &FigureOptions) -> (f64, f64) {
    if opts.quick {
        (0.3, 0.3)
    } else {
        (5.0, 3.0)
    }
}

/// What every simulated hopping figure's title says of the motor's heat.
pub const NO_THERMAL_LIMIT: &str = "no motor thermal limit (as the thesis)";

/// Run a named firmware controller as the thesis simulated it, without the
/// motor's thermal protection; samples at 1 kHz, default sensor noise, seed 1.
fn simulate(
    params: Params,
    params_name: &str,
    spec: ControllerSpec,
    start_apex_m: f64,
    duration_s: f64,
) -> Result<(Vec<Sample>, Summary), String> {
    let cfg = RunConfig {
        start_apex_m,
        duration_s,
        sample_dt_s: 1e-3,
        ..RunConfig::new(params)
    };
    // The thesis's simulations had no motor thermal limit: run as it did
    // (every hopping figure's title says so, [`NO_THERMAL_LIMIT`]).
    let mut spec = spec;
    spec.params
        .push((&hopper_control::params::THERMAL_PROTECT, 0.0));
    let mut ctl = spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s)?;
    let r = run::run(&cfg, params_name, &mut ctl)?;
    Ok((r.samples, r.summary))
}

fn chapter2_figures(
    opts: &FigureOptions,
    figs: &mut Vec<Figure>,
    notes: &mut Vec<String>,
) -> Result<(), String> {
    let (duration_s, _) = durations(opts);
    let params = Params::design();
    let e_d = Plant::new(params, CH2_TARGET_APEX_M)
        .map_err(|e| e.to_string())?
        .energy_j();
    // (state figure, phase figure, controller, thesis caption)
    let laws: [(&str, &str, &str, &str); 5] = [
        (
            "fig-2-4",
            "fig-2-5",
            "step-open",
            "Open loop position step (eq 2.49)",
        ),
        (
            "fig-2-6",
            "fig-2-7",
            "step-closed",
            "Closed loop position step (eq 2.50)",
        ),
        (
            "fig-2-8",
            "fig-2-9",
            "open-torque",
            "Open loop torque control, 1 N m",
        ),
        (
            "fig-2-10",
            "fig-2-11",
            "energy",
            "Closed loop torque control (eq 2.52)",
        ),
        (
            "fig-2-12",
            "fig-2-13",
            "velocity",
            "Actuator velocity control (eq 2.53)",
        ),
    ];
    for (state_file, phase_file, name, caption) in laws {
        // The design preset as the thesis simulated it: its Table 2.1
        // flight law with these Chapter 2 laws.
        let spec = ControllerSpec {
            target_apex_m: CH2_TARGET_APEX_M,
            sensors: SensorConfig::DEFAULT,
            preset: Some("design"),
            ..ControllerSpec::new(name)
        };
        let (samples, summary) = simulate(params, "design", spec, CH2_START_APEX_M, duration_s)?;
        notes.push(format!("{state_file}/{phase_file} {}", hop_note(&summary)));
        let title = format!(
            "{caption}; design parameters, start apex {CH2_START_APEX_M} m, E_D = {e_d:.2} J; {NO_THERMAL_LIMIT}"
        );
        figs.push(Figure {
            file: state_file,
            title: format!("{title}: state variables"),
            rows: 4,
            cols: 1,
            size: (1000, 1100),
            panels: vec![
                Panel {
                    caption: "Body height coordinate".into(),
                    legend: SeriesLabelPosition::UpperRight,
                    x_label: "time [s]",
                    y_label: "z [m]",
                    lines: vec![
                        line(
                            "z (body)",
                            time_series(&samples, |s| s.z_m),
                            C_MAIN,
                            Kind::Solid,
                        ),
                        line(
                            "l0 (touchdown height)",
                            vec![
                                (0.0, params.leg_length_m),
                                (duration_s, params.leg_length_m),
                            ],
                            C_SECOND,
                            Kind::Dashed,
                        ),
                    ],
                },
                Panel {
                    caption: "Body velocity".into(),
                    legend: SeriesLabelPosition::UpperRight,
                    x_label: "time [s]",
                    y_label: "zd [m/s]",
                    lines: vec![line(
                        "zd",
                        time_series(&samples, |s| s.zd_mps),
                        C_MAIN,
                        Kind::Solid,
                    )],
                },
                nut_position_panel(&samples),
                Panel {
                    caption: "Actuator (nut) velocity".into(),
                    legend: SeriesLabelPosition::UpperRight,
                    x_label: "time [s]",
                    y_label: "pd [m/s]",
                    lines: vec![line(
                        "pd",
                        time_series(&samples, |s| s.pd_mps),
                        C_MAIN,
                        Kind::Solid,
                    )],
                },
            ],
        });
        figs.push(Figure {
            file: phase_file,
            title: format!("{title}: phase plot and total energy"),
            rows: 1,
            cols: 2,
            size: (1300, 560),
            panels: vec![
                Panel {
                    caption: "Phase plot".into(),
                    legend: SeriesLabelPosition::UpperRight,
                    x_label: "z [m]",
                    y_label: "zd [m/s]",
                    lines: vec![line(
                        "trajectory",
                        samples.iter().map(|s| (s.z_m, s.zd_mps)).collect(),
                        C_MAIN,
                        Kind::Solid,
                    )],
                },
                energy_panel(
                    &samples,
                    Some(line(
                        "E_D (0.15 m apex)",
                        vec![(0.0, e_d), (duration_s, e_d)],
                        C_SECOND,
                        Kind::Dashed,
                    )),
                ),
            ],
        });
    }
    Ok(())
}

/// The numbers the comparison doc quotes from a hopping run.
fn hop_note(s: &Summary) -> String {
    let apexes: Vec<String> = s.apex_heights_m.iter().map(|h| format!("{h:.4}")).collect();
    let shown = if apexes.len() > 8 {
        format!(
            "{} ... {}",
            apexes[..5].join(" "),
            apexes[apexes.len() - 3..].join(" ")
        )
    } else {
        apexes.join(" ")
    };
    let opt = |v: Option<f64>, scale: f64, unit: &str| {
        v.map_or("-".to_string(), |x| format!("{:.3} {unit}", x * scale))
    };
    format!(
        "{} ({}): {} hops, apexes [m] [{shown}], steady {}, stance {}, stopped at {}, \
         E {:.2} -> {:.2} J, motor work {:.2} J, peak motor speed {:.0} rad/s ({:.0}% of no-load), \
         peak stroke {:.1} mm",
        s.controller,
        s.params,
        s.hops,
        opt(s.steady_apex_m, 1.0, "m"),
        opt(s.stance_time_s, 1e3, "ms"),
        opt(s.stopped_at_s, 1.0, "s"),
        s.initial_energy_j,
        s.final_energy_j,
        s.ledger.motor_work_j,
        s.peak_motor_speed_rad_s,
        100.0 * s.peak_motor_speed_rad_s / s.no_load_speed_rad_s,
        s.peak_stroke_m * 1e3,
    )
}

// ---------------------------------------------------------------- chapter 4 hops

/// Energy change over each stance and each flight, J, at the time the phase
/// ends: `(stance, flight)`. A stance runs from the last flight sample before
/// touchdown to the first flight sample after liftoff, so it includes the
/// touchdown and liftoff impact losses; a flight is the rest.
fn phase_energy_changes(samples: &[Sample]) -> (Points, Points) {
    let mut stance = Vec::new();
    let mut flight = Vec::new();
    let mut flight_start: Option<&Sample> = samples.first().filter(|s| s.phase == Phase::Flight);
    let mut last_flight: Option<&Sample> = None;
    let mut stance_from: Option<&Sample> = None;
    for s in samples {
        let airborne = s.phase == Phase::Flight;
        match (airborne, stance_from) {
            (false, None) => {
                // Touchdown: the flight that just ended is complete.
                if let (Some(a), Some(b)) = (flight_start, last_flight) {
                    flight.push((b.t_s, b.energy_j - a.energy_j));
                }
                stance_from = last_flight.or(Some(s));
                flight_start = None;
            }
            (true, Some(a)) => {
                // Liftoff: the stance is complete.
                stance.push((s.t_s, s.energy_j - a.energy_j));
                stance_from = None;
                flight_start = Some(s);
            }
            _ => {}
        }
        if airborne {
            last_flight = Some(s);
        }
    }
    (stance, flight)
}

fn chapter4_figures(
    opts: &FigureOptions,
    figs: &mut Vec<Figure>,
    notes: &mut Vec<String>,
) -> Result<(), String> {
    let (_, duration_s) = durations(opts);
    let params = Params::identified();
    let cases: [(&str, &str, &str); 3] = [
        ("fig-4-7", "passive", "Passive hopping"),
        (
            "fig-4-8",
            "open-torque",
            "Open loop torque control (full current in stance)",
        ),
        ("fig-4-9", "modified-torque", "Modified torque control"),
    ];
    for (file, name, caption) in cases {
        let spec = ControllerSpec {
            sensors: SensorConfig::DEFAULT,
            ..ControllerSpec::new(name)
        };
        let (samples, summary) =
            simulate(params, "identified", spec, CH4_START_APEX_M, duration_s)?;
        let (stance, flight) = phase_energy_changes(&samples);
        let fmt = |v: &[(f64, f64)]| {
            v.iter()
                .take(4)
                .map(|(_, e)| format!("{e:+.2}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        notes.push(format!(
            "{file} {}; stance dE [J] {}; flight dE [J] {}",
            hop_note(&summary),
            fmt(&stance),
            fmt(&flight)
        ));
        let mut panels = vec![Panel {
            caption: "Hopping height".into(),
            legend: SeriesLabelPosition::UpperRight,
            x_label: "time [s]",
            y_label: "toe height [cm]",
            lines: vec![line(
                "toe height",
                time_series(&samples, |s| s.toe_height_m * 100.0),
                C_MAIN,
                Kind::Solid,
            )],
        }];
        if name != "passive" {
            panels.push(nut_position_panel(&samples));
        }
        panels.push(energy_panel(&samples, None));
        panels.push(Panel {
            caption: "Energy change of each phase (incl. touchdown/liftoff losses in stance)"
                .into(),
            legend: SeriesLabelPosition::UpperRight,
            x_label: "time at end of phase [s]",
            y_label: "dE [J]",
            lines: vec![
                line("stance", stance, C_SECOND, Kind::Markers),
                line("flight", flight, C_THIRD, Kind::Markers),
            ],
        });
        let rows = panels.len();
        figs.push(Figure {
            file,
            title: format!(
                "{caption}; identified parameters, start apex {CH4_START_APEX_M} m; {NO_THERMAL_LIMIT}"
            ),
            rows,
            cols: 1,
            size: (1000, 280 * rows as u32 + 60),
            panels,
        });
    }
    Ok(())
}

// ---------------------------------------------------------------- chapter 4 PD

/// Control period of the step-response simulation, s (the firmware's 10 kHz).
const PD_DT_S: f64 = 1e-4;

/// One step response of the flight PD on `theta_dd = A i`.
struct StepResponse {
    /// (t, theta) in s, rad.
    angle: Vec<(f64, f64)>,
    /// (t, i) in s, A.
    current: Vec<(f64, f64)>,
    /// Last time the angle was outside 5% of the step, s.
    settling_s: f64,
    /// Largest overshoot beyond the set point, % of the step.
    overshoot_pct: f64,
}

/// Simulate the PD from rest at 0 rad to a set point `step_rad`.
///
/// `limit_a` is the amplifier's clamp; `None` simulates the thesis's
/// unlimited theory. The PD is the firmware's [`flight_pd::FlightPd`], fed
/// the exact angle and speed (the encoder is fine enough that quantisation
/// would not show at this scale).
fn step_response(
    plant_gain: f64,
    gains: PdGains,
    step_rad: f64,
    limit_a: Option<f64>,
    duration_s: f64,
    screw_m_per_rad: f64,
) -> Result<StepResponse, String> {
    let act = Actuator {
        torque_constant_nm_per_a: 1.0,
        // The firmware clamps a non-finite limit to 0 A, so "no limit" is
        // the largest finite current instead.
        current_limit_a: limit_a.map_or(f32::MAX, |l| l as f32),
        screw_m_per_rad: screw_m_per_rad as f32,
        efficiency: 1.0,
        spring_stiffness_n_per_m: 0.0,
        stroke_m: 1.0,
    };
    let cfg = flight_pd::Config {
        gains,
        start_position_m: (step_rad * screw_m_per_rad) as f32,
    };
    let pd = flight_pd::FlightPd::new(&cfg, &act)
        .map_err(|f| format!("flight PD configuration rejected: {}", f.0))?;
    let steps = (duration_s / PD_DT_S).round() as usize;
    let (mut theta, mut omega) = (0.0_f64, 0.0_f64);
    let mut angle = Vec::with_capacity(steps + 1);
    let mut current = Vec::with_capacity(steps + 1);
    let mut settling_s = 0.0;
    let mut peak: f64 = 0.0;
    for k in 0..=steps {
        let t = k as f64 * PD_DT_S;
        let i = f64::from(pd.current_a(theta as f32, omega as f32));
        angle.push((t, theta));
        current.push((t, i));
        if (theta - step_rad).abs() > 0.05 * step_rad.abs() {
            settling_s = t;
        }
        peak = peak.max((theta - step_rad) * step_rad.signum());
        // The current is constant over a period, so the double integrator
        // integrates exactly.
        let acc = plant_gain * i;
        theta += omega * PD_DT_S + 0.5 * acc * PD_DT_S * PD_DT_S;
        omega += acc * PD_DT_S;
    }
    Ok(StepResponse {
        angle,
        current,
        settling_s,
        overshoot_pct: 100.0 * peak / step_rad.abs(),
    })
}

fn step_response_figures(figs: &mut Vec<Figure>, notes: &mut Vec<String>) -> Result<(), String> {
    let p = Params::design();
    // Eq 4.2 with no output torque: J_e is the rotor; the nut's share
    // (m_s r^2 = 1.6e-7 kg m^2) is under 0.1% of it.
    let plant_gain = p.torque_constant_nm_per_a / p.rotor_inertia_kg_m2;
    let limit_a = p.current_limit_a;
    let r = p.screw_m_per_rad();
    let design_err = |e: pd_design::DesignError| format!("PD gain design failed: {e:?}");
    let t_s = 0.1_f32;
    let eq413 = pd_design::pd_gains(plant_gain as f32, 0.707, t_s).map_err(design_err)?;
    // Current-limited design (eqs 4.14-4.18): damping eta_opt fixes the gain
    // ratio k_p / k_d = 2.39124 / t_s; k_p is then bounded so that the
    // largest command, k_p times the step at the first instant, stays inside
    // the amplifier limit for the one-revolution step. The thesis bounds the
    // gains by experiment instead; the bound is what costs settling time.
    let small_step = std::f64::consts::TAU;
    let large_step = 4.0 * std::f64::consts::TAU;
    let ratio = pd_design::kp_over_kd_at_eta_opt(t_s).map_err(design_err)?;
    let kp_lim = (limit_a / small_step) as f32;
    let limited = PdGains {
        kp: kp_lim,
        kd: kp_lim / ratio,
    };
    let cases: [(&str, PdGains, f64, f64, String); 3] = [
        (
            "fig-4-4",
            eq413,
            small_step,
            0.3,
            format!(
                "Flight PD step response, eq 4.13 gains (k_p = {:.4} A/rad, k_d = {:.4} A s/rad), 1 rev step",
                eq413.kp, eq413.kd
            ),
        ),
        (
            "fig-4-5",
            limited,
            small_step,
            0.6,
            format!(
                "Current-limited design (eta_opt = {:.7}, k_p = {:.3} A/rad, k_d = {:.4} A s/rad), 1 rev step",
                pd_design::eta_opt(),
                limited.kp,
                limited.kd
            ),
        ),
        (
            "fig-4-6",
            limited,
            large_step,
            0.6,
            format!(
                "Current-limited design, large initial error (4 rev = {:.0} mm of nut)",
                large_step * r * 1e3
            ),
        ),
    ];
    for (file, gains, step, duration_s, title) in cases {
        let free = step_response(plant_gain, gains, step, None, duration_s, r)?;
        let clamped = step_response(plant_gain, gains, step, Some(limit_a), duration_s, r)?;
        notes.push(format!(
            "{file} kp {:.4} A/rad kd {:.4} A s/rad, step {step:.3} rad: no limit settles (5%) at {:.3} s, \
             overshoot {:.1}%, peak current {:.1} A; with {limit_a:.1} A limit settles at {:.3} s, overshoot {:.1}%",
            gains.kp,
            gains.kd,
            free.settling_s,
            free.overshoot_pct,
            free.current.iter().fold(0.0_f64, |m, (_, i)| m.max(i.abs())),
            clamped.settling_s,
            clamped.overshoot_pct,
        ));
        let limit_label = format!("with {limit_a:.1} A current limit");
        figs.push(Figure {
            file,
            title,
            rows: 2,
            cols: 1,
            size: (1000, 760),
            panels: vec![
                Panel {
                    caption: "Motor angle (eq 4.2 plant, A = 110 rad/(s^2 A))".into(),
                    x_label: "time [s]",
                    y_label: "theta [rad]",
                    legend: SeriesLabelPosition::LowerRight,
                    lines: vec![
                        line("no current limit (theory)", free.angle, C_MAIN, Kind::Solid),
                        line(&limit_label, clamped.angle, C_SECOND, Kind::Solid),
                        line(
                            "set point",
                            vec![(0.0, step), (duration_s, step)],
                            BLACK,
                            Kind::Dashed,
                        ),
                    ],
                },
                Panel {
                    caption: "Amplifier current".into(),
                    legend: SeriesLabelPosition::UpperRight,
                    x_label: "time [s]",
                    y_label: "i [A]",
                    lines: vec![
                        line(
                            "no current limit (theory)",
                            free.current,
                            C_MAIN,
                            Kind::Solid,
                        ),
                        line(&limit_label, clamped.current, C_SECOND, Kind::Solid),
                    ],
                },
            ],
        });
    }
    Ok(())
}

// ---------------------------------------------------------------- rendering

// The callers name the file in the error: they know its final path.
fn render_png(f: &Figure, path: &Path) -> Result<(), String> {
    let root = BitMapBackend::new(path, f.size).into_drawing_area();
    draw(f, &root).and_then(|_| root.present().map_err(|e| e.to_string()))
}

fn render_svg(f: &Figure, path: &Path) -> Result<(), String> {
    let root = SVGBackend::new(path, f.size).into_drawing_area();
    draw(f, &root).and_then(|_| root.present().map_err(|e| e.to_string()))
}

/// Bounds of the finite values, padded by 5% (and never empty).
fn padded_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
    if lo > hi {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05)
        .max(1e-3 * hi.abs().max(lo.abs()))
        .max(1e-9);
    (lo - pad, hi + pad)
}

fn draw<DB: DrawingBackend>(f: &Figure, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    // A long title goes on two lines, split at its last "; ".
    let lines: Vec<&str> = match f.title.rsplit_once("; ") {
        Some((a, b)) if f.title.len() > 90 => vec![a, b],
        _ => vec![f.title.as_str()],
    };
    let (head, body) = root.split_vertically(20 + 24 * lines.len() as u32);
    for (k, line) in lines.iter().enumerate() {
        let (w, _) = head.dim_in_pixel();
        let style = ("sans-serif", 20).into_font().color(&BLACK).pos(
            plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Center,
                plotters::style::text_anchor::VPos::Top,
            ),
        );
        head.draw(&Text::new(*line, (w as i32 / 2, 8 + 24 * k as i32), style))
            .map_err(err)?;
    }
    let areas = body.split_evenly((f.rows, f.cols));
    for (area, panel) in areas.iter().zip(&f.panels) {
        let all = || panel.lines.iter().flat_map(|l| l.points.iter());
        let (x0, x1) = padded_range(all().map(|p| p.0));
        let (y0, y1) = padded_range(all().map(|p| p.1));
        // Room above (or below) the data for the legend, so it never
        // covers a line: the legend box's share of the plot's height.
        let (_, h_px) = area.dim_in_pixel();
        let plot_px = (f64::from(h_px) - 85.0).max(40.0);
        let legend_px = 20.0 * panel.lines.len() as f64 + 14.0;
        let share = (legend_px / plot_px).min(0.6);
        let room = (y1 - y0) * share / (1.0 - share);
        let (y0, y1) = match panel.legend {
            SeriesLabelPosition::UpperLeft
            | SeriesLabelPosition::UpperMiddle
            | SeriesLabelPosition::UpperRight => (y0, y1 + room),
            SeriesLabelPosition::LowerLeft
            | SeriesLabelPosition::LowerMiddle
            | SeriesLabelPosition::LowerRight => (y0 - room, y1),
            _ => (y0, y1),
        };
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.caption, ("sans-serif", 17))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(panel.x_label)
            .y_desc(panel.y_label)
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(err)?;
        for l in &panel.lines {
            let style = l.color.stroke_width(2);
            let pts = l
                .points
                .iter()
                .copied()
                .filter(|p| p.0.is_finite() && p.1.is_finite());
            let anno = match l.kind {
                Kind::Solid => chart.draw_series(LineSeries::new(pts, style)),
                Kind::Dashed => chart.draw_series(DashedLineSeries::new(pts, 8, 6, style)),
                Kind::Markers => {
                    chart.draw_series(pts.map(|p| Circle::new(p, 4, l.color.filled())))
                }
            }
            .map_err(err)?;
            let legend_color = l.color;
            match l.kind {
                Kind::Markers => anno
                    .label(l.label.as_str())
                    .legend(move |(x, y)| Circle::new((x + 10, y), 4, legend_color.filled())),
                _ => anno.label(l.label.as_str()).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], legend_color.stroke_width(2))
                }),
            };
        }
        chart
            .configure_series_labels()
            .position(panel.legend.clone())
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phase_energy_changes_split_stance_and_flight() {
        let mk = |t: f64, phase: Phase, e: f64| Sample {
            t_s: t,
            phase,
            z_m: 0.0,
            zd_mps: 0.0,
            p_m: 0.0,
            pd_mps: 0.0,
            toe_height_m: 0.0,
            spring_force_n: 0.0,
            torque_nm: 0.0,
            energy_j: e,
            winding_c: None,
        };
        let s = [
            mk(0.0, Phase::Flight, 10.0),
            mk(1.0, Phase::Flight, 9.0),
            mk(2.0, Phase::Stance, 8.0),
            mk(3.0, Phase::Stance, 7.5),
            mk(4.0, Phase::Flight, 7.0),
            mk(5.0, Phase::Flight, 6.0),
            mk(6.0, Phase::Stance, 5.0),
        ];
        let (stance, flight) = phase_energy_changes(&s);
        assert_eq!(stance, vec![(4.0, -2.0)]);
        assert_eq!(flight, vec![(1.0, -1.0), (5.0, -1.0)]);
    }

    #[test]
    fn pd_without_limit_matches_the_design_settling_time() -> Result<(), String> {
        let g = pd_design::pd_gains(110.0, 0.707, 0.1).map_err(|e| format!("{e:?}"))?;
        let r = step_response(110.0, g, 1.0, None, 0.3, 7.96e-4)?;
        // Eq 4.10 bounds the envelope, so the response itself settles a
        // little before t_s; sampling at 10 kHz adds a little lag.
        assert!(
            r.settling_s > 0.05 && r.settling_s < 0.1,
            "{}",
            r.settling_s
        );
        Ok(())
    }
}
