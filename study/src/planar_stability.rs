//! The section 2.2 runner's apex-to-apex return map (beyond the thesis):
//! its fixed point by Newton iteration and the eigenvalues of its Jacobian
//! there, so that "drifts" and "reentrant" (section 2.2.3-2.2.4) become
//! numbers, and the range of the stabiliser's gain `K_c` (eq 2.79) that
//! makes each speed's gait attracting.
//!
//! The map `P` takes the apex state `[z, x', phi, theta, phi', theta']`
//! (the forward position drops out: nothing depends on it) to the next
//! apex's. A gait is reentrant when `P(a) = a`, and attracting when every
//! eigenvalue of `DP(a)` lies inside the unit circle.
//!
//! Two eigenvalues are fixed by the model's structure. The touchdown's
//! plastic impact projects out the toe's sliding speed, so one is 0. And
//! a symmetric gait (mirror-symmetric about mid-stance) lands without
//! sliding and, with no losses, keeps its energy, so the fixed points form
//! a family along the energy and one eigenvalue is 1: passive, a gait is
//! at best neutral along it. The stabiliser of eq 2.79 does not change
//! that: on a symmetric stance its force `K_c (x_d - x')` is even in time
//! while the leg's rate `r'` and angle are odd, so it does no net work
//! (nor a net forward impulse, though a vertical one: the stabilised
//! gait's apex sits lower) and keeps the symmetry, and the family and its
//! eigenvalue 1 persist at every `K_c`. So the fixed point is sought with the apex speed held at
//! the speed asked for, and a gait is called attracting when every other
//! eigenvalue is inside the unit circle ([`FixedPoint::growth`]).

use hopper_plant::planar::{passive_design, ApexState, Gait, PlanarParams, PlanarRunner};
use nalgebra::{DMatrix, DVector, Matrix6};
use serde::Serialize;

/// The integration step, s (as `planar run`).
const DT_S: f64 = 1e-4;
/// The central-difference step for the Jacobians (every component is of
/// order 0.1-5 in SI).
const FD_STEP: f64 = 1e-6;
/// Newton stops below this residual norm.
const TOLERANCE: f64 = 1e-10;
/// Newton's iteration limit.
const MAX_ITERATIONS: usize = 40;
/// A fixed point counts as found when its residual is below this.
pub const FOUND: f64 = 1e-8;

/// The return map: the apex after `a`, with the stabiliser `kc` about
/// `speed_mps` (0: passive), or `None` if the runner falls before one.
pub fn apex_map(p: &PlanarParams, kc: f64, speed_mps: f64, a: &[f64; 6]) -> Option<[f64; 6]> {
    let mut r = PlanarRunner::from_apex(*p, &ApexState::from_array(*a))
        .ok()?
        .stabilised(kc, speed_mps);
    r.next_apex(DT_S, 5.0).map(|(a, _)| a.to_array())
}

/// A gait's fixed point and its stability.
#[derive(Clone, Debug, Serialize)]
pub struct FixedPoint {
    /// Speed asked for, m/s.
    pub speed_mps: f64,
    /// The stabiliser's gain, N s/m (0: passive).
    pub gain_ns_per_m: f64,
    /// The fixed apex `[z m, x' m/s, phi rad, theta rad, phi' rad/s,
    /// theta' rad/s]`.
    pub apex: [f64; 6],
    /// `|P(a) - a|` there.
    pub residual: f64,
    /// Newton iterations taken.
    pub iterations: usize,
    /// The eigenvalues of `DP` as `[re, im]`, largest modulus first.
    pub eigenvalues: Vec<[f64; 2]>,
    /// The energy family's eigenvalue (the one nearest 1).
    pub energy_eigenvalue: [f64; 2],
    /// The largest modulus of the others: how much a deviation off the
    /// family grows each hop (below 1: the gait attracts).
    pub growth: f64,
}

fn residual(p: &PlanarParams, kc: f64, v: f64, a: &[f64; 6]) -> Option<[f64; 6]> {
    let n = apex_map(p, kc, v, a)?;
    let mut r = [0.0; 6];
    for i in 0..6 {
        r[i] = n[i] - a[i];
    }
    Some(r)
}

fn norm(r: &[f64; 6]) -> f64 {
    r.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// `DP(a)` by central differences.
pub fn jacobian(p: &PlanarParams, kc: f64, v: f64, a: &[f64; 6]) -> Option<Matrix6<f64>> {
    let mut j = Matrix6::zeros();
    for c in 0..6 {
        let (mut hi, mut lo) = (*a, *a);
        hi[c] += FD_STEP;
        lo[c] -= FD_STEP;
        let (ph, pl) = (apex_map(p, kc, v, &hi)?, apex_map(p, kc, v, &lo)?);
        for r in 0..6 {
            j[(r, c)] = (ph[r] - pl[r]) / (2.0 * FD_STEP);
        }
    }
    Some(j)
}

/// The error when the runner falls during the search.
fn fell(v: f64, kc: f64) -> String {
    format!("the runner falls near the {v} m/s, K_c {kc} gait")
}

/// Gauss-Newton on `P(a) - a = 0` over the components `free` from `a`:
/// least squares through the SVD, halving a step that does not lower the
/// residual. The last apex, its residual and the iterations taken.
fn newton(
    p: &PlanarParams,
    kc: f64,
    v: f64,
    free: &[usize],
    mut a: [f64; 6],
) -> Result<([f64; 6], [f64; 6], usize), String> {
    let fell = || fell(v, kc);
    let mut r = residual(p, kc, v, &a).ok_or_else(fell)?;
    let mut iterations = 0;
    while norm(&r) > TOLERANCE && iterations < MAX_ITERATIONS {
        iterations += 1;
        let dp = jacobian(p, kc, v, &a).ok_or_else(fell)?;
        let mut jr = DMatrix::zeros(6, free.len());
        for (k, &c) in free.iter().enumerate() {
            for row in 0..6 {
                jr[(row, k)] = dp[(row, c)] - if row == c { 1.0 } else { 0.0 };
            }
        }
        let rhs = DVector::from_iterator(6, r.iter().map(|x| -x));
        let step = jr
            .svd(true, true)
            .solve(&rhs, 1e-12)
            .map_err(|e| format!("Newton step: {e}"))?;
        let mut scale = 1.0;
        let mut moved = false;
        for _ in 0..20 {
            let mut trial = a;
            for (k, &c) in free.iter().enumerate() {
                trial[c] += scale * step[k];
            }
            if let Some(rt) = residual(p, kc, v, &trial) {
                if norm(&rt) < norm(&r) {
                    a = trial;
                    r = rt;
                    moved = true;
                    break;
                }
            }
            scale *= 0.5;
        }
        if !moved {
            break;
        }
    }
    Ok((a, r, iterations))
}

/// The fixed point of `P` near `guess`, the apex speed held at
/// `speed_mps` (the energy family, module docs), and its eigenvalues.
/// Newton runs first among symmetric apexes (angles zero, where a
/// symmetric gait's apex has them), then with the angles free: from the
/// design's apex at 1 m/s, free angles at once lead it to a least-squares
/// minimum that is no fixed point.
pub fn fixed_point(
    p: &PlanarParams,
    kc: f64,
    speed_mps: f64,
    guess: &[f64; 6],
) -> Result<FixedPoint, String> {
    let fell = || fell(speed_mps, kc);
    let mut a = *guess;
    a[1] = speed_mps;
    a[2] = 0.0;
    a[3] = 0.0;
    let (a, _, first) = newton(p, kc, speed_mps, &[0, 4, 5], a)?;
    let (a, r, second) = newton(p, kc, speed_mps, &[0, 2, 3, 4, 5], a)?;
    let iterations = first + second;
    let dp = jacobian(p, kc, speed_mps, &a).ok_or_else(fell)?;
    let mut eig: Vec<[f64; 2]> = dp
        .complex_eigenvalues()
        .iter()
        .map(|z| [z.re, z.im])
        .collect();
    let modulus = |z: &[f64; 2]| z[0].hypot(z[1]);
    eig.sort_by(|x, y| modulus(y).total_cmp(&modulus(x)));
    let energy = eig
        .iter()
        .enumerate()
        .min_by(|x, y| {
            let d = |z: &[f64; 2]| (z[0] - 1.0).hypot(z[1]);
            d(x.1).total_cmp(&d(y.1))
        })
        .map_or(0, |(i, _)| i);
    let growth = eig
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != energy)
        .map(|(_, z)| modulus(z))
        .fold(0.0, f64::max);
    Ok(FixedPoint {
        speed_mps,
        gain_ns_per_m: kc,
        apex: a,
        residual: norm(&r),
        iterations,
        energy_eigenvalue: eig[energy],
        eigenvalues: eig,
        growth,
    })
}

/// The fixed point of Table 2.2's runner at `speed_mps` with gain `kc`,
/// from the passive design's apex.
pub fn table_fixed_point(speed_mps: f64, kc: f64) -> Result<FixedPoint, String> {
    let p = PlanarParams::table_2_2();
    let d = passive_design(&p, &Gait::table_2_2(speed_mps))
        .map_err(|e| format!("planar design: {e:?}"))?;
    fixed_point(
        &p,
        kc,
        speed_mps,
        &ApexState::of_design(&d, speed_mps).to_array(),
    )
}

/// One speed's row of [`scan`].
#[derive(Clone, Debug, Serialize)]
pub struct SpeedRow {
    /// Speed, m/s.
    pub speed_mps: f64,
    /// The fixed point at each gain of the scan (`None`: Newton found none
    /// or the runner fell).
    pub points: Vec<Option<FixedPoint>>,
    /// The passive gait's growth per hop (`K_c = 0`), if found.
    pub passive_growth: Option<f64>,
    /// The scanned gain with the least growth, N s/m, and that growth.
    pub best_gain_ns_per_m: Option<f64>,
    /// The least growth.
    pub best_growth: Option<f64>,
    /// The gains that lower the growth below the passive gait's: the
    /// lowest and highest scanned, N s/m.
    pub helps_ns_per_m: Option<[f64; 2]>,
    /// The gains whose gait attracts (growth below 1): the lowest and
    /// highest scanned, N s/m.
    pub attracts_ns_per_m: Option<[f64; 2]>,
}

/// The fixed points of Table 2.2's runner over `speeds` x `gains`, each
/// speed's gains in order from the design's apex then the last fixed
/// point found (continuation); `progress` after each point.
pub fn scan(speeds: &[f64], gains: &[f64], progress: &mut dyn FnMut()) -> Vec<SpeedRow> {
    let p = PlanarParams::table_2_2();
    let mut rows = Vec::new();
    for &v in speeds {
        let design = passive_design(&p, &Gait::table_2_2(v))
            .ok()
            .map(|d| ApexState::of_design(&d, v).to_array());
        let mut points: Vec<Option<FixedPoint>> = Vec::new();
        let mut guess = design;
        for &kc in gains {
            let solve = |g: Option<[f64; 6]>| {
                g.and_then(|g| fixed_point(&p, kc, v, &g).ok())
                    .filter(|f| f.residual < FOUND)
            };
            // From the last fixed point, else (if that was another start)
            // from the design's apex.
            let found = solve(guess).or_else(|| if guess == design { None } else { solve(design) });
            if let Some(f) = &found {
                guess = Some(f.apex);
            }
            points.push(found);
            progress();
        }
        let growth_at = |k: usize| points[k].as_ref().map(|f| f.growth);
        let passive_growth = gains.iter().position(|&g| g == 0.0).and_then(growth_at);
        let best = (0..gains.len())
            .filter_map(|k| growth_at(k).map(|g| (gains[k], g)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let range = |keep: &dyn Fn(f64) -> bool| {
            let sel: Vec<f64> = (0..gains.len())
                .filter(|&k| growth_at(k).is_some_and(keep))
                .map(|k| gains[k])
                .collect();
            Some([*sel.first()?, *sel.last()?])
        };
        let helps = passive_growth.and_then(|pg| range(&|g| g < pg));
        let attracts = range(&|g| g < 1.0);
        rows.push(SpeedRow {
            speed_mps: v,
            points,
            passive_growth,
            best_gain_ns_per_m: best.map(|b| b.0),
            best_growth: best.map(|b| b.1),
            helps_ns_per_m: helps,
            attracts_ns_per_m: attracts,
        });
    }
    rows
}

/// The growth per hop against `K_c`, a line per speed, on a log scale with
/// the unit line marked.
fn growth_plot<DB: plotters::prelude::DrawingBackend>(
    root: plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    rows: &[SpeedRow],
    gains: &[f64],
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    root.fill(&WHITE)?;
    let all = rows
        .iter()
        .flat_map(|r| r.points.iter().flatten().map(|f| f.growth));
    let hi = all.clone().fold(1.0, f64::max) * 1.2;
    let lo = all.fold(1.0, f64::min).min(0.9) / 1.1;
    let (g_lo, g_hi) = crate::plot::extent(gains.iter().copied());
    // The legend goes in a column right of the chart, clear of the lines.
    let (w, _) = root.dim_in_pixel();
    let (chart_area, key) = root.split_horizontally(w.saturating_sub(crate::plot::SIDE_LEGEND_PX));
    let mut entries = vec![(
        "1 (attracts below)".to_string(),
        crate::plot::LegendKey::Line(BLACK),
    )];
    let mut c = ChartBuilder::on(&chart_area)
        .caption(
            "Section 2.2 runner: growth of a deviation per hop at the fixed point",
            ("sans-serif", 18),
        )
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(70)
        .build_cartesian_2d(g_lo..g_hi.max(g_lo + 1.0), (lo..hi).log_scale())?;
    c.configure_mesh()
        .x_desc("stabiliser gain K_c [N s/m] (eq 2.79)")
        .y_desc("largest |eigenvalue| off the energy family")
        .draw()?;
    c.draw_series(LineSeries::new(
        [(g_lo, 1.0), (g_hi, 1.0)],
        BLACK.stroke_width(1),
    ))?;
    for (k, row) in rows.iter().enumerate() {
        let colour = Palette99::pick(k).to_rgba();
        let (r, g, b) = colour.rgb();
        entries.push((
            format!("{} m/s", row.speed_mps),
            crate::plot::LegendKey::Line(RGBColor(r, g, b)),
        ));
        let pts: Vec<(f64, f64)> = gains
            .iter()
            .zip(&row.points)
            .filter_map(|(&g, f)| f.as_ref().map(|f| (g, f.growth)))
            .collect();
        c.draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))?;
        c.draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled())))?;
    }
    crate::plot::side_legend(&key, &entries)?;
    root.present()?;
    Ok(())
}

/// `stability.csv` (a row per speed and gain: the fixed apex, the growth,
/// every eigenvalue) and `stability.png`/`.svg` into `dir`, whole or not
/// at all.
pub fn write_outputs(
    dir: &std::path::Path,
    rows: &[SpeedRow],
    gains: &[f64],
) -> Result<Vec<std::path::PathBuf>, String> {
    crate::plot::ensure_font()?;
    crate::out_dir::write_whole(dir, |staging| {
        let mut w = csv::Writer::from_path(staging.join("stability.csv"))
            .map_err(|e| format!("cannot write stability.csv: {e}"))?;
        let mut head: Vec<String> = [
            "speed_mps",
            "kc_ns_per_m",
            "found",
            "z_m",
            "x_dot_mps",
            "phi_rad",
            "theta_rad",
            "phi_dot_rad_s",
            "theta_dot_rad_s",
            "growth",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        for k in 1..=6 {
            head.push(format!("eig{k}_re"));
            head.push(format!("eig{k}_im"));
        }
        w.write_record(&head).map_err(|e| e.to_string())?;
        for row in rows {
            for (&g, f) in gains.iter().zip(&row.points) {
                let mut rec = vec![row.speed_mps.to_string(), g.to_string()];
                match f {
                    Some(f) => {
                        rec.push("true".into());
                        rec.extend(f.apex.iter().map(|x| format!("{x:.9}")));
                        rec.push(format!("{:.6}", f.growth));
                        for z in &f.eigenvalues {
                            rec.push(format!("{:.6}", z[0]));
                            rec.push(format!("{:.6}", z[1]));
                        }
                    }
                    None => {
                        rec.push("false".into());
                        rec.extend(std::iter::repeat_n(String::new(), 19));
                    }
                }
                w.write_record(&rec).map_err(|e| e.to_string())?;
            }
        }
        w.flush()
            .map_err(|e| format!("cannot write stability.csv: {e}"))?;
        let mut names = vec!["stability.csv".to_string()];
        names.extend(crate::plot::png_and_svg(
            staging,
            "stability",
            (1100, 800),
            "the stability plot",
            |a| growth_plot(a, rows, gains),
            |a| growth_plot(a, rows, gains),
        )?);
        Ok(names)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use hopper_plant::planar::PlanarRunner;

    fn point(v: f64, kc: f64) -> FixedPoint {
        table_fixed_point(v, kc).unwrap_or_else(|e| panic!("{v} m/s, K_c {kc}: {e}"))
    }

    /// The fixed points and their growth per hop: 2 m/s passive 1.168, 4
    /// m/s passive 5.51 (the drift of Figures 2.19-2.20), 4 m/s with K_c =
    /// 1000 1.230 (much less, not below 1); each with the energy family's
    /// eigenvalue 1 and the touchdown projection's 0.
    #[test]
    fn fixed_points_and_their_eigenvalues() {
        for (v, kc, growth) in [(2.0, 0.0, 1.168), (4.0, 0.0, 5.510), (4.0, 1000.0, 1.230)] {
            let f = point(v, kc);
            assert!(f.residual < 1e-9, "{f:?}");
            assert!((f.apex[1] - v).abs() < 1e-12);
            assert!(
                (f.growth / growth - 1.0).abs() < 0.02,
                "{v} m/s, K_c {kc}: growth {} (expected {growth})",
                f.growth
            );
            let e = f.energy_eigenvalue;
            assert!((e[0] - 1.0).abs() < 1e-6 && e[1].abs() < 1e-9, "{e:?}");
            let smallest = f.eigenvalues.last().map_or(1.0, |z| z[0].hypot(z[1]));
            assert!(smallest < 1e-6, "{:?}", f.eigenvalues);
            // The symmetric gait: angles zero at the apex.
            assert!(f.apex[2].abs() < 1e-9 && f.apex[3].abs() < 1e-9, "{f:?}");
        }
    }

    /// The Jacobian predicts the runner: a 1e-8 deviation along the 4 m/s
    /// passive gait's largest eigenvector (-5.51) is multiplied by the
    /// eigenvalue's square over two hops, within 2%.
    #[test]
    fn the_jacobian_predicts_the_runners_growth() {
        let p = PlanarParams::table_2_2();
        let f = point(4.0, 0.0);
        let j = jacobian(&p, 0.0, 4.0, &f.apex).unwrap_or_else(|| panic!("fell"));
        let lambda = f.eigenvalues[0][0];
        assert!(
            f.eigenvalues[0][1] == 0.0 && lambda < -5.0,
            "{:?}",
            f.eigenvalues
        );
        let m = j - Matrix6::identity() * lambda;
        let svd = m.svd(false, true);
        let vt = svd.v_t.unwrap_or_else(|| panic!("no SVD"));
        let k = svd.singular_values.imin();
        let mut a = f.apex;
        for i in 0..6 {
            a[i] += 1e-8 * vt[(k, i)];
        }
        let once = apex_map(&p, 0.0, 4.0, &a).unwrap_or_else(|| panic!("fell"));
        let twice = apex_map(&p, 0.0, 4.0, &once).unwrap_or_else(|| panic!("fell"));
        let dev = |x: &[f64; 6]| {
            x.iter()
                .zip(&f.apex)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt()
        };
        let ratio = dev(&twice) / dev(&a);
        assert!(
            (ratio / (lambda * lambda) - 1.0).abs() < 0.02,
            "grew {ratio}, lambda^2 {}",
            lambda * lambda
        );
    }

    /// Why the family survives the stabiliser: over the stance of the 4
    /// m/s, K_c = 1000 fixed point its force's work `-int F_c dr` and its
    /// forward impulse `int F_c sin(theta) dt` vanish (below 1e-6 of their
    /// gross `int |...|`, the trapezoid's error at 0.1 ms), while its
    /// vertical impulse does not; the touchdown takes nothing.
    #[test]
    fn the_stabiliser_does_no_work_on_a_symmetric_gait() {
        let p = PlanarParams::table_2_2();
        let f = point(4.0, 1000.0);
        let mut r = PlanarRunner::from_apex(p, &ApexState::from_array(f.apex))
            .unwrap_or_else(|e| panic!("{e:?}"))
            .stabilised(1000.0, 4.0);
        let (mut work, mut gross_work) = (0.0, 0.0);
        let (mut forward, mut gross_forward, mut up) = (0.0, 0.0, 0.0);
        let mut loss = 0.0;
        let mut apexes = 0;
        for _ in 0..20_000 {
            let (q0, f0) = (r.state(), r.stabiliser_force_n());
            r.step(DT_S, &mut |e| match e {
                hopper_plant::planar::PlanarEvent::Touchdown { loss_j, .. } => loss += loss_j,
                hopper_plant::planar::PlanarEvent::Apex { .. } => apexes += 1,
                hopper_plant::planar::PlanarEvent::Liftoff { .. } => {}
            });
            if apexes > 0 {
                break;
            }
            let (q1, f1) = (r.state(), r.stabiliser_force_n());
            let dw = -0.5 * (f0 + f1) * (q1.leg_length_m - q0.leg_length_m);
            work += dw;
            gross_work += dw.abs();
            let fwd = 0.5 * DT_S * (f0 * q0.theta_rad.sin() + f1 * q1.theta_rad.sin());
            forward += fwd;
            gross_forward += fwd.abs();
            up -= 0.5 * DT_S * (f0 * q0.theta_rad.cos() + f1 * q1.theta_rad.cos());
        }
        assert_eq!(apexes, 1);
        assert!(loss.abs() < 1e-9, "touchdown took {loss} J");
        assert!(
            gross_work > 1.0 && gross_forward > 0.1,
            "{gross_work} {gross_forward}"
        );
        assert!(
            work.abs() < 1e-6 * gross_work,
            "work {work} of {gross_work}"
        );
        assert!(
            forward.abs() < 1e-6 * gross_forward,
            "{forward} of {gross_forward}"
        );
        assert!(up.abs() > 0.1 * gross_forward, "vertical impulse {up}");
    }

    /// The design's apex is off the fixed point (4 m/s: 0.8733 m against
    /// 0.8726 m, the leg rate 6.154 against 5.925 rad/s): from it the
    /// stabilised gait falls after 16 apexes; from the fixed point its
    /// apexes stay within 0.1 mm for 20 hops (and it runs 137).
    #[test]
    fn from_the_fixed_point_the_stabilised_gait_holds() {
        let p = PlanarParams::table_2_2();
        let f = point(4.0, 1000.0);
        assert!(
            (f.apex[0] - 0.8726).abs() < 2e-4 && (f.apex[5] - 5.925).abs() < 5e-3,
            "{f:?}"
        );
        let mut r = PlanarRunner::from_apex(p, &ApexState::from_array(f.apex))
            .unwrap_or_else(|e| panic!("{e:?}"))
            .stabilised(1000.0, 4.0);
        for hop in 0..20 {
            let (a, _) = r
                .next_apex(DT_S, 5.0)
                .unwrap_or_else(|| panic!("fell at {hop}"));
            assert!((a.z_m - f.apex[0]).abs() < 1e-4, "hop {hop}: {a:?}");
        }
    }

    /// The scan's summary: at 4 m/s the scanned gains 250-2500 lower the
    /// growth below the passive gait's, the best near the thesis's 1000,
    /// and none attracts.
    #[test]
    fn the_scan_ranges() {
        let gains = [0.0, 250.0, 1000.0, 2500.0, 3000.0];
        let rows = scan(&[4.0], &gains, &mut || {});
        let r = &rows[0];
        assert_eq!(r.best_gain_ns_per_m, Some(1000.0), "{r:?}");
        assert_eq!(r.helps_ns_per_m, Some([250.0, 2500.0]), "{r:?}");
        assert_eq!(r.attracts_ns_per_m, None);
        assert!(r.points.iter().all(Option::is_some));
    }
}
