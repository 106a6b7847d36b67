//! `hopper-sim planar run` and `planar figures`: the section 2.2 runner
//! ([`hopper_plant::planar`]) from its passive design's apex, and the
//! simulation counterparts of the thesis's Figures 2.18-2.22.

use crate::csv_out::Fixed;
use hopper_plant::planar::{
    passive_design, ApexState, Gait, PlanarError, PlanarEvent, PlanarParams, PlanarRunner,
    PlanarState,
};
use hopper_plant::planar_general::{GeneralParams, GeneralRunner};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The integration step, s.
const DT_S: f64 = 1e-4;
/// The figures' size, pixels.
const FIGURE_SIZE: (u32, u32) = (1000, 900);

/// One run's apexes and what the touchdowns took.
#[derive(Clone, Debug, Serialize)]
pub struct PlanarRun {
    /// The runner: `section-2-2` or `appendix-a`.
    pub model: &'static str,
    /// Running speed asked for, m/s.
    pub speed_mps: f64,
    /// The stabiliser's gain (0: passive), N s/m.
    pub gain_ns_per_m: f64,
    /// Where it started.
    pub start: Start,
    /// The hip height it started from, m.
    pub start_apex_m: f64,
    /// The design's apex (hip height), m.
    pub design_apex_m: f64,
    /// Hip height at each apex, m.
    pub apex_heights_m: Vec<f64>,
    /// Forward speed at each apex, m/s.
    pub apex_speeds_mps: Vec<f64>,
    /// Body pitch at each apex, rad.
    pub apex_pitch_rad: Vec<f64>,
    /// Touchdowns.
    pub touchdowns: usize,
    /// Energy the touchdown impacts took, J.
    pub touchdown_loss_j: f64,
    /// Energy the liftoffs' pick-up of the toe mass took, J (0 without
    /// one).
    pub liftoff_loss_j: f64,
    /// The largest leg force in stance (the spring's less the
    /// stabiliser's, eq 2.80), N.
    pub max_leg_force_n: f64,
    /// The largest |stabiliser force| `|K_c (x_dot_d - x')|` in stance (eq
    /// 2.79), N: the thesis chose K_c so that it stays below a tenth of the
    /// largest ground force.
    pub max_stabiliser_force_n: f64,
    /// The largest |apex - the apex it started from|, m.
    pub apex_drift_m: f64,
    /// Whether the body fell (hip below half the leg's length).
    pub fell: bool,
    /// Samples every millisecond.
    #[serde(skip)]
    pub samples: Vec<PlanarState>,
}

/// Where a run starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Start {
    /// The passive design's apex (eqs 2.76-2.78), as the thesis.
    Design,
    /// The gait's fixed point of the apex return map
    /// ([`crate::planar_stability`]).
    FixedPoint,
}

/// Table 2.2's runner at `speed_mps` (its step period 0.5 s and stance
/// fraction 0.125), stabilised with `gain_ns_per_m` (0: passive), for
/// `duration_s` from the design's apex.
pub fn simulate(speed_mps: f64, gain_ns_per_m: f64, duration_s: f64) -> Result<PlanarRun, String> {
    simulate_model(
        speed_mps,
        gain_ns_per_m,
        duration_s,
        Start::Design,
        &Model::Section22,
    )
}

/// Which planar runner a run uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Model {
    /// Section 2.2's (Table 2.2).
    Section22,
    /// Appendix A's with these parameters ([`GeneralParams`]; Table 2.2's
    /// design still gives the start).
    AppendixA(GeneralParams),
}

impl Model {
    /// Its name in `--model` and in the JSON.
    pub fn name(&self) -> &'static str {
        match self {
            Model::Section22 => "section-2-2",
            Model::AppendixA(_) => "appendix-a",
        }
    }
}

/// Either runner, stepped alike.
enum Runner {
    Section22(PlanarRunner),
    AppendixA(GeneralRunner),
}

impl Runner {
    fn step(&mut self, dt_s: f64, on_event: &mut impl FnMut(PlanarEvent)) {
        match self {
            Runner::Section22(r) => r.step(dt_s, on_event),
            Runner::AppendixA(r) => r.step(dt_s, on_event),
        }
    }
    fn state(&self) -> PlanarState {
        match self {
            Runner::Section22(r) => r.state(),
            Runner::AppendixA(r) => r.state(),
        }
    }
    /// The leg's force and the stabiliser's, N.
    fn forces(&self) -> (f64, f64) {
        match self {
            Runner::Section22(r) => (r.leg_force_n(), r.stabiliser_force_n()),
            Runner::AppendixA(r) => (r.leg_force_n(), r.stabiliser_force_n()),
        }
    }
}

/// As [`simulate`], from `start` with `model`'s runner (the fixed point is the
/// section 2.2 runner's only).
pub fn simulate_model(
    speed_mps: f64,
    gain_ns_per_m: f64,
    duration_s: f64,
    start: Start,
    model: &Model,
) -> Result<PlanarRun, String> {
    if !(speed_mps.is_finite() && (0.0..=10.0).contains(&speed_mps)) {
        return Err(format!("--speed {speed_mps} must be within 0 ..= 10 m/s"));
    }
    if !(gain_ns_per_m.is_finite() && gain_ns_per_m.abs() <= 10_000.0) {
        return Err(format!(
            "--kc {gain_ns_per_m} must be within -10000 ..= 10000 N s/m"
        ));
    }
    if start == Start::FixedPoint && matches!(model, Model::AppendixA(_)) {
        return Err(
            "--start fixed-point is the section 2.2 runner's (--model section-2-2)".to_string(),
        );
    }
    if !(duration_s.is_finite() && duration_s > 0.0 && duration_s <= 600.0) {
        return Err(format!(
            "--duration {duration_s} must be within 0 ..= 600 s"
        ));
    }
    let p = PlanarParams::table_2_2();
    let d = passive_design(&p, &Gait::table_2_2(speed_mps))
        .map_err(|e| format!("planar design: {e:?}"))?;
    let apex = match start {
        Start::Design => ApexState::of_design(&d, speed_mps),
        Start::FixedPoint => {
            let f = crate::planar_stability::fixed_point(
                &p,
                gain_ns_per_m,
                speed_mps,
                &ApexState::of_design(&d, speed_mps).to_array(),
            )?;
            if f.residual > crate::planar_stability::FOUND {
                return Err(format!(
                    "no fixed point found at {speed_mps} m/s, K_c {gain_ns_per_m} N s/m (Newton's residual {:.1e})",
                    f.residual
                ));
            }
            ApexState::from_array(f.apex)
        }
    };
    let mut r = match model {
        Model::Section22 => Runner::Section22(
            PlanarRunner::from_apex(p, &apex)
                .map_err(|e| format!("planar runner: {e:?}"))?
                .stabilised(gain_ns_per_m, speed_mps),
        ),
        Model::AppendixA(g) => Runner::AppendixA(
            GeneralRunner::from_apex(*g, &apex)
                .map_err(|e| match e {
                    PlanarError::NotPositive(f) | PlanarError::OutOfRange(f) => {
                        format!("Appendix A parameter {f} is out of range")
                    }
                    PlanarError::StanceFraction => format!("{e:?}"),
                })?
                .stabilised(gain_ns_per_m, speed_mps),
        ),
    };
    let mut run = PlanarRun {
        model: model.name(),
        speed_mps,
        gain_ns_per_m,
        start,
        start_apex_m: apex.z_m,
        design_apex_m: d.apex_height_m,
        apex_heights_m: Vec::new(),
        apex_speeds_mps: Vec::new(),
        apex_pitch_rad: Vec::new(),
        touchdowns: 0,
        touchdown_loss_j: 0.0,
        liftoff_loss_j: 0.0,
        max_leg_force_n: 0.0,
        max_stabiliser_force_n: 0.0,
        apex_drift_m: 0.0,
        fell: false,
        samples: vec![r.state()],
    };
    let steps = (duration_s / DT_S).round() as u64;
    for k in 1..=steps {
        r.step(DT_S, &mut |e| match e {
            PlanarEvent::Apex { apex, .. } => {
                run.apex_heights_m.push(apex.z_m);
                run.apex_speeds_mps.push(apex.x_dot_mps);
                run.apex_pitch_rad.push(apex.phi_rad);
            }
            PlanarEvent::Touchdown { loss_j, .. } => {
                run.touchdowns += 1;
                run.touchdown_loss_j += loss_j;
            }
            PlanarEvent::Liftoff { loss_j, .. } => run.liftoff_loss_j += loss_j,
        });
        let q = r.state();
        if !(q.z_m.is_finite() && q.x_dot_mps.is_finite()) {
            return Err(format!(
                "the {} runner's state became non-finite at {:.4} s",
                model.name(),
                q.t_s
            ));
        }
        let (leg, fc) = r.forces();
        run.max_leg_force_n = run.max_leg_force_n.max(leg);
        run.max_stabiliser_force_n = run.max_stabiliser_force_n.max(fc.abs());
        if k % 10 == 0 {
            run.samples.push(q);
        }
        if q.z_m < 0.5 * p.leg_rest_length_m {
            run.fell = true;
            break;
        }
    }
    run.apex_drift_m = run
        .apex_heights_m
        .iter()
        .map(|a| (a - apex.z_m).abs())
        .fold(0.0, f64::max);
    Ok(run)
}

/// Hip height, forward speed, body pitch and leg angle against time, as
/// `NAME.png` and `NAME.svg` (Figures 2.18, 2.19, 2.21).
fn time_plot<DB: plotters::prelude::DrawingBackend>(
    root: plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    run: &PlanarRun,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 18))?;
    let panels = root.split_evenly((4, 1));
    let t_hi = run.samples.last().map_or(1.0, |q| q.t_s).max(0.1);
    type Get = fn(&PlanarState) -> f64;
    let series: [(&str, Get); 4] = [
        ("hip height [m]", |q| q.z_m),
        ("forward speed [m/s]", |q| q.x_dot_mps),
        ("body pitch [rad]", |q| q.phi_rad),
        ("leg angle [rad]", |q| q.theta_rad),
    ];
    for ((label, get), panel) in series.iter().zip(panels.iter()) {
        let (lo, hi) = crate::plot::extent(run.samples.iter().map(get));
        let mut c = crate::plot::time_chart(panel, t_hi, lo, hi, label)?;
        c.draw_series(LineSeries::new(
            run.samples.iter().map(|q| (q.t_s, get(q))),
            BLUE.stroke_width(2),
        ))?;
    }
    root.present()?;
    Ok(())
}

/// Body pitch against hip height (Figures 2.20, 2.22).
fn phase_plot<DB: plotters::prelude::DrawingBackend>(
    root: plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    run: &PlanarRun,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    root.fill(&WHITE)?;
    let (z_lo, z_hi) = crate::plot::extent(run.samples.iter().map(|q| q.z_m));
    let (p_lo, p_hi) = crate::plot::extent(run.samples.iter().map(|q| q.phi_rad));
    let mut c = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(70)
        .build_cartesian_2d((z_lo - 0.01)..(z_hi + 0.01), (p_lo - 0.01)..(p_hi + 0.01))?;
    c.configure_mesh()
        .x_desc("hip height [m]")
        .y_desc("body pitch [rad]")
        .draw()?;
    c.draw_series(LineSeries::new(
        run.samples.iter().map(|q| (q.z_m, q.phi_rad)),
        BLUE.stroke_width(1),
    ))?;
    root.present()?;
    Ok(())
}

/// Figures 2.18-2.22 (10 s runs) into `dir`, whole or not at all; the
/// three runs' summaries.
pub fn write_figures(dir: &Path) -> Result<(Vec<PathBuf>, Vec<PlanarRun>), String> {
    crate::plot::ensure_font()?;
    let runs = vec![
        simulate(2.0, 0.0, 10.0)?,
        simulate(4.0, 0.0, 10.0)?,
        simulate(4.0, 1000.0, 10.0)?,
    ];
    let titles = [
        "Figure 2.18: passive running at 2 m/s (Table 2.2)",
        "Figure 2.19: passive running at 4 m/s",
        "Figure 2.21: 4 m/s with the speed stabiliser, K_c = 1000",
    ];
    let written = crate::out_dir::write_whole(dir, |staging| {
        let mut names = Vec::new();
        for (run, (name, title)) in runs
            .iter()
            .zip(["fig-2-18", "fig-2-19", "fig-2-21"].iter().zip(titles))
        {
            names.extend(crate::plot::png_and_svg(
                staging,
                name,
                FIGURE_SIZE,
                name,
                |a| time_plot(a, run, title),
                |a| time_plot(a, run, title),
            )?);
        }
        for (run, name, title) in [
            (
                &runs[1],
                "fig-2-20",
                "Figure 2.20: pitch against hip height, passive, 4 m/s",
            ),
            (
                &runs[2],
                "fig-2-22",
                "Figure 2.22: pitch against hip height, K_c = 1000, 4 m/s",
            ),
        ] {
            names.extend(crate::plot::png_and_svg(
                staging,
                name,
                FIGURE_SIZE,
                name,
                |a| phase_plot(a, run, title),
                |a| phase_plot(a, run, title),
            )?);
        }
        Ok(names)
    })?;
    Ok((written, runs))
}

/// One row of a planar run's `trajectory.csv`.
#[derive(Serialize)]
struct TrajectoryRow {
    t_s: Fixed<6>,
    x_m: Fixed<9>,
    z_m: Fixed<9>,
    phi_rad: Fixed<9>,
    theta_rad: Fixed<9>,
    x_dot_mps: Fixed<9>,
    z_dot_mps: Fixed<9>,
    phi_dot_rad_s: Fixed<9>,
    theta_dot_rad_s: Fixed<9>,
    leg_length_m: Fixed<9>,
    stance: u8,
}

/// `trajectory.csv` (the run's samples, every millisecond: time, the hip,
/// the angles, their rates, the leg's length, 1 in stance) and
/// `run.png`/`run.svg` (height, speed, pitch and leg angle against time)
/// into `dir`, whole or not at all.
pub fn write_run(dir: &Path, run: &PlanarRun) -> Result<Vec<PathBuf>, String> {
    crate::plot::ensure_font()?;
    let title = format!(
        "planar run ({}): {} m/s, K_c {} N s/m, from the {}",
        run.model,
        run.speed_mps,
        run.gain_ns_per_m,
        match run.start {
            Start::Design => "design's apex",
            Start::FixedPoint => "fixed point",
        }
    );
    crate::out_dir::write_whole(dir, |staging| {
        let mut w = csv::Writer::from_path(staging.join("trajectory.csv"))
            .map_err(|e| format!("cannot write trajectory.csv: {e}"))?;
        for q in &run.samples {
            w.serialize(TrajectoryRow {
                t_s: Fixed(q.t_s),
                x_m: Fixed(q.x_m),
                z_m: Fixed(q.z_m),
                phi_rad: Fixed(q.phi_rad),
                theta_rad: Fixed(q.theta_rad),
                x_dot_mps: Fixed(q.x_dot_mps),
                z_dot_mps: Fixed(q.z_dot_mps),
                phi_dot_rad_s: Fixed(q.phi_dot_rad_s),
                theta_dot_rad_s: Fixed(q.theta_dot_rad_s),
                leg_length_m: Fixed(q.leg_length_m),
                stance: u8::from(q.stance),
            })
            .map_err(|e| format!("cannot write trajectory.csv: {e}"))?;
        }
        w.flush()
            .map_err(|e| format!("cannot write trajectory.csv: {e}"))?;
        let mut names = vec!["trajectory.csv".to_string()];
        names.extend(crate::plot::png_and_svg(
            staging,
            "run",
            FIGURE_SIZE,
            "the run's plot",
            |a| time_plot(a, run, &title),
            |a| time_plot(a, run, &title),
        )?);
        Ok(names)
    })
}
