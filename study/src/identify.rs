//! Identification from logs (thesis section 4.5): the plant parameters
//! that make the simulation reproduce a recorded hop.
//!
//! The thesis identified its machine in two steps "by some trials": the
//! planarizer and leg friction from a passive hop (section 4.5.1), then,
//! with those, the effective stance torque and the nut mass from an
//! open-loop torque hop (section 4.5.2). Here each step is a least-squares
//! fit of the simulated toe height to the recorded one, minimised by
//! argmin's Nelder-Mead simplex; every evaluation is a `hopper-sim run` of
//! the same experiment (the firmware's law in the loop) with the candidate
//! parameters, in the plant and in what the firmware believes (as in a
//! `hopper-sim run` without `--model-params`: the firmware's own current
//! limit caps its command, so the effective torque must be the
//! candidate's in both).
//!
//! A log is a directory holding `trajectory.csv` (`hopper-sim run --out`:
//! `time_s`, `toe_height_m`) or `telemetry.csv` (`hopper-link record`:
//! `t_s`, `toe_height_m`), starting at the release from rest (a drop, or
//! the hoist letting go when armed): its first toe height is the start
//! apex. The uncertainty is one standard deviation from the fit's Jacobian
//! with the residuals taken as independent: a lower bound, since samples a
//! millisecond apart are not.

use crate::params_toml::PlantSet;
use crate::run;
use crate::scenario::{Overrides, Settings};
use crate::Params;
use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;
use hopper_control::laws::ControllerKind;
use serde::Serialize;
use std::path::Path;

/// A recorded toe-height trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct Log {
    /// Sample times from the first, s.
    pub t_s: Vec<f64>,
    /// Toe height above the ground, m.
    pub toe_m: Vec<f64>,
    /// Which file it came from.
    pub file: String,
}

/// Reads `dir`'s `trajectory.csv` or `telemetry.csv`.
pub fn read_log(dir: &Path) -> Result<Log, String> {
    let (path, time_col) = [("trajectory.csv", "time_s"), ("telemetry.csv", "t_s")]
        .iter()
        .map(|(f, c)| (dir.join(f), *c))
        .find(|(p, _)| p.is_file())
        .ok_or_else(|| {
            format!(
                "{}: no trajectory.csv (hopper-sim run --out) or telemetry.csv (hopper-link record)",
                dir.display()
            )
        })?;
    let shown = path.display().to_string();
    let mut r = csv::Reader::from_path(&path).map_err(|e| format!("{shown}: {e}"))?;
    let headers = r.headers().map_err(|e| format!("{shown}: {e}"))?.clone();
    let col = |name: &str| {
        headers
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| format!("{shown}: no `{name}` column"))
    };
    let (ti, zi) = (col(time_col)?, col("toe_height_m")?);
    // hopper-link's toe height is the body height less the leg length: it
    // goes negative by the spring's compression in stance, where the
    // plant's is 0 (the toe on the ground).
    let ground_clamp = time_col == "t_s";
    let (mut t_s, mut toe_m) = (Vec::new(), Vec::new());
    for (i, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| format!("{shown} row {}: {e}", i + 1))?;
        let num = |k: usize| -> Result<f64, String> {
            let s = rec.get(k).unwrap_or("");
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("{shown} row {}: `{s}` is not a number", i + 1))
        };
        t_s.push(num(ti)?);
        let z = num(zi)?;
        toe_m.push(if ground_clamp { z.max(0.0) } else { z });
    }
    if t_s.len() < 100 {
        return Err(format!(
            "{shown}: {} samples; a hop needs 100 at least",
            t_s.len()
        ));
    }
    let t0 = t_s.first().copied().unwrap_or(0.0);
    if t_s.windows(2).any(|w| w[1] <= w[0]) {
        return Err(format!("{shown}: the times do not increase"));
    }
    for t in &mut t_s {
        *t -= t0;
    }
    Ok(Log {
        t_s,
        toe_m,
        file: shown,
    })
}

/// What was done in the recorded hop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Experiment {
    /// Motor off: fits `planarizer_friction_n` and `leg_friction_n`.
    Passive,
    /// The open-loop torque law commanding `torque_nm`: fits the effective
    /// stance torque (as `current_limit_a`, the parameter file's field)
    /// and `nut_mass_kg`.
    OpenTorque {
        /// The torque commanded, N m.
        torque_nm: f64,
    },
}

/// One identified parameter.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Estimate {
    /// The parameter file's field name.
    pub field: &'static str,
    /// Its value, in the field's unit.
    pub value: f64,
    /// One standard deviation (module docs).
    pub std: f64,
    /// Where the fit started (the base parameters' value).
    pub start: f64,
}

/// The fit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Identified {
    /// The estimates.
    pub estimates: Vec<Estimate>,
    /// The effective stance torque `k_t * current_limit_a`, N m (actuated
    /// fits only).
    pub stance_torque_nm: Option<f64>,
    /// RMS of the toe-height residual at the optimum, m.
    pub rms_residual_m: f64,
    /// Samples fitted.
    pub samples: usize,
    /// Simulations run.
    pub simulations: usize,
    /// The fitted trajectory at the log's times, m.
    #[serde(skip)]
    pub fitted_m: Vec<f64>,
}

/// The fields each experiment fits.
fn fields(e: Experiment) -> [&'static str; 2] {
    match e {
        Experiment::Passive => ["planarizer_friction_n", "leg_friction_n"],
        Experiment::OpenTorque { .. } => ["current_limit_a", "nut_mass_kg"],
    }
}

fn with(base: &Params, e: Experiment, x: &[f64]) -> Params {
    let mut p = *base;
    match (e, x) {
        (Experiment::Passive, [a, b]) => {
            p.planarizer_friction_n = *a;
            p.leg_friction_n = *b;
        }
        (Experiment::OpenTorque { .. }, [a, b]) => {
            p.current_limit_a = *a;
            p.nut_mass_kg = *b;
        }
        _ => {}
    }
    p
}

fn start_of(base: &Params, e: Experiment) -> [f64; 2] {
    match e {
        Experiment::Passive => [base.planarizer_friction_n, base.leg_friction_n],
        // A current limit at or above the command's current changes
        // nothing (the law asks for less): the fit starts where it binds,
        // at most 80% of the command.
        Experiment::OpenTorque { torque_nm } => [
            base.current_limit_a
                .min(0.8 * torque_nm / base.torque_constant_nm_per_a),
            base.nut_mass_kg,
        ],
    }
}

/// The cost: the experiment simulated with candidate parameters against
/// the log.
#[derive(Clone, Copy)]
struct Fit<'a> {
    base: Params,
    experiment: Experiment,
    log: &'a Log,
    runs: &'a std::cell::Cell<usize>,
}

impl Fit<'_> {
    /// The simulated toe height at the log's times (an error: the candidate
    /// is out of the parameters' ranges or the run failed).
    fn simulate(&self, x: &[f64]) -> Result<Vec<f64>, String> {
        self.runs.set(self.runs.get() + 1);
        let params = with(&self.base, self.experiment, x);
        params.validate().map_err(|e| e.to_string())?;
        let (controller, torque) = match self.experiment {
            Experiment::Passive => (ControllerKind::Passive, None),
            Experiment::OpenTorque { torque_nm } => (ControllerKind::OpenTorque, Some(torque_nm)),
        };
        let duration = self.log.t_s.last().copied().unwrap_or(0.0) + 0.002;
        let cli = Overrides {
            plant: Some(PlantSet {
                params,
                name: "candidate".into(),
                preset: None,
            }),
            // The firmware believes the candidate, as `hopper-sim run`'s
            // does the plant it runs on: its own current limit caps the
            // command, so the effective torque is the candidate's in both.
            model: None,
            controller: Some(controller),
            torque_nm: torque,
            noise: Some(false),
            start_apex_m: self.log.toe_m.first().copied(),
            duration_s: Some(duration),
            ..Overrides::default()
        };
        let s = Settings::resolve(None, &cli);
        s.check()?;
        let cfg = s.run_config(1.0 / s.control_hz);
        let mut ctl = s
            .controller_spec()
            .and_then(|spec| spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s))?;
        let r = run::run(&cfg, "candidate", &mut ctl)?;
        // Linear interpolation of the samples (one a control period) at
        // the log's times.
        let samples = &r.samples;
        let mut k = 0;
        let mut out = Vec::with_capacity(self.log.t_s.len());
        for &t in &self.log.t_s {
            while k + 1 < samples.len() && samples[k + 1].t_s < t {
                k += 1;
            }
            let a = samples.get(k).ok_or("the run recorded no samples")?;
            let b = samples.get(k + 1).unwrap_or(a);
            let w = if b.t_s > a.t_s {
                ((t - a.t_s) / (b.t_s - a.t_s)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            out.push(a.toe_height_m + w * (b.toe_height_m - a.toe_height_m));
        }
        Ok(out)
    }

    fn unscale(&self, u: &[f64]) -> Vec<f64> {
        let x0 = start_of(&self.base, self.experiment);
        u.iter().zip(x0).map(|(u, x)| u * x).collect()
    }

    fn residuals(&self, x: &[f64]) -> Result<Vec<f64>, String> {
        let sim = self.simulate(x)?;
        Ok(sim
            .iter()
            .zip(&self.log.toe_m)
            .map(|(s, m)| s - m)
            .collect())
    }
}

impl CostFunction for Fit<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    /// The mean square residual in mm^2, of the parameters as multiples of
    /// where the fit started (both near 1: the simplex moves them alike).
    fn cost(&self, u: &Self::Param) -> Result<f64, argmin::core::Error> {
        let x = self.unscale(u);
        Ok(match self.residuals(&x) {
            Ok(r) => 1e6 * r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64,
            // Out of range: worse than any candidate in range.
            Err(_) => 1e12,
        })
    }
}

/// The part of `log` an experiment's fit uses: a passive hop whole (its
/// friction shows in every hop); an actuated hop to its second touchdown,
/// the first stance and the flight it launched (as the thesis compares the
/// first stance's energy, height and velocity): the hops after it follow
/// the first so sensitively that a whole-log fit finds minima where a
/// later hop lines up with another.
pub fn window(log: &Log, experiment: Experiment) -> Log {
    const GROUND_M: f64 = 1.0e-4;
    const AIRBORNE_M: f64 = 1.0e-3;
    if experiment == Experiment::Passive {
        return log.clone();
    }
    let mut touchdowns = 0;
    let mut airborne = false;
    let mut end = log.t_s.len();
    for (i, &z) in log.toe_m.iter().enumerate() {
        if z > AIRBORNE_M {
            airborne = true;
        } else if airborne && z <= GROUND_M {
            airborne = false;
            touchdowns += 1;
            if touchdowns == 2 {
                end = i + 1;
                break;
            }
        }
    }
    Log {
        t_s: log.t_s.iter().take(end).copied().collect(),
        toe_m: log.toe_m.iter().take(end).copied().collect(),
        file: log.file.clone(),
    }
}

/// Fits `experiment`'s two parameters to `log` (its [`window`]), starting
/// from `base`.
pub fn identify(log: &Log, base: &Params, experiment: Experiment) -> Result<Identified, String> {
    let log = &window(log, experiment);
    let runs = std::cell::Cell::new(0);
    let fit = Fit {
        base: *base,
        experiment,
        log,
        runs: &runs,
    };
    let x0 = start_of(base, experiment);
    if x0.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
        return Err(format!(
            "identify: the base parameters' {} and {} must be positive to start from",
            fields(experiment)[0],
            fields(experiment)[1]
        ));
    }
    // The start must simulate (else the log or the base cannot be fitted:
    // say why, once).
    fit.residuals(&x0).map_err(|e| {
        format!("identify: the experiment does not run from the base parameters: {e}")
    })?;
    // The simplex, in multiples of the start: the start and 30% up each.
    let simplex = vec![vec![1.0, 1.0], vec![1.3, 1.0], vec![1.0, 1.3]];
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(1e-9)
        .map_err(|e| format!("identify: {e}"))?;
    let res = Executor::new(fit, solver)
        .configure(|s| s.max_iters(300))
        .run()
        .map_err(|e| format!("identify: {e}"))?;
    let best = fit.unscale(
        res.state()
            .get_best_param()
            .ok_or("identify: the fit found no parameters")?,
    );
    let r0 = fit
        .residuals(&best)
        .map_err(|e| format!("identify: the best parameters do not simulate: {e}"))?;
    let n = r0.len();
    let ssr: f64 = r0.iter().map(|v| v * v).sum();
    // The Jacobian by central differences, 1% of each value.
    let mut jac = [vec![0.0; n], vec![0.0; n]];
    for (k, col) in jac.iter_mut().enumerate() {
        let h = (best[k].abs() * 0.01).max(1e-4);
        let (mut up, mut down) = (best.clone(), best.clone());
        up[k] += h;
        down[k] -= h;
        // (A step out of the parameters' ranges leaves the column NaN: no
        // uncertainty, the estimate stands.)
        match (fit.residuals(&up), fit.residuals(&down)) {
            (Ok(ru), Ok(rd)) => {
                for (c, (u, d)) in col.iter_mut().zip(ru.iter().zip(&rd)) {
                    *c = (u - d) / (2.0 * h);
                }
            }
            _ => col.iter_mut().for_each(|c| *c = f64::NAN),
        }
    }
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let (a, b, d) = (
        dot(&jac[0], &jac[0]),
        dot(&jac[0], &jac[1]),
        dot(&jac[1], &jac[1]),
    );
    let det = a * d - b * b;
    let s2 = ssr / (n.saturating_sub(2).max(1)) as f64;
    let var = if det > 0.0 {
        [s2 * d / det, s2 * a / det]
    } else {
        [f64::NAN; 2]
    };
    let names = fields(experiment);
    let estimates = (0..2)
        .map(|k| Estimate {
            field: names[k],
            value: best[k],
            std: var[k].sqrt(),
            start: x0[k],
        })
        .collect();
    let stance_torque_nm = match experiment {
        Experiment::OpenTorque { .. } => Some(base.torque_constant_nm_per_a * best[0]),
        Experiment::Passive => None,
    };
    let fitted = fit.simulate(&best).unwrap_or_default();
    Ok(Identified {
        estimates,
        stance_torque_nm,
        rms_residual_m: (ssr / n as f64).sqrt(),
        samples: n,
        simulations: runs.get(),
        fitted_m: fitted,
    })
}

/// Measured against fitted toe height, as `identify.png` and `identify.svg`
/// in `dir` (whole or not at all).
pub fn write_plot(
    log: &Log,
    id: &Identified,
    title: &str,
    dir: &Path,
) -> Result<Vec<std::path::PathBuf>, String> {
    use plotters::prelude::*;
    crate::plot::ensure_font()?;
    const SIZE: (u32, u32) = (1000, 600);
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, plotters::coord::Shift>,
        log: &Log,
        id: &Identified,
        title: &str,
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let t_hi = log.t_s.last().copied().unwrap_or(1.0);
        let z_hi = log
            .toe_m
            .iter()
            .chain(&id.fitted_m)
            .copied()
            .fold(0.0, f64::max)
            * 1.1
            + 1e-3;
        let mut c = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..t_hi, 0.0..z_hi)?;
        c.configure_mesh()
            .x_desc("time [s]")
            .y_desc("toe height [m]")
            .draw()?;
        c.draw_series(LineSeries::new(
            log.t_s.iter().copied().zip(log.toe_m.iter().copied()),
            BLACK.stroke_width(2),
        ))?
        .label("measured")
        .legend(|(a, b)| PathElement::new(vec![(a, b), (a + 20, b)], BLACK.stroke_width(2)));
        c.draw_series(LineSeries::new(
            log.t_s.iter().copied().zip(id.fitted_m.iter().copied()),
            RED.stroke_width(1),
        ))?
        .label("fitted")
        .legend(|(a, b)| PathElement::new(vec![(a, b), (a + 20, b)], RED));
        crate::plot::legend(&mut c, SeriesLabelPosition::UpperRight)?;
        root.present()?;
        Ok(())
    }
    crate::out_dir::write_whole(dir, |staging| {
        crate::plot::png_and_svg(
            staging,
            "identify",
            SIZE,
            "the fit",
            |a| draw(a, log, id, title),
            |a| draw(a, log, id, title),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `hopper-link record`'s telemetry.csv: its columns by name, times
    /// from the first sample; a bad cell is one error naming the row.
    #[test]
    fn reads_a_recorded_telemetry_log() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let mut text = String::from(
            "t_s,seq,step,phase,armed,faults,body_height_m,toe_height_m,nut_position_m,spring_force_n,energy_j,command_a\n",
        );
        for i in 0..150 {
            let t = 12.5 + f64::from(i) * 0.001;
            text += &format!(
                "{t:.6},{i},0,flight,1,none,0.66,{:.6},0,0,60,0\n",
                0.05 - f64::from(i) * 5e-4
            );
        }
        std::fs::write(dir.path().join("telemetry.csv"), &text).unwrap_or_else(|e| panic!("{e}"));
        let log = read_log(dir.path()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(log.t_s.len(), 150);
        assert!(log.t_s[0].abs() < 1e-12 && (log.t_s[149] - 0.149).abs() < 1e-9);
        assert!((log.toe_m[1] - 0.0495).abs() < 1e-9);
        // Body height less leg length goes negative in stance: the toe is
        // on the ground.
        assert_eq!(log.toe_m[149], 0.0);
        std::fs::write(
            dir.path().join("telemetry.csv"),
            text.replace("0.049500", "oops"),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let e = read_log(dir.path()).err().unwrap_or_default();
        assert!(e.contains("row 2") && e.contains("`oops`"), "{e}");
        let empty = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        assert!(read_log(empty.path()).is_err());
    }
}
