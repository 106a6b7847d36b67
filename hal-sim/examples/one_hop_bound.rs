//! How much can one hop raise the apex at all? A numerical search over
//! open-loop current schedules on the full plant model, with perfect
//! knowledge of the plant's state and events: whatever a controller does with
//! its sensors, on this (deterministic) plant it amounts to one such
//! schedule, so the best schedule there is bounds every controller. The
//! best one a search finds is a numerical estimate of that bound, not a
//! proof: a search can miss a better schedule.
//!
//! A hop (apex to apex) gets `3 * SEG` current levels in `[-I_max, I_max]`,
//! each held over a segment timed from the hop's own events: the descent
//! (apex to touchdown) in `SEG` equal parts of its predicted duration, the
//! stance in `SEG` parts of the model's half-period `pi sqrt((M + m_s) / k)`
//! times `STANCE_SPAN` from the environment (default 1; the last
//! level held until liftoff), the ascent in `SEG` parts of its predicted
//! duration (the last held until the apex). The nut's position in its stroke
//! and its speed (up to 0.8 m/s either way) at the starting apex are free
//! too: the best state any earlier hop could have left. A
//! differential-evolution search (five independent runs, three started from
//! the push-reverse-push shape with the nut at rest on its upper stop, two
//! from random schedules and states alone; their spread is printed)
//! maximises the next apex, less `PENALTY` m per joule of stop impacts
//! (default 0.01; 0 allows them, and finds the same rises).
//!
//! For each starting apex it prints the best next apex and that hop's energy
//! ledger. Climbing from 0.05 m to 98 % of 0.15 m then takes at least
//! `0.097 m / rise` hops, `rise` being the largest per-hop rise found at any
//! height; a height from which even the best hop ends lower cannot be held.
//! `SEG=4` or `SEG=16` in the environment changes the grid (8 by default),
//! to check that a finer one finds no more.
//!
//! ```sh
//! cargo run --release -p hal-sim --example one_hop_bound [PENALTY] [PARAMS] [H1,H2,...]
//! ```
//!
//! `PARAMS`: `design` (default), `identified`, or `identified-1nm` (the
//! identified plant with the design's 1 N m current limit).
#![allow(missing_docs)]

use hal_sim::heat_bound::{run_levels, Grid};
use hal_sim::{Mode, Params, Plant, State};

const START_M: f64 = 0.05;
const TARGET_M: f64 = 0.15;
/// Largest nut speed at the starting apex, m/s (about the
/// motor's no-load speed through the screw).
const NUT_SPEED_RANGE_MPS: f64 = 0.8;

/// The schedule's grid ([`Grid`]): `seg` levels per phase (`SEG`, default
/// 8), the stance's spread over `stance_span` model stance times
/// (`STANCE_SPAN`, default 1); from the environment, to check that the
/// grid does not limit the result.
fn grid_from_env() -> Grid {
    let env = |name: &str| std::env::var(name).ok();
    Grid {
        seg: env("SEG")
            .and_then(|s| s.parse().ok())
            .filter(|&n| n > 0)
            .unwrap_or(8),
        stance_span: env("STANCE_SPAN")
            .and_then(|s| s.parse().ok())
            .filter(|&x: &f64| x > 0.0 && x.is_finite())
            .unwrap_or(1.0),
    }
}

/// Levels per hop.
fn levels(grid: Grid) -> usize {
    3 * grid.seg
}

/// What one hop's schedule did.
struct Outcome {
    /// The apex after the hop's liftoff, m (`None`: no such apex).
    apex_m: Option<f64>,
    impact_j: f64,
    /// The plant at that apex (or where the hop ended).
    plant: Plant,
}

/// Run one hop's `levels` from `plant`, at an apex `apex_m` high: the
/// heat bound's hop ([`run_levels`]); a plant error ends the hop without
/// an apex.
fn simulate(plant: &Plant, apex_m: f64, levels: &[f64], grid: Grid) -> Outcome {
    let mut plant = plant.clone();
    let impact0 = plant.ledger().stop_impact_loss_j;
    let apex_m = run_levels(&mut plant, apex_m, levels, grid, &mut |_, _| {})
        .ok()
        .flatten();
    Outcome {
        apex_m,
        impact_j: plant.ledger().stop_impact_loss_j - impact0,
        plant,
    }
}

/// Differential evolution over `[-1, 1]^dim`, maximising `f`:
/// [`hal_sim::heat_bound::minimise`] on `-f`.
fn maximise(
    dim: usize,
    generations: usize,
    seed: u64,
    seeds: &[Vec<f64>],
    f: impl Fn(&[f64]) -> f64 + Sync,
) -> (Vec<f64>, f64) {
    let (x, v) = hal_sim::heat_bound::minimise(dim, generations, seed, seeds, &|x| -f(x));
    (x, -v)
}

/// The bang-bang structure of the yardstick (`bang_bang_climb`) as one
/// hop's levels: reverse, then push in the descent; push in stance; reverse
/// in the ascent.
fn bang_bang_levels(grid: Grid) -> Vec<f64> {
    (0..levels(grid))
        .map(|i| match i / grid.seg {
            0 if i < grid.seg / 2 => -1.0,
            0 | 1 => 1.0,
            _ => -1.0,
        })
        .collect()
}

fn apex_plant(p: &Params, apex_m: f64, nut_pos: f64, nut_speed: f64) -> Plant {
    let state = State {
        z_m: p.leg_length_m + apex_m,
        zd_mps: 0.0,
        p_m: 0.5 * (nut_pos + 1.0) * p.stroke_m,
        pd_mps: NUT_SPEED_RANGE_MPS * nut_speed,
    };
    match Plant::with_state(*p, Mode::Flight, state) {
        Ok(pl) => pl,
        Err(e) => panic!("{e}"),
    }
}

/// What the actuator holds, J: the plant's energy less that of the same
/// body with the nut at rest on its upper stop.
fn actuator_energy_j(plant: &Plant) -> f64 {
    let rest = State {
        p_m: 0.0,
        pd_mps: 0.0,
        ..plant.state()
    };
    plant.energy_j()
        - Plant::with_state(*plant.params(), Mode::Flight, rest)
            .map_or(f64::NAN, |pl| pl.energy_j())
}

fn gain(p: &Params, penalty: f64, heights: &[f64], grid: Grid) {
    println!("largest next apex from an apex h, nut state at h free, stop impacts {penalty} m/J");
    println!("   h (m)   next (m)   rise (m)   impacts (J)   nut p (mm)   nut v (m/s)   below best (mm): seeded worst, unseeded best");
    let mut best_rise = f64::NEG_INFINITY;
    for &h in heights {
        let dim = levels(grid) + 2;
        let mut start = bang_bang_levels(grid);
        start.extend([-1.0, 0.0]);
        let score = |x: &[f64]| {
            let plant = apex_plant(p, h, x[dim - 2], x[dim - 1]);
            let o = simulate(&plant, h, &x[..dim - 2], grid);
            o.apex_m.unwrap_or(-1.0) - penalty * o.impact_j
        };
        // Five searches: three start from the push-reverse-push shape (nut at
        // rest on its upper stop), two from random schedules and states
        // alone. What the unseeded ones reach (printed) says whether the
        // seed steers the result.
        let runs: Vec<(Vec<f64>, f64)> = (1..=5)
            .map(|seed| {
                let seeded = if seed <= 3 {
                    vec![start.clone()]
                } else {
                    Vec::new()
                };
                maximise(dim, 250, seed, &seeded, score)
            })
            .collect();
        let seeded_lo = runs[..3].iter().map(|r| r.1).fold(f64::INFINITY, f64::min);
        let unseeded_best = runs[3..]
            .iter()
            .map(|r| r.1)
            .fold(f64::NEG_INFINITY, f64::max);
        let Some((x, hi)) = runs
            .into_iter()
            .reduce(|a, b| if b.1 > a.1 { b } else { a })
        else {
            continue;
        };
        let plant = apex_plant(p, h, x[dim - 2], x[dim - 1]);
        let o = simulate(&plant, h, &x[..dim - 2], grid);
        let next = o.apex_m.unwrap_or(f64::NAN);
        best_rise = best_rise.max(next - h);
        println!(
            "  {h:.3}     {next:.4}     {:+.4}     {:8.2}     {:8.1}     {:+.3}     {:.1}     {:.1}",
            next - h,
            o.impact_j,
            1e3 * plant.state().p_m,
            plant.state().pd_mps,
            1e3 * (hi - seeded_lo),
            1e3 * (hi - unseeded_best)
        );
        let (l0, l1) = (plant.ledger(), o.plant.ledger());
        println!(
            "          J: motor {:.2}, friction {:.2}, touchdown {:.2}, liftoff {:.2}, stops {:.2}, actuator at apex {:.2} -> {:.2}",
            l1.motor_work_j - l0.motor_work_j,
            l1.friction_j - l0.friction_j,
            l1.touchdown_loss_j - l0.touchdown_loss_j,
            l1.liftoff_loss_j - l0.liftoff_loss_j,
            l1.stop_impact_loss_j - l0.stop_impact_loss_j,
            actuator_energy_j(&plant),
            actuator_energy_j(&o.plant)
        );
    }
    let need = 0.98 * TARGET_M - START_M;
    if best_rise > 0.0 {
        println!(
            "largest rise per hop {best_rise:.4} m: {START_M} -> {:.3} m takes at least {:.1} hops",
            0.98 * TARGET_M,
            need / best_rise
        );
    } else {
        println!("no hop from these heights ends higher than it started: no steady hop there");
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let penalty = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(0.01);
    let name = args.get(2).map_or("design", String::as_str);
    // `identified-1nm`: the identified plant with the design's 1 N m limit.
    let p = match name {
        "identified-1nm" => Params::preset("identified").map(|mut p| {
            p.current_limit_a = Params::design().current_limit_a;
            p
        }),
        _ => Params::preset(name),
    };
    let Some(p) = p else {
        panic!("unknown preset {name}: design, identified or identified-1nm")
    };
    let heights: Vec<f64> = args
        .get(3)
        .map(|s| s.split(',').filter_map(|h| h.parse().ok()).collect())
        .unwrap_or_else(|| vec![0.01, 0.03, 0.05, 0.07, 0.09, 0.11, 0.13, 0.15]);
    gain(&p, penalty, &heights, grid_from_env());
}
