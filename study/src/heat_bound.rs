//! The least heat per hop: how little copper loss any current schedule can
//! spend to hold a given apex on the plant, and so how long any controller
//! could hop with a given motor (docs/endurance.md).
//!
//! A steady hop is a periodic orbit: from an apex at `h` with the nut at
//! some position and speed, through one stance, to the next apex at `h`
//! with the nut where and as fast as it started. A controller with
//! perfect knowledge of the plant's state and events can do no better
//! than the best open-loop schedule for that orbit, so the least
//! `int i^2 dt` over schedules that close the orbit bounds every
//! controller's heat per hop at that apex. As with `one_hop_bound`, a
//! search finds an estimate of that least value, not a proof: a finer grid
//! or a better search could find a lower one (the spread of independent
//! searches is reported).
//!
//! The schedule: `3 * seg` current levels in `[-I_max, I_max]`, each held
//! over a segment timed from the hop's own events: the descent (apex to
//! touchdown) in `seg` equal parts of its predicted duration, the stance in
//! `seg` parts of the model's half period `pi sqrt((M + m_s) / k)` (the
//! last held until liftoff), the ascent in `seg` parts of its predicted
//! duration (the last held until the apex). The nut's position and speed at
//! the starting apex are free. The search (differential evolution)
//! minimises `int i^2 dt` plus a penalty on how far the orbit is from
//! closing; a schedule counts when it closes to [`CLOSE_APEX_M`],
//! [`CLOSE_NUT_M`] and [`CLOSE_NUT_MPS`].

use crate::plant::{Event, Mode, Plant, State};
use crate::Params;
use hopper_control::thermal::{MotorThermal, ThermalConfig, THERMAL_STEP_S};
use rand_distr::{Distribution, StandardUniform};
use rand_xoshiro::rand_core::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// The integration step and control period of a hop, s.
pub const DT_S: f64 = 1e-4;
/// Largest nut speed at the starting apex, m/s (either way).
pub const NUT_SPEED_RANGE_MPS: f64 = 0.8;
/// How close the next apex must come to the starting one, m.
pub const CLOSE_APEX_M: f64 = 2e-4;
/// How close the nut must end to where it started, m.
pub const CLOSE_NUT_M: f64 = 2e-4;
/// How close the nut's speed must end to its start, m/s.
pub const CLOSE_NUT_MPS: f64 = 5e-3;

/// One hop's open-loop schedule and the nut's state at its starting apex.
#[derive(Clone, Debug, PartialEq)]
pub struct HopPlan {
    /// Levels, fractions of the current limit in `[-1, 1]`: `seg` for the
    /// descent, `seg` for the stance, `seg` for the ascent.
    pub levels: Vec<f64>,
    /// Nut position at the starting apex, m.
    pub nut_m: f64,
    /// Nut speed at the starting apex, m/s.
    pub nut_mps: f64,
}

impl HopPlan {
    /// Segments per phase.
    pub fn seg(&self) -> usize {
        self.levels.len() / 3
    }
}

/// What one hop of a [`HopPlan`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HopOutcome {
    /// The apex after the hop's liftoff, m (`None`: none within 2 s).
    pub apex_m: Option<f64>,
    /// The state there.
    pub end: State,
    /// `int i^2 dt` over the hop, A^2 s.
    pub current_squared_a2s: f64,
    /// Apex to apex, s.
    pub duration_s: f64,
    /// Net motor work, J.
    pub motor_work_j: f64,
    /// Nut impacts on its stops, J.
    pub stop_impact_j: f64,
}

impl HopOutcome {
    /// The current's RMS over the hop, A.
    pub fn rms_current_a(&self) -> f64 {
        (self.current_squared_a2s / self.duration_s.max(f64::MIN_POSITIVE)).sqrt()
    }

    /// How far the orbit is from closing, in units of its tolerances
    /// (largest of the three; <= 1 closes it).
    pub fn miss(&self, apex_m: f64, plan: &HopPlan) -> f64 {
        let Some(a) = self.apex_m else {
            return f64::INFINITY;
        };
        ((a - apex_m).abs() / CLOSE_APEX_M)
            .max((self.end.p_m - plan.nut_m).abs() / CLOSE_NUT_M)
            .max((self.end.pd_mps - plan.nut_mps).abs() / CLOSE_NUT_MPS)
    }
}

/// Runs one hop of `plan` from an apex at `apex_m` on `params`.
pub fn fly(params: &Params, apex_m: f64, plan: &HopPlan) -> Result<HopOutcome, String> {
    fly_watched(params, apex_m, plan, &mut |_, _| {})
}

/// [`fly`], calling `watch(plant, command_a)` after every period.
pub fn fly_watched(
    params: &Params,
    apex_m: f64,
    plan: &HopPlan,
    watch: &mut dyn FnMut(&Plant, f64),
) -> Result<HopOutcome, String> {
    let p = params;
    let start = State {
        z_m: p.leg_length_m + apex_m,
        zd_mps: 0.0,
        p_m: plan.nut_m,
        pd_mps: plan.nut_mps,
    };
    let mut plant = Plant::with_state(*p, Mode::Flight, start).map_err(|e| e.to_string())?;
    let grid = Grid {
        seg: plan.seg(),
        stance_span: 1.0,
    };
    let apex = run_levels(&mut plant, apex_m, &plan.levels, grid, watch)?;
    let l = plant.ledger();
    Ok(HopOutcome {
        apex_m: apex,
        end: plant.state(),
        current_squared_a2s: l.current_squared_a2s,
        duration_s: plant.time_s(),
        motor_work_j: l.motor_work_j,
        stop_impact_j: l.stop_impact_loss_j,
    })
}

/// How a hop's schedule is laid over its phases: `seg` levels per phase
/// (descent, stance, ascent), the stance's spread over `stance_span`
/// times the model's half period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Levels per phase (at least 1).
    pub seg: usize,
    /// The stance's levels spread over this many model stance times (the
    /// last held until liftoff).
    pub stance_span: f64,
}

/// The one open-loop hop of both searches (this module's least heat, and
/// the `one_hop_bound` example's largest rise): `levels` (fractions of the
/// current limit; `3 * grid.seg` of them, missing ones 0) from `plant`, at
/// an apex `apex_m` high, each held over its segment of the hop's phases,
/// timed from the hop's own events: the descent in `seg` parts of its
/// predicted duration, the stance in `seg` parts of `stance_span` times
/// the model's half period `pi sqrt((M + m_s) / k)`, the ascent in `seg`
/// parts of its predicted duration (each phase's last held until the next
/// event). The hop ends at the apex after its liftoff (returned) or 2 s
/// on (`None`). Only the first touchdown starts the stance: a toe that
/// bounces off the ground in the ascent keeps the ascent's levels.
/// `watch(plant, command_a)` is called after every period.
pub fn run_levels(
    plant: &mut Plant,
    apex_m: f64,
    levels: &[f64],
    grid: Grid,
    watch: &mut dyn FnMut(&Plant, f64),
) -> Result<Option<f64>, String> {
    let p = *plant.params();
    let seg = grid.seg.max(1);
    let i_max = p.current_limit_a;
    let m_t = p.body_mass_kg + p.nut_mass_kg + p.unsprung_mass_kg;
    let g_up = p.gravity_mps2 + p.planarizer_friction_n / m_t;
    let g_dn = p.gravity_mps2 - p.planarizer_friction_n / m_t;
    let t_stance = core::f64::consts::PI
        * ((p.body_mass_kg + p.nut_mass_kg) / p.spring_stiffness_n_per_m).sqrt();
    // Phase: 0 descent, 1 stance, 2 ascent; its start and expected length.
    let mut phase = 0usize;
    let mut phase_t0 = plant.time_s();
    let mut phase_len = (2.0 * apex_m.max(1e-4) / g_dn).sqrt();
    let t_end = plant.time_s() + 2.0;
    let mut apex = None;
    let mut events = Vec::new();
    while apex.is_none() && plant.time_s() < t_end {
        let part = (((plant.time_s() - phase_t0) / phase_len * seg as f64) as usize).min(seg - 1);
        let cmd = levels.get(phase * seg + part).copied().unwrap_or(0.0) * i_max;
        events.clear();
        plant
            .advance(DT_S, cmd, &mut |e| events.push(e))
            .map_err(|e| e.to_string())?;
        watch(plant, cmd);
        for &e in &events {
            match e {
                Event::Touchdown { t_s, .. } if phase == 0 => {
                    phase = 1;
                    phase_t0 = t_s;
                    phase_len = grid.stance_span * t_stance;
                }
                Event::Liftoff {
                    t_s, zd_after_mps, ..
                } => {
                    phase = 2;
                    phase_t0 = t_s;
                    phase_len = zd_after_mps.max(1e-3) / g_up;
                }
                // Only the apex after a liftoff ends the hop (a nut started
                // moving can lift the body off its starting apex at once).
                Event::Apex { toe_height_m, .. } if phase == 2 => apex = Some(toe_height_m),
                _ => {}
            }
        }
    }
    Ok(apex)
}

/// The least-heat hop found at one apex.
#[derive(Clone, Debug)]
pub struct Bound {
    /// The apex held, m.
    pub apex_m: f64,
    /// The best schedule found (`None`: no search closed the orbit).
    pub plan: Option<HopPlan>,
    /// Its hop.
    pub outcome: Option<HopOutcome>,
    /// The independent searches' closed `int i^2 dt`, A^2 s, best first
    /// (`NaN` for a search that closed none).
    pub runs_a2s: Vec<f64>,
}

fn uniform(rng: &mut Xoshiro256PlusPlus) -> f64 {
    StandardUniform.sample(rng)
}

/// Differential evolution (rand/1/bin, weight 0.6, crossover 0.9,
/// population `max(40, dim)`) over `[-1, 1]^dim`, minimising `f`; `seeds`
/// join the random initial population. The best point and its value.
pub fn minimise(
    dim: usize,
    generations: usize,
    seed: u64,
    seeds: &[Vec<f64>],
    f: &(dyn Fn(&[f64]) -> f64 + Sync),
) -> (Vec<f64>, f64) {
    let np = 40usize.max(dim);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut pop: Vec<Vec<f64>> = (0..np)
        .map(|_| (0..dim).map(|_| 2.0 * uniform(&mut rng) - 1.0).collect())
        .collect();
    for (member, s) in pop.iter_mut().zip(seeds) {
        member.clone_from(s);
    }
    let mut fit: Vec<f64> = pop.iter().map(|x| f(x)).collect();
    let (weight, crossover) = (0.6, 0.9);
    for _ in 0..generations {
        for i in 0..np {
            let mut pick = |not: &[usize]| loop {
                let k = (rng.next_u64() % np as u64) as usize;
                if !not.contains(&k) {
                    break k;
                }
            };
            let a = pick(&[i]);
            let b = pick(&[i, a]);
            let c = pick(&[i, a, b]);
            let jr = (rng.next_u64() % dim as u64) as usize;
            let trial: Vec<f64> = (0..dim)
                .map(|j| {
                    if j == jr || uniform(&mut rng) < crossover {
                        (pop[a][j] + weight * (pop[b][j] - pop[c][j])).clamp(-1.0, 1.0)
                    } else {
                        pop[i][j]
                    }
                })
                .collect();
            let s = f(&trial);
            if s <= fit[i] {
                pop[i] = trial;
                fit[i] = s;
            }
        }
    }
    let best = (0..np).fold(0, |b, i| if fit[i] < fit[b] { i } else { b });
    (pop[best].clone(), fit[best])
}

/// The search's point as a plan: levels, then the nut's position (from
/// `[-1, 1]` onto the stroke) and speed.
fn plan_of(p: &Params, x: &[f64]) -> HopPlan {
    let n = x.len() - 2;
    HopPlan {
        levels: x[..n].to_vec(),
        nut_m: 0.5 * (x[n] + 1.0) * p.stroke_m,
        nut_mps: NUT_SPEED_RANGE_MPS * x[n + 1],
    }
}

/// Searches `runs` times (in parallel) for the least-heat closed hop at
/// `apex_m`, `seg` levels per phase, `generations` each.
pub fn search(p: &Params, apex_m: f64, seg: usize, runs: u64, generations: usize) -> Bound {
    use rayon::prelude::*;
    let dim = 3 * seg + 2;
    // The penalty makes any open orbit cost more than the heat of any
    // closed one within the current limit (I_max^2 over a 1 s hop).
    let open_a2s = p.current_limit_a * p.current_limit_a;
    let cost = |x: &[f64]| -> f64 {
        let plan = plan_of(p, x);
        match fly(p, apex_m, &plan) {
            Ok(o) => {
                let miss = o.miss(apex_m, &plan);
                if miss <= 1.0 {
                    o.current_squared_a2s
                } else if miss.is_finite() {
                    open_a2s * (1.0 + miss.ln())
                } else {
                    10.0 * open_a2s
                }
            }
            Err(_) => 10.0 * open_a2s,
        }
    };
    // Half the searches start from the passive hop (0 A, nut at rest on
    // its upper stop), half from random schedules alone.
    let mut passive = vec![0.0; dim];
    passive[dim - 2] = -1.0;
    let found: Vec<(Vec<f64>, f64)> = (1..=runs)
        .into_par_iter()
        .map(|seed| {
            let seeds = if seed % 2 == 1 {
                vec![passive.clone()]
            } else {
                Vec::new()
            };
            minimise(dim, generations, seed, &seeds, &cost)
        })
        .collect();
    let closed = |x: &[f64]| {
        let plan = plan_of(p, x);
        fly(p, apex_m, &plan)
            .ok()
            .filter(|o| o.miss(apex_m, &plan) <= 1.0)
            .map(|o| (plan, o))
    };
    let mut runs_a2s: Vec<f64> = found
        .iter()
        .map(|(x, _)| closed(x).map_or(f64::NAN, |(_, o)| o.current_squared_a2s))
        .collect();
    runs_a2s.sort_by(|a, b| a.total_cmp(b));
    let best = found
        .iter()
        .filter_map(|(x, _)| closed(x))
        .min_by(|a, b| a.1.current_squared_a2s.total_cmp(&b.1.current_squared_a2s));
    Bound {
        apex_m,
        plan: best.as_ref().map(|b| b.0.clone()),
        outcome: best.map(|b| b.1),
        runs_a2s,
    }
}

/// How long a motor with `thermal`'s data runs under a steady RMS current
/// before the winding reaches its derating temperature, from the ambient,
/// s; `None`: never (its steady temperature is below the derating one).
/// The firmware's model, stepped as the firmware steps it.
pub fn endurance_s(thermal: &ThermalConfig, rms_a: f64) -> Option<f64> {
    let cfg = ThermalConfig {
        protect: false,
        ..*thermal
    };
    if cfg
        .steady_winding_c((rms_a * rms_a) as f32)
        .is_some_and(|t| t < cfg.derate_winding_c)
    {
        return None;
    }
    let mut m = MotorThermal::new(cfg).ok()?;
    let mut t_s = 0.0;
    while m.winding_c() < cfg.derate_winding_c {
        m.add(rms_a as f32, THERMAL_STEP_S);
        t_s += f64::from(THERMAL_STEP_S);
        if t_s > 1e6 {
            return None;
        }
    }
    Some(t_s)
}
