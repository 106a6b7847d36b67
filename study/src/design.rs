//! The actuator studies of thesis section 3.1 (Table 3.1, Figures 3.1-3.3):
//! the energy a motor adds in the first stance through a ball screw into
//! the spring, with the motor on its own voltage-limited torque-speed curve
//! rather than behind the amplifier's 1 N m.
//!
//! One run per point, the same as `hopper-sim run`: the design machine with
//! the motor's constants and the screw's lead, dropped from 0.15 m, the
//! firmware's open-torque law commanding the motor's stall torque in
//! stance. The plant's motor limit `|R i + k_e omega| <= V` with the current
//! limit at the stall current `V / R` is the straight torque-speed line
//! `tau <= tau_stall (1 - omega / omega_0)`; the DAC's scale is set to reach
//! that current (calibration.dac_amps_per_code). `docs/design.md` compares
//! the figures with the thesis's.

use crate::controller::ControllerSpec;
use crate::params_toml::PlantSet;
use crate::run::{self, Sample};
use crate::scenario::{Overrides, Settings};
use crate::Params;
use hopper_control::laws::ControllerKind;
use serde::Serialize;

pub use crate::motors::{table_3_1, Motor, CATALOGUE, DESIGN_MOTOR, TRANSMISSION_INERTIA_KG_M2};

/// The thesis's spring rate for these studies, N/m (`k = 10`, kN/m).
pub const STUDY_SPRING_N_PER_M: f64 = 10_000.0;
/// The drop: the toe this high at rest, m (the lead-study preset's).
pub const STUDY_START_APEX_M: f64 = 0.15;
/// Drop (0.17 s), first stance (about 0.1 s) and the flight after, s.
const STUDY_DURATION_S: f64 = 0.6;

/// What the first stance did.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FirstStance {
    /// Screw lead, m.
    pub lead_m: f64,
    /// The motor's thesis name.
    pub motor: &'static str,
    /// Motor work from the first touchdown to the first liftoff (the
    /// plant's ledger): the thesis's "energy added", J.
    pub motor_work_j: f64,
    /// The first apex after it, m (what the stance did to the hop: the
    /// motor's work also spins the rotor, and that part does not lift the
    /// body).
    pub first_apex_m: f64,
    /// The energy the first apex has over the drop's, `m_t g (h1 - h0)`, J.
    pub hop_energy_gain_j: f64,
    /// Stance duration, s.
    pub stance_s: f64,
    /// Fastest motor speed in the stance, rad/s.
    pub peak_speed_rad_s: f64,
    /// Largest motor torque in the stance, N m.
    pub peak_torque_nm: f64,
    /// The stance's operating points: (time since touchdown s, motor speed
    /// rad/s, motor torque N m, motor work so far J: `eta tau omega`
    /// integrated, what reaches the nut), one a period.
    #[serde(skip)]
    pub points: Vec<(f64, f64, f64, f64)>,
}

/// The design machine with `motor` and `lead_m` and the study's spring.
pub fn study_params(motor: &Motor, lead_m: f64) -> Params {
    Params {
        spring_stiffness_n_per_m: STUDY_SPRING_N_PER_M,
        screw_lead_m: lead_m,
        torque_constant_nm_per_a: motor.torque_constant_nm_per_a,
        winding_resistance_ohm: motor.resistance_ohm,
        rotor_inertia_kg_m2: motor.rotor_inertia_kg_m2,
        supply_voltage_v: motor.supply_v,
        current_limit_a: motor.stall_current_a(),
        ..Params::design()
    }
}

/// The first stance of `motor` through a `lead_m` screw (module docs).
pub fn first_stance(motor: &Motor, lead_m: f64) -> Result<FirstStance, String> {
    let params = study_params(motor, lead_m);
    params
        .validate()
        .map_err(|e| format!("{} with a {} mm lead: {e}", motor.thesis_name, lead_m * 1e3))?;
    let cli = Overrides {
        plant: Some(PlantSet {
            params,
            name: format!("{} motor, {} mm lead", motor.thesis_name, lead_m * 1e3),
            preset: Some("design"),
        }),
        controller: Some(ControllerKind::OpenTorque),
        torque_nm: Some(motor.stall_torque_nm()),
        noise: Some(false),
        start_apex_m: Some(STUDY_START_APEX_M),
        duration_s: Some(STUDY_DURATION_S),
        // The DAC's full scale (2047 codes) a little beyond the stall current.
        firmware_params: Some(vec![(
            &hopper_control::params::CAL_DAC_AMPS,
            (motor.stall_current_a() / 2000.0) as f32,
        )]),
        ..Overrides::default()
    };
    let settings = Settings::resolve(None, &cli);
    settings.check()?;
    let cfg = settings.run_config(1.0 / settings.control_hz);
    let spec: ControllerSpec = settings.controller_spec()?;
    let mut ctl = spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s)?;
    let r = run::run(&cfg, &settings.params_name, &mut ctl)?;
    let s = &r.summary;
    let work = s
        .first_stance_motor_work_j
        .ok_or_else(|| format!("{}: no complete first stance", settings.params_name))?;
    let first_apex = s.apex_heights_m.first().copied().unwrap_or(f64::NAN);
    let (t_td, t_lo) = first_stance_times(&r.events)
        .ok_or_else(|| format!("{}: no complete first stance", settings.params_name))?;
    let rr = params.screw_m_per_rad();
    let mut points = Vec::new();
    let mut work_so_far = 0.0;
    let mut last: Option<&Sample> = None;
    for smp in r.samples.iter().filter(|x| x.t_s >= t_td && x.t_s <= t_lo) {
        let omega = smp.pd_mps / rr;
        if let Some(l) = last {
            let p0 = l.torque_nm * l.pd_mps / rr;
            let p1 = smp.torque_nm * omega;
            // What reaches the nut, `eta tau omega`: the ledger's motor work.
            work_so_far += params.efficiency * 0.5 * (p0 + p1) * (smp.t_s - l.t_s);
        }
        points.push((smp.t_s - t_td, omega, smp.torque_nm, work_so_far));
        last = Some(smp);
    }
    let m_total = params.body_mass_kg + params.nut_mass_kg + params.unsprung_mass_kg;
    Ok(FirstStance {
        lead_m,
        motor: motor.thesis_name,
        motor_work_j: work,
        first_apex_m: first_apex,
        hop_energy_gain_j: m_total * params.gravity_mps2 * (first_apex - STUDY_START_APEX_M),
        stance_s: t_lo - t_td,
        peak_speed_rad_s: points.iter().map(|p| p.1.abs()).fold(0.0, f64::max),
        peak_torque_nm: points.iter().map(|p| p.2.abs()).fold(0.0, f64::max),
        points,
    })
}

/// The first touchdown's and the first liftoff's times, s.
fn first_stance_times(events: &[crate::Event]) -> Option<(f64, f64)> {
    let td = events.iter().find_map(|e| match *e {
        crate::Event::Touchdown { t_s, .. } => Some(t_s),
        _ => None,
    })?;
    let lo = events.iter().find_map(|e| match *e {
        crate::Event::Liftoff { t_s, .. } if t_s > td => Some(t_s),
        _ => None,
    })?;
    Some((td, lo))
}

/// The lead study's leads (Figures 3.1-3.3: 2, 5 and 10 mm) and the points
/// between, m.
pub const STUDY_LEADS_M: [f64; 9] = [
    0.002, 0.003, 0.004, 0.005, 0.006, 0.007, 0.008, 0.009, 0.010,
];

/// The lead study's figure (Figures 3.1-3.3 side by side): the motor's
/// work in the first stance and the first apex against the lead, the work
/// through the stance and the torque-speed operating points (with the
/// motor's line) for 2, 5 and 10 mm; written as `lead-study.png` and
/// `lead-study.svg` into `dir`, whole or not at all.
pub fn write_lead_plot(
    motor: &Motor,
    study: &[FirstStance],
    dir: &std::path::Path,
) -> Result<Vec<std::path::PathBuf>, String> {
    use plotters::prelude::*;
    crate::plot::ensure_font()?;
    const SIZE: (u32, u32) = (1200, 900);
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, plotters::coord::Shift>,
        motor: &Motor,
        study: &[FirstStance],
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let root = root.titled(
            &format!(
                "Ball-screw lead study on the torque-speed curve ({}, k = 10 kN/m, dropped from 0.15 m)",
                motor.thesis_name
            ),
            ("sans-serif", 20),
        )?;
        let panels = root.split_evenly((2, 2));
        let mm = |x: f64| x * 1e3;
        let leads: Vec<f64> = study.iter().map(|x| mm(x.lead_m)).collect();
        let (l_lo, l_hi) = (
            leads.iter().copied().fold(f64::INFINITY, f64::min) - 0.5,
            leads.iter().copied().fold(0.0, f64::max) + 0.5,
        );
        let style = |c: &mut ChartBuilder<'_, '_, DB>| {
            c.margin(12).x_label_area_size(40).y_label_area_size(60);
        };
        // (a) work against the lead.
        let w_hi = study.iter().map(|x| x.motor_work_j).fold(0.0, f64::max) * 1.1;
        let mut b = ChartBuilder::on(&panels[0]);
        style(&mut b);
        let mut c = b
            .caption("energy added in the first stance", ("sans-serif", 16))
            .build_cartesian_2d(l_lo..l_hi, 0.0..w_hi)?;
        c.configure_mesh()
            .x_desc("lead [mm]")
            .y_desc("motor work [J]")
            .draw()?;
        c.draw_series(LineSeries::new(
            study.iter().map(|x| (mm(x.lead_m), x.motor_work_j)),
            BLUE.stroke_width(2),
        ))?;
        c.draw_series(
            study
                .iter()
                .map(|x| Circle::new((mm(x.lead_m), x.motor_work_j), 4, BLUE.filled())),
        )?;
        // (b) the first apex against the lead.
        let a_lo = study
            .iter()
            .map(|x| x.first_apex_m)
            .fold(f64::INFINITY, f64::min)
            * 0.95;
        let a_hi = study.iter().map(|x| x.first_apex_m).fold(0.0, f64::max) * 1.05;
        let mut b = ChartBuilder::on(&panels[1]);
        style(&mut b);
        let mut c = b
            .caption("first apex after it (from 0.15 m)", ("sans-serif", 16))
            .build_cartesian_2d(l_lo..l_hi, a_lo..a_hi)?;
        c.configure_mesh()
            .x_desc("lead [mm]")
            .y_desc("apex [m]")
            .draw()?;
        c.draw_series(LineSeries::new(
            study.iter().map(|x| (mm(x.lead_m), x.first_apex_m)),
            RED.stroke_width(2),
        ))?;
        c.draw_series(
            study
                .iter()
                .map(|x| Circle::new((mm(x.lead_m), x.first_apex_m), 4, RED.filled())),
        )?;
        let shown: Vec<&FirstStance> = study
            .iter()
            .filter(|x| {
                [2.0, 5.0, 10.0]
                    .iter()
                    .any(|l| (mm(x.lead_m) - l).abs() < 1e-6)
            })
            .collect();
        let colors = [BLUE, GREEN, RED];
        // (c) work through the stance.
        let t_hi = shown.iter().map(|x| x.stance_s).fold(0.0, f64::max) * 1000.0 * 1.05;
        let mut b = ChartBuilder::on(&panels[2]);
        style(&mut b);
        let mut c = b
            .caption("through the stance", ("sans-serif", 16))
            .build_cartesian_2d(0.0..t_hi, 0.0..w_hi)?;
        c.configure_mesh()
            .x_desc("time since touchdown [ms]")
            .y_desc("motor work [J]")
            .draw()?;
        for (x, col) in shown.iter().zip(colors) {
            c.draw_series(LineSeries::new(
                x.points.iter().map(|p| (p.0 * 1000.0, p.3)),
                col.stroke_width(2),
            ))?
            .label(format!("{} mm", mm(x.lead_m)))
            .legend(move |(a, b)| PathElement::new(vec![(a, b), (a + 20, b)], col.stroke_width(2)));
        }
        crate::plot::legend(&mut c, SeriesLabelPosition::LowerRight)?;
        // (d) torque-speed points and the motor's line.
        let w0 = motor.no_load_speed_rad_s();
        let t0 = motor.stall_torque_nm();
        let mut b = ChartBuilder::on(&panels[3]);
        style(&mut b);
        let mut c = b
            .caption(
                "torque-speed operating points in the stance",
                ("sans-serif", 16),
            )
            .build_cartesian_2d(0.0..w0 * 1.05, 0.0..t0 * 1.1)?;
        c.configure_mesh()
            .x_desc("motor speed [rad/s]")
            .y_desc("motor torque [N m]")
            .draw()?;
        c.draw_series(LineSeries::new(
            [(0.0, t0), (w0, 0.0)],
            BLACK.stroke_width(1),
        ))?
        .label("the motor's limit")
        .legend(|(a, b)| PathElement::new(vec![(a, b), (a + 20, b)], BLACK));
        for (x, col) in shown.iter().zip(colors) {
            c.draw_series(
                x.points
                    .iter()
                    .step_by(10)
                    .map(|p| Circle::new((p.1.abs(), p.2.abs()), 2, col.filled())),
            )?
            .label(format!("{} mm", mm(x.lead_m)))
            .legend(move |(a, b)| Circle::new((a + 10, b), 3, col.filled()));
        }
        crate::plot::legend(&mut c, SeriesLabelPosition::UpperRight)?;
        root.present()?;
        Ok(())
    }
    crate::out_dir::write_whole(dir, |staging| {
        crate::plot::png_and_svg(
            staging,
            "lead-study",
            SIZE,
            "the lead study",
            |a| draw(a, motor, study),
            |a| draw(a, motor, study),
        )
    })
}

/// Which controller holds the hop: the project's best (shaped, target
/// 0.05 m) or the thesis's law of section 4.6 (open-loop torque at the
/// torque limit, stance only, eq 4.13's flight PD).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Holder {
    /// `shaped` at a 0.05 m target.
    Shaped,
    /// `open-torque` commanding the torque limit.
    OpenTorque,
}

impl Holder {
    /// Both, in the order they are reported.
    pub const ALL: [Holder; 2] = [Holder::Shaped, Holder::OpenTorque];

    /// The controller's command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Holder::Shaped => "shaped",
            Holder::OpenTorque => "open-torque",
        }
    }
}

/// The hop to hold, m (toe apex), and how long the run lasts, s.
pub const HOLD_APEX_M: f64 = 0.05;
const HOLD_DURATION_S: f64 = 15.0;

/// The steady apex of `holder` on `params` released from 0.05 m, 15 s
/// (None: it never becomes steady; the torque limit is `current_limit_a`
/// with the DAC's scale set to reach it). `protect`: the firmware's motor
/// thermal protection on, as on a robot; off (`thermal.protect = 0`), the
/// mechanics alone.
pub fn steady_apex(params: &Params, holder: Holder, protect: bool) -> Result<Option<f64>, String> {
    let (controller, torque) = match holder {
        Holder::Shaped => (ControllerKind::Shaped, None),
        Holder::OpenTorque => (
            ControllerKind::OpenTorque,
            Some(params.torque_constant_nm_per_a * params.current_limit_a),
        ),
    };
    let cli = Overrides {
        plant: Some(PlantSet {
            params: *params,
            name: "candidate".into(),
            preset: None,
        }),
        controller: Some(controller),
        torque_nm: torque,
        target_apex_m: Some(HOLD_APEX_M),
        start_apex_m: Some(HOLD_APEX_M),
        duration_s: Some(HOLD_DURATION_S),
        firmware_params: Some(vec![
            (
                &hopper_control::params::CAL_DAC_AMPS,
                (params.current_limit_a.max(40.0) / 2000.0) as f32,
            ),
            (
                &hopper_control::params::THERMAL_PROTECT,
                if protect { 1.0 } else { 0.0 },
            ),
        ]),
        ..Overrides::default()
    };
    let s = Settings::resolve(None, &cli);
    s.check()?;
    let cfg = s.run_config(0.0);
    let mut ctl = s
        .controller_spec()?
        .build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s)?;
    Ok(run::run(&cfg, "candidate", &mut ctl)?.summary.steady_apex_m)
}

/// Whether a steady apex holds the 5 cm hop: within 2% of it for shaped
/// (its target), at or above 98% of it for open-loop torque (no target).
pub fn holds(apex: Option<f64>, holder: Holder) -> bool {
    match (apex, holder) {
        (Some(a), Holder::Shaped) => (a - HOLD_APEX_M).abs() <= 0.02 * HOLD_APEX_M,
        (Some(a), Holder::OpenTorque) => a >= 0.98 * HOLD_APEX_M,
        (None, _) => false,
    }
}

/// One design parameter changed alone from the identified machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Change {
    /// Both frictions scaled together (the thesis's "friction fix").
    Friction,
    /// The stance torque limit (the amplifier's current limit).
    TorqueLimit,
    /// The ball-screw lead.
    Lead,
    /// The spring rate.
    SpringRate,
    /// The spring preload.
    Preload,
}

impl Change {
    /// Every change, in the order reported.
    pub const ALL: [Change; 5] = [
        Change::Friction,
        Change::TorqueLimit,
        Change::Lead,
        Change::SpringRate,
        Change::Preload,
    ];

    /// Name and unit.
    pub fn label(self) -> (&'static str, &'static str) {
        match self {
            Change::Friction => ("friction (both, scaled)", "x"),
            Change::TorqueLimit => ("stance torque limit", "N m"),
            Change::Lead => ("screw lead", "mm"),
            Change::SpringRate => ("spring rate", "kN/m"),
            Change::Preload => ("spring preload", "mm"),
        }
    }

    /// The identified machine's value, in the label's unit.
    pub fn identified(self) -> f64 {
        let p = Params::identified();
        match self {
            Change::Friction => 1.0,
            Change::TorqueLimit => p.torque_constant_nm_per_a * p.current_limit_a,
            Change::Lead => p.screw_lead_m * 1e3,
            Change::SpringRate => p.spring_stiffness_n_per_m * 1e-3,
            Change::Preload => p.spring_preload_m * 1e3,
        }
    }

    /// The values tried, nearest the identified first.
    pub fn candidates(self) -> Vec<f64> {
        let mut v: Vec<f64> = match self {
            Change::Friction => (1..20).map(|i| 1.0 - 0.05 * f64::from(i)).collect(),
            Change::TorqueLimit => (1..=44)
                .map(|i| 0.62 * (1.0 + 0.05 * f64::from(i)))
                .collect(),
            Change::Lead => (4..=20)
                .map(|i| 0.5 * f64::from(i))
                .filter(|l| (l - 5.0).abs() > 1e-9)
                .collect(),
            Change::SpringRate => (-10..=20)
                .filter(|&i| i != 0)
                .map(|i| 11.0 * (1.0 + 0.05 * f64::from(i)))
                .collect(),
            Change::Preload => (1..=40).map(|i| 0.5 * f64::from(i)).collect(),
        };
        let id = self.identified();
        v.sort_by(|a, b| {
            ((a - id) / id.max(1.0))
                .abs()
                .total_cmp(&((b - id) / id.max(1.0)).abs())
        });
        v
    }

    /// The identified machine with this parameter at `value` (label's unit).
    pub fn apply(self, value: f64) -> Params {
        let mut p = Params::identified();
        match self {
            Change::Friction => {
                p.planarizer_friction_n *= value;
                p.leg_friction_n *= value;
            }
            Change::TorqueLimit => p.current_limit_a = value / p.torque_constant_nm_per_a,
            Change::Lead => p.screw_lead_m = value * 1e-3,
            Change::SpringRate => p.spring_stiffness_n_per_m = value * 1e3,
            Change::Preload => p.spring_preload_m = value * 1e-3,
        }
        p
    }
}

/// The smallest single change that holds the hop: the first candidate (in
/// the order of [`Change::candidates`]) whose run holds it, with its
/// steady apex; None when none of them does.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Smallest {
    /// What changed.
    pub change: Change,
    /// Which controller.
    pub holder: Holder,
    /// The motor's thermal protection on.
    pub thermal_protection: bool,
    /// The identified value and the one that holds (label's unit).
    pub identified: f64,
    /// The smallest change that holds, None if no candidate does.
    pub holds_at: Option<f64>,
    /// Its steady apex, m.
    pub apex_m: Option<f64>,
    /// Candidates run.
    pub tried: usize,
}

/// [`Smallest`] for every change and both controllers (in parallel).
pub fn smallest_changes(protect: bool) -> Result<Vec<Smallest>, String> {
    use rayon::prelude::*;
    let jobs: Vec<(Change, Holder, f64)> = Change::ALL
        .iter()
        .flat_map(|&c| {
            Holder::ALL
                .iter()
                .flat_map(move |&h| c.candidates().into_iter().map(move |v| (c, h, v)))
        })
        .collect();
    let results: Vec<Option<f64>> = jobs
        .par_iter()
        .map(|&(c, h, v)| steady_apex(&c.apply(v), h, protect))
        .collect::<Result<Vec<_>, String>>()?;
    let mut out = Vec::new();
    for c in Change::ALL {
        for h in Holder::ALL {
            let mine: Vec<(f64, Option<f64>)> = jobs
                .iter()
                .zip(&results)
                .filter(|((jc, jh, _), _)| *jc == c && *jh == h)
                .map(|((_, _, v), a)| (*v, *a))
                .collect();
            let first = mine.iter().find(|(_, a)| holds(*a, h));
            out.push(Smallest {
                change: c,
                holder: h,
                thermal_protection: protect,
                identified: c.identified(),
                holds_at: first.map(|f| f.0),
                apex_m: first.and_then(|f| f.1),
                tried: mine.len(),
            });
        }
    }
    Ok(out)
}

/// The feasibility map: steady apex over friction scale x torque limit for
/// `holder` (rows: friction scales, columns: torque limits).
pub struct FeasibilityMap {
    /// Friction scales (1 = identified).
    pub friction: Vec<f64>,
    /// Torque limits, N m.
    pub torque_nm: Vec<f64>,
    /// Steady apex per cell, m (None: never steady).
    pub apex: Vec<Vec<Option<f64>>>,
    /// Which controller.
    pub holder: Holder,
    /// The motor's thermal protection on.
    pub thermal_protection: bool,
}

/// The map for `holder`: friction 0.1..1.0 (10) x torque 0.5..1.5 N m (11).
pub fn feasibility_map(holder: Holder, protect: bool) -> Result<FeasibilityMap, String> {
    use rayon::prelude::*;
    let friction: Vec<f64> = (1..=10).map(|i| 0.1 * f64::from(i)).collect();
    let torque_nm: Vec<f64> = (0..=10).map(|i| 0.5 + 0.1 * f64::from(i)).collect();
    let cells: Vec<(f64, f64)> = friction
        .iter()
        .flat_map(|&f| torque_nm.iter().map(move |&t| (f, t)))
        .collect();
    let apex: Vec<Option<f64>> = cells
        .par_iter()
        .map(|&(f, t)| {
            let mut p = Change::Friction.apply(f);
            p.current_limit_a = t / p.torque_constant_nm_per_a;
            steady_apex(&p, holder, protect)
        })
        .collect::<Result<Vec<_>, String>>()?;
    let apex = apex
        .chunks(torque_nm.len())
        .map(<[Option<f64>]>::to_vec)
        .collect();
    Ok(FeasibilityMap {
        friction,
        torque_nm,
        apex,
        holder,
        thermal_protection: protect,
    })
}

/// Width of the feasibility map's right column (colour bar, legend), px.
const FEASIBILITY_SIDE_PX: u32 = 220;

/// The maps side by side as `feasibility.png` and `.svg` in `dir`: steady
/// apex as colour (grey: never steady), cells that hold 5 cm outlined, the
/// identified machine marked; the colour bar and the legend in a column
/// right of the maps, clear of the data.
pub fn write_feasibility_plot(
    maps: &[FeasibilityMap],
    dir: &std::path::Path,
) -> Result<Vec<std::path::PathBuf>, String> {
    use plotters::prelude::*;
    crate::plot::ensure_font()?;
    const SIZE: (u32, u32) = (1300 + FEASIBILITY_SIDE_PX, 1150);
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, plotters::coord::Shift>,
        maps: &[FeasibilityMap],
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let root = root.titled(
            "The identified machine: steady apex over friction and stance torque",
            ("sans-serif", 18),
        )?;
        let (maps_area, side) = root.split_horizontally(SIZE.0 - FEASIBILITY_SIDE_PX);
        let panels = maps_area.split_evenly((maps.len().div_ceil(2).max(1), 2));
        // The colour scale's top: the highest apex, at least a bit above
        // the 5 cm the map asks about.
        let hi = maps
            .iter()
            .flat_map(|m| m.apex.iter().flatten().flatten())
            .copied()
            .fold(0.0, f64::max)
            .max(0.06);
        feasibility_key(&side, hi)?;
        for (m, panel) in maps.iter().zip(panels.iter()) {
            let (df, dt) = (0.05, 0.05);
            let mut c = ChartBuilder::on(panel)
                .caption(
                    format!(
                        "{}, {}",
                        m.holder.name(),
                        if m.thermal_protection {
                            "thermal protection on (as on the robot)"
                        } else {
                            "mechanics only (thermal.protect = 0)"
                        }
                    ),
                    ("sans-serif", 16),
                )
                .margin(16)
                .x_label_area_size(44)
                .y_label_area_size(56)
                .build_cartesian_2d(0.45..1.55, 0.05..1.05)?;
            c.configure_mesh()
                .x_desc("stance torque limit [N m]")
                .y_desc("friction (x identified: 13 N + 15 N)")
                .disable_mesh()
                .draw()?;
            for (fi, f) in m.friction.iter().enumerate() {
                for (ti, t) in m.torque_nm.iter().enumerate() {
                    let a = m.apex.get(fi).and_then(|r| r.get(ti)).copied().flatten();
                    let col = match a {
                        Some(a) => crate::plot::viridis(a / hi),
                        None => RGBColor(200, 200, 200),
                    };
                    let rect = [(t - dt, f - df), (t + dt, f + df)];
                    c.draw_series(std::iter::once(Rectangle::new(rect, col.filled())))?;
                    if holds(a, m.holder) {
                        c.draw_series(std::iter::once(Rectangle::new(
                            rect,
                            BLACK.stroke_width(2),
                        )))?;
                    }
                }
            }
            c.draw_series(std::iter::once(Cross::new(
                (0.62, 1.0),
                8,
                RED.stroke_width(3),
            )))?;
        }
        root.present()?;
        Ok(())
    }
    /// The colour bar (steady apex, 0 to `hi` m, shown in cm) and the
    /// legend of the maps' marks, in the column right of the maps.
    fn feasibility_key<DB: DrawingBackend>(
        side: &DrawingArea<DB, plotters::coord::Shift>,
        hi: f64,
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        let (bar, key) = side.split_vertically(560);
        let hi_cm = hi * 100.0;
        let mut scale = ChartBuilder::on(&bar)
            .margin_top(60)
            .margin_bottom(10)
            .margin_left(10)
            .margin_right(90)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..1.0, 0.0..hi_cm)?;
        scale
            .configure_mesh()
            .disable_x_axis()
            .disable_mesh()
            .y_desc("steady apex [cm]")
            .y_label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 15))
            .draw()?;
        crate::plot::colour_strip(&mut scale, 0.0, hi_cm)?;
        let style = ("sans-serif", 14).into_font().color(&BLACK);
        /// What a legend entry shows left of its label.
        enum Key {
            Grey,
            Outlined,
            Cross,
        }
        let entries = [
            (Key::Grey, "never steady"),
            (Key::Outlined, "holds 5 cm"),
            (Key::Cross, "as identified"),
        ];
        let mut y = 20;
        for (k, label) in entries {
            let (cx, cy) = (24, y + 8);
            let cell = [(cx - 9, cy - 9), (cx + 9, cy + 9)];
            match k {
                Key::Grey => key.draw(&Rectangle::new(cell, RGBColor(200, 200, 200).filled()))?,
                Key::Outlined => {
                    key.draw(&Rectangle::new(cell, crate::plot::viridis(0.3).filled()))?;
                    key.draw(&Rectangle::new(cell, BLACK.stroke_width(2)))?;
                }
                Key::Cross => key.draw(&Cross::new((cx, cy), 8, RED.stroke_width(3)))?,
            }
            key.draw(&Text::new(label, (cx + 20, y), style.clone()))?;
            y += 30;
        }
        key.draw(&Rectangle::new(
            [(6, 6), (FEASIBILITY_SIDE_PX as i32 - 16, y)],
            BLACK.stroke_width(1),
        ))?;
        Ok(())
    }
    crate::out_dir::write_whole(dir, |staging| {
        crate::plot::png_and_svg(
            staging,
            "feasibility",
            SIZE,
            "the feasibility map",
            |a| draw(a, maps),
            |a| draw(a, maps),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The feasibility plot has a colour bar with its quantity and unit,
    /// and its legend, beside the maps.
    #[test]
    fn the_feasibility_plot_has_a_colour_bar_and_a_legend() {
        use plotters::prelude::*;
        let map = |protect| FeasibilityMap {
            friction: vec![0.1, 0.2],
            torque_nm: vec![0.5, 0.6],
            apex: vec![vec![Some(0.08), None], vec![Some(0.02), None]],
            holder: Holder::Shaped,
            thermal_protection: protect,
        };
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let out = dir.path().join("f");
        write_feasibility_plot(&[map(true), map(false)], &out).unwrap_or_else(|e| panic!("{e}"));
        let svg = std::fs::read_to_string(out.join("feasibility.svg")).unwrap_or_default();
        for text in [
            "steady apex [cm]",
            "never steady",
            "holds 5 cm",
            "as identified",
        ] {
            assert!(svg.contains(text), "no `{text}`");
        }
        // The bar's ends: viridis from 0 to the highest apex.
        let fill = |c: RGBColor| format!("fill=\"#{:02X}{:02X}{:02X}\"", c.0, c.1, c.2);
        assert!(svg.contains(&fill(ViridisRGB::get_color(0.0))));
        assert!(svg.contains(&fill(ViridisRGB::get_color(0.99))));
        assert!(out.join("feasibility.png").exists());
    }

    /// The design motor on its curve through 2, 5 and 10 mm leads: the
    /// motor's work falls with the lead (a small lead spins the rotor:
    /// 2700 kg reflected at 2 mm) while the first apex rises.
    #[test]
    fn the_lead_study_on_the_torque_speed_curve() {
        let s: Vec<FirstStance> = [0.002, 0.005, 0.010]
            .iter()
            .map(|&l| first_stance(&DESIGN_MOTOR, l).unwrap_or_else(|e| panic!("{e}")))
            .collect();
        for x in &s {
            eprintln!(
                "{} mm: {:.2} J, apex {:.4} m, stance {:.3} s, {:.0} rad/s, {:.2} N m",
                x.lead_m * 1e3,
                x.motor_work_j,
                x.first_apex_m,
                x.stance_s,
                x.peak_speed_rad_s,
                x.peak_torque_nm
            );
        }
        let near = |x: f64, want: f64| (x / want - 1.0).abs() < 0.02;
        assert!(near(s[0].motor_work_j, 28.31), "{:?}", s[0].motor_work_j);
        assert!(near(s[1].motor_work_j, 25.67), "{:?}", s[1].motor_work_j);
        assert!(near(s[2].motor_work_j, 21.05), "{:?}", s[2].motor_work_j);
        assert!(s[0].first_apex_m < s[1].first_apex_m && s[1].first_apex_m < s[2].first_apex_m);
        // The trapezoid of the points agrees with the ledger.
        for x in &s {
            let w = x.points.last().map_or(0.0, |p| p.3);
            assert!(
                (w - x.motor_work_j).abs() < 0.01 * x.motor_work_j,
                "{w} vs {}",
                x.motor_work_j
            );
            // On or under the motor's line.
            let m = DESIGN_MOTOR;
            for &(_, om, tau, _) in &x.points {
                let line = m.stall_torque_nm() * (1.0 - om.abs() / m.no_load_speed_rad_s());
                assert!(
                    tau.abs() <= line + 1e-6,
                    "{om} rad/s {tau} N m above {line}"
                );
            }
        }
    }
}

/// A tiny check of the motor tables, on the figures docs/design.md quotes.
#[cfg(test)]
mod motor_tests {
    use super::*;

    #[test]
    fn table_3_1_on_each_stall_torque() {
        let t = table_3_1();
        let e: Vec<f64> = t
            .iter()
            .map(|m| {
                first_stance(m, 0.005)
                    .unwrap_or_else(|e| panic!("{e}"))
                    .motor_work_j
            })
            .collect();
        for (m, e) in t.iter().zip(&e) {
            eprintln!(
                "{}: stall {:.3} N m: {e:.2} J (thesis {} J)",
                m.thesis_name,
                m.stall_torque_nm(),
                m.thesis_energy_j
            );
        }
        for m in CATALOGUE {
            let f = first_stance(&m, 0.005).unwrap_or_else(|e| panic!("{e}"));
            eprintln!(
                "{}: stall {:.3} N m: {:.2} J",
                m.model,
                m.stall_torque_nm(),
                f.motor_work_j
            );
        }
        // The stall torque is what orders them, as in the thesis: the two
        // small ones add an order of magnitude less.
        assert!(e[0] < e[1] && e[1] < 0.2 * e[2]);
        assert!((e[2] - e[3]).abs() < 1e-9);
    }
}

/// The machine that would hop, on the figures docs/design.md quotes.
#[cfg(test)]
mod would_hop_tests {
    use super::*;

    fn apex(c: Change, v: f64, h: Holder, protect: bool) -> Option<f64> {
        steady_apex(&c.apply(v), h, protect).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn friction_at_40_percent_holds_5_cm_and_torque_alone_only_without_thermal_protection() {
        // As identified: no hop.
        assert!(!holds(
            apex(Change::Friction, 1.0, Holder::Shaped, true),
            Holder::Shaped
        ));
        // The friction at 40% (shaped) and 20% (open-loop torque): 5 cm.
        assert!(holds(
            apex(Change::Friction, 0.4, Holder::Shaped, true),
            Holder::Shaped
        ));
        assert!(!holds(
            apex(Change::Friction, 0.45, Holder::Shaped, true),
            Holder::Shaped
        ));
        assert!(holds(
            apex(Change::Friction, 0.2, Holder::OpenTorque, true),
            Holder::OpenTorque
        ));
        // 1.71 N m of open-loop torque holds it mechanically, but the
        // motor's thermal protection stops it.
        assert!(holds(
            apex(Change::TorqueLimit, 1.705, Holder::OpenTorque, false),
            Holder::OpenTorque
        ));
        assert!(!holds(
            apex(Change::TorqueLimit, 1.705, Holder::OpenTorque, true),
            Holder::OpenTorque
        ));
    }
}
