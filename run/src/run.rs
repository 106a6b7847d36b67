//! Scenario runner: a controller against the plant at a fixed control rate,
//! with trajectory sampling and the per-run summary `hopper-sim` prints.

use crate::controller::{EstimatorEvents, FaultRecord, PlantDriver};
use crate::csv_out::Fixed;
use crate::params::Params;
use crate::plant::{Event, Ledger, Mode, Plant, PlantError};
use hopper_control::telemetry::HopLedger;
use serde::Serialize;

/// Toe height bounds accepted for a start apex, m.
pub const START_APEX_RANGE_M: (f64, f64) = (0.0, 2.0);

/// Longest simulated duration a run accepts, s.
pub const MAX_DURATION_S: f64 = 3600.0;

/// A hopper counts as stopped when it stays on the ground at least this long
/// after its last touchdown (several stance times), s.
pub const STOPPED_AFTER_S: f64 = 0.5;

/// What to run.
#[derive(Clone, Debug)]
pub struct RunConfig {
    /// Plant parameters.
    pub params: Params,
    /// Initial toe height at rest, m.
    pub start_apex_m: f64,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Control period, s (10 kHz default).
    pub control_dt_s: f64,
    /// Trajectory sample period, s (0 records nothing).
    pub sample_dt_s: f64,
}

impl RunConfig {
    /// Defaults: design parameters, 0.15 m drop, 5 s, 10 kHz control, 1 kHz samples.
    pub fn new(params: Params) -> Self {
        RunConfig {
            params,
            start_apex_m: 0.15,
            duration_s: 5.0,
            control_dt_s: 1e-4,
            sample_dt_s: 1e-3,
        }
    }

    /// Check the run settings, naming the bad one.
    pub fn validate(&self) -> Result<(), String> {
        self.params.validate().map_err(|e| e.to_string())?;
        let (lo, hi) = START_APEX_RANGE_M;
        if !(self.start_apex_m.is_finite() && self.start_apex_m > lo && self.start_apex_m <= hi) {
            return Err(format!(
                "start apex {} m is out of range: allowed > {lo} and <= {hi} m",
                self.start_apex_m
            ));
        }
        if !(self.duration_s.is_finite()
            && self.duration_s > 0.0
            && self.duration_s <= MAX_DURATION_S)
        {
            return Err(format!(
                "duration {} s is out of range: allowed > 0 and <= {MAX_DURATION_S} s",
                self.duration_s
            ));
        }
        if !(self.control_dt_s.is_finite()
            && self.control_dt_s >= 1e-6
            && self.control_dt_s <= 0.01)
        {
            return Err(format!(
                "control period {} s is out of range: allowed 1e-6 ..= 0.01 s",
                self.control_dt_s
            ));
        }
        if !(self.sample_dt_s.is_finite() && self.sample_dt_s >= 0.0) {
            return Err(format!("sample period {} s must be >= 0", self.sample_dt_s));
        }
        Ok(())
    }
}

/// The trajectory sample (a CSV row) and its contact phase, defined with
/// the plot that draws them (`hopper-plot`); [`phase`] converts the plant's
/// mode.
pub use hopper_plot::{Phase, Sample};

/// A sample's phase: the plant's contact mode.
pub fn phase(mode: Mode) -> Phase {
    match mode {
        Mode::Flight => Phase::Flight,
        Mode::Stance => Phase::Stance,
        Mode::Standing => Phase::Standing,
    }
}

/// The plant's state now as a trajectory sample.
fn sample_of(plant: &Plant, winding_c: Option<f64>) -> Sample {
    let s = plant.state();
    Sample {
        t_s: plant.time_s(),
        phase: phase(plant.mode()),
        z_m: s.z_m,
        zd_mps: s.zd_mps,
        p_m: s.p_m,
        pd_mps: s.pd_mps,
        toe_height_m: plant.toe_height_m(),
        spring_force_n: plant.spring_force_n(),
        torque_nm: plant.motor_torque_nm(),
        energy_j: plant.energy_j(),
        winding_c,
    }
}

/// Per-run summary; its JSON form is `hopper-sim run --json`'s contract.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// Controller name.
    pub controller: String,
    /// Parameter set (preset name or file).
    pub params: String,
    /// Start toe height, m.
    pub start_apex_m: f64,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Toe height at each flight apex after a liftoff, in order, m.
    pub apex_heights_m: Vec<f64>,
    /// Number of stance phases (touchdowns).
    pub hops: usize,
    /// Mean of the last 5 apexes if they are within 2% of each other, m.
    pub steady_apex_m: Option<f64>,
    /// Mean duration of completed stance phases, s.
    pub stance_time_s: Option<f64>,
    /// Time of the last touchdown, if the toe then stayed on the ground for
    /// at least [`STOPPED_AFTER_S`] until the end of the run, s.
    pub stopped_at_s: Option<f64>,
    /// Ledger residual `E - E0 - W_motor + losses` at the end, J.
    pub energy_residual_j: f64,
    /// Largest |residual| seen at any control step, J.
    pub max_abs_energy_residual_j: f64,
    /// Total energy at the start, J.
    pub initial_energy_j: f64,
    /// Total energy at the end, J.
    pub final_energy_j: f64,
    /// Where the energy went, J.
    pub ledger: Ledger,
    /// Fastest motor speed reached, rad/s.
    pub peak_motor_speed_rad_s: f64,
    /// Motor no-load speed at the supply voltage, rad/s.
    pub no_load_speed_rad_s: f64,
    /// Largest nut displacement, m.
    pub peak_stroke_m: f64,
    /// Largest |motor current|, A.
    pub peak_current_a: f64,
    /// Number of nut impacts on the mechanical stops.
    pub stop_impacts: usize,
    /// The controller's apex target, m (null for passive).
    pub target_apex_m: Option<f64>,
    /// First hop (1-based index into `apex_heights_m`) from which every later
    /// apex is within 2% of the target, at least 3 apexes in a row; null if never.
    pub hops_to_converge: Option<usize>,
    /// Largest nut displacement, m (same as `peak_stroke_m`).
    pub max_stroke_m: f64,
    /// Largest |motor current|, A (same as `peak_current_a`).
    pub max_current_a: f64,
    /// The faults the firmware latched, in order, each with the time of the
    /// period that latched it; empty when none.
    pub faults: Vec<FaultRecord>,
    /// Time of the first latched fault, s (null when none).
    pub first_fault_s: Option<f64>,
    /// Largest |current| commanded to the amplifier (DAC code with the
    /// enable) from the period the first fault latched on, A; null when no
    /// fault latched. The supervisor makes it 0.
    pub max_abs_current_after_fault_a: Option<f64>,
    /// Events the firmware's phase estimator reported (null without firmware).
    pub estimated_events: Option<EstimatorEvents>,
    /// The estimator's touchdown and liftoff timing against the plant's
    /// (null without firmware).
    pub contact_latency: Option<ContactLatency>,
    /// Why the firmware refused to arm (`arming::ArmRefusal::name`; the run
    /// then stays disarmed: 0 A, amplifier off); null when it armed.
    pub arm_refused: Option<&'static str>,
    /// The firmware's estimate of the motor's winding temperature (null
    /// without firmware).
    pub thermal: Option<crate::controller::ThermalSummary>,
    /// The firmware's per-hop ledger, one entry per completed hop.
    pub firmware_hops: Vec<HopLedger>,
    /// Motor work (plant ledger) from the first touchdown to the first
    /// liftoff: the energy the motor adds in the first stance, the quantity
    /// of the thesis's ball-screw lead study (Figures 3.1-3.3), J. Null if
    /// the run has no complete stance.
    pub first_stance_motor_work_j: Option<f64>,
    /// Where the energy went, hop by hop (plant ledger between consecutive
    /// apexes, the first entry from the release; `hopper-sim run --ledger`
    /// prints it as a table).
    pub hop_ledger: Vec<HopEnergy>,
    /// Means over the last 5 entries of `hop_ledger`, whether or not the
    /// apex is steady; null with fewer than 5 full hops (the entry from the
    /// release does not count).
    pub steady_hop: Option<HopEnergy>,
    /// A hardware-in-the-loop run's exchange and the robot's control
    /// interrupt cost (`hopper-sim run --hil`); absent from other runs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hil: Option<crate::hil::HilReport>,
}

/// How far apart an estimator event and a plant event may be and still be
/// the same event, s: far more than any detection delay (4.5 ms without
/// the estimator's contact prediction), far less than a stance or flight
/// (90 ms, 40 ms).
pub const CONTACT_MATCH_WINDOW_S: f64 = 0.02;

/// The phase estimator's touchdowns and liftoffs against the plant's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ContactLatency {
    /// Touchdowns.
    pub touchdown: LatencyStats,
    /// Liftoffs.
    pub liftoff: LatencyStats,
}

/// One kind of contact event: estimator against plant (ground truth).
/// Latency is the estimator's event time (the start of the first period
/// whose command follows it) minus the plant's; negative is early.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LatencyStats {
    /// Plant events, except those in the run's last
    /// [`CONTACT_MATCH_WINDOW_S`] (the estimator has had no time to see them).
    pub true_events: usize,
    /// Estimator events paired one to one with a plant event within
    /// [`CONTACT_MATCH_WINDOW_S`].
    pub matched: usize,
    /// Estimator events with no plant event to pair: false events.
    pub false_events: usize,
    /// Plant events with no estimator event: missed events.
    pub missed: usize,
    /// Smallest latency of the pairs, ms.
    pub min_ms: Option<f64>,
    /// Mean latency, ms.
    pub mean_ms: Option<f64>,
    /// Largest latency, ms.
    pub max_ms: Option<f64>,
    /// Largest |latency|, ms.
    pub max_abs_ms: Option<f64>,
}

impl LatencyStats {
    /// Pairs sorted estimator times with sorted plant times, each estimator
    /// event with the nearest unpaired plant event within the window;
    /// plant events after `end_s - window` do not count as missed.
    pub fn pair(estimated_s: &[f64], truth_s: &[f64], end_s: f64) -> LatencyStats {
        let w = CONTACT_MATCH_WINDOW_S;
        let mut used = vec![false; truth_s.len()];
        let mut lat = Vec::new();
        let mut false_events = 0;
        for &e in estimated_s {
            let best = truth_s
                .iter()
                .enumerate()
                .filter(|(i, t)| !used[*i] && (e - **t).abs() <= w)
                .min_by(|a, b| (e - a.1).abs().total_cmp(&(e - b.1).abs()));
            match best {
                Some((i, t)) => {
                    used[i] = true;
                    lat.push((e - t) * 1e3);
                }
                None => false_events += 1,
            }
        }
        let counted = |t: f64| t <= end_s - w;
        let true_events = truth_s.iter().filter(|t| counted(**t)).count();
        let missed = truth_s
            .iter()
            .zip(&used)
            .filter(|(t, u)| counted(**t) && !**u)
            .count();
        let n = lat.len();
        let fold = |f: fn(f64, f64) -> f64| lat.iter().copied().reduce(f);
        LatencyStats {
            true_events,
            matched: n,
            false_events,
            missed,
            min_ms: fold(f64::min),
            mean_ms: (n > 0).then(|| lat.iter().sum::<f64>() / n as f64),
            max_ms: fold(f64::max),
            max_abs_ms: lat.iter().map(|x| x.abs()).reduce(f64::max),
        }
    }
}

/// One hop's energy flows, from the previous apex (or the release) to this
/// apex, J, from the plant's ledger. Read at the end of the control period
/// in which the apex fell (within 0.1 ms of it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct HopEnergy {
    /// Time of the apex that ends the hop, s.
    pub apex_time_s: f64,
    /// Its toe height, m.
    pub apex_m: f64,
    /// The plant's total energy there (eqs 2.43-2.45), J: the hop changed it
    /// by `motor_work_j` minus the losses.
    pub total_energy_j: f64,
    /// Net mechanical work of the motor on the nut.
    pub motor_work_j: f64,
    /// Dry friction and spring damping.
    pub friction_j: f64,
    /// Unsprung mass stopped at touchdown.
    pub touchdown_loss_j: f64,
    /// Unsprung mass picked up at liftoff.
    pub liftoff_loss_j: f64,
    /// Nut impacts on the stops.
    pub stop_impact_loss_j: f64,
    /// Kinetic energy dropped when a crawl-speed liftoff became standing.
    pub settle_loss_j: f64,
    /// Rotor and nut kinetic energy at the apex, `0.5 alpha pd^2`.
    pub actuator_kinetic_j: f64,
    /// Spring energy the nut holds at the apex beyond the preload,
    /// `0.5 k ((delta0 + p)^2 - delta0^2)`.
    pub actuator_spring_j: f64,
    /// The hop's time, from the previous apex (or the release), s.
    pub duration_s: f64,
    /// Heat in the motor's winding over the hop, `int i^2 R(T) dt` (outside
    /// the mechanical balance above), J: `stance_copper_loss_j +
    /// flight_copper_loss_j`.
    pub copper_loss_j: f64,
    /// The part of it with the toe on the ground (stance and standing).
    pub stance_copper_loss_j: f64,
    /// The part of it in flight (returning the nut, holding it).
    pub flight_copper_loss_j: f64,
    /// The motor current's RMS over the hop, A.
    pub rms_current_a: f64,
}

impl HopEnergy {
    fn mean(hops: &[HopEnergy]) -> Option<HopEnergy> {
        let n = hops.len() as f64;
        let last = hops.last()?;
        let sum = |f: fn(&HopEnergy) -> f64| hops.iter().map(f).sum::<f64>() / n;
        Some(HopEnergy {
            apex_time_s: last.apex_time_s,
            apex_m: sum(|h| h.apex_m),
            total_energy_j: sum(|h| h.total_energy_j),
            motor_work_j: sum(|h| h.motor_work_j),
            friction_j: sum(|h| h.friction_j),
            touchdown_loss_j: sum(|h| h.touchdown_loss_j),
            liftoff_loss_j: sum(|h| h.liftoff_loss_j),
            stop_impact_loss_j: sum(|h| h.stop_impact_loss_j),
            settle_loss_j: sum(|h| h.settle_loss_j),
            actuator_kinetic_j: sum(|h| h.actuator_kinetic_j),
            actuator_spring_j: sum(|h| h.actuator_spring_j),
            duration_s: sum(|h| h.duration_s),
            copper_loss_j: sum(|h| h.copper_loss_j),
            stance_copper_loss_j: sum(|h| h.stance_copper_loss_j),
            flight_copper_loss_j: sum(|h| h.flight_copper_loss_j),
            // The RMS over all of them, not the mean of their RMS values.
            rms_current_a: Self::rms_over(hops)?,
        })
    }

    /// The current's RMS over consecutive hops, A.
    fn rms_over(hops: &[HopEnergy]) -> Option<f64> {
        let t_s: f64 = hops.iter().map(|h| h.duration_s).sum();
        let a2s: f64 = hops
            .iter()
            .map(|h| h.rms_current_a * h.rms_current_a * h.duration_s)
            .sum();
        (t_s > 0.0).then(|| (a2s / t_s).sqrt())
    }
}

/// Per-hop bookkeeping of the plant ledger.
struct HopTracker {
    last: Ledger,
    last_apex_s: f64,
    /// Copper loss since the last apex with the toe on the ground and in
    /// flight, J.
    stance_copper_j: f64,
    flight_copper_j: f64,
    hops: Vec<HopEnergy>,
}

impl HopTracker {
    /// Books one period's copper loss `copper_j`, from `t0_s` to `t1_s`,
    /// to stance or flight: the toe on the ground at the start
    /// (`on_ground`) and as the period's `events` change it, each part in
    /// proportion to its time (the current changes little within a period).
    fn heat(&mut self, on_ground: bool, t0_s: f64, t1_s: f64, copper_j: f64, events: &[Event]) {
        let span_s = t1_s - t0_s;
        if span_s <= 0.0 {
            return;
        }
        let (mut t_s, mut ground) = (t0_s, on_ground);
        let mut book = |ground: bool, dt_s: f64| {
            let j = copper_j * dt_s / span_s;
            if ground {
                self.stance_copper_j += j;
            } else {
                self.flight_copper_j += j;
            }
        };
        for e in events {
            let (te_s, now_ground) = match *e {
                Event::Touchdown { t_s, .. } => (t_s, true),
                Event::Liftoff { t_s, .. } => (t_s, false),
                _ => continue,
            };
            book(ground, te_s - t_s);
            (t_s, ground) = (te_s, now_ground);
        }
        book(ground, t1_s - t_s);
    }

    /// Called after a period in which an apex fell.
    fn apex(&mut self, plant: &Plant, t_s: f64, apex_m: f64) {
        let l = *plant.ledger();
        let p = plant.params();
        let s = plant.state();
        let alpha = p.reflected_inertia_kg();
        let k = p.spring_stiffness_n_per_m;
        let d0 = p.spring_preload_m;
        let d = |f: fn(&Ledger) -> f64| f(&l) - f(&self.last);
        self.hops.push(HopEnergy {
            apex_time_s: t_s,
            apex_m,
            total_energy_j: plant.energy_j(),
            motor_work_j: d(|l| l.motor_work_j),
            friction_j: d(|l| l.friction_j + l.damping_j),
            touchdown_loss_j: d(|l| l.touchdown_loss_j),
            liftoff_loss_j: d(|l| l.liftoff_loss_j),
            stop_impact_loss_j: d(|l| l.stop_impact_loss_j),
            settle_loss_j: d(|l| l.settle_loss_j),
            actuator_kinetic_j: 0.5 * alpha * s.pd_mps * s.pd_mps,
            actuator_spring_j: 0.5 * k * ((d0 + s.p_m).powi(2) - d0 * d0),
            duration_s: plant.time_s() - self.last_apex_s,
            copper_loss_j: d(|l| l.copper_loss_j),
            stance_copper_loss_j: self.stance_copper_j,
            flight_copper_loss_j: self.flight_copper_j,
            rms_current_a: {
                let t = plant.time_s() - self.last_apex_s;
                if t > 0.0 {
                    (d(|l| l.current_squared_a2s) / t).sqrt()
                } else {
                    0.0
                }
            },
        });
        self.last = l;
        self.last_apex_s = plant.time_s();
        self.stance_copper_j = 0.0;
        self.flight_copper_j = 0.0;
    }
}
/// Everything a run produced.
#[derive(Clone, Debug)]
pub struct RunResult {
    /// Trajectory samples at the sample period.
    pub samples: Vec<Sample>,
    /// Every transition, in order.
    pub events: Vec<Event>,
    /// The summary.
    pub summary: Summary,
}

pub use crate::metrics::{hops_to_converge, steady_apex};

/// A running maximum as compare-and-move: `f64::max` adds the NaN handling
/// it needs for operands that can be NaN, once per period and value; the
/// plant refuses a non-finite state, so these are finite (and a NaN would be
/// skipped all the same).
#[inline(always)]
fn raise(max: &mut f64, v: f64) {
    if v > *max {
        *max = v;
    }
}

/// Run a controller against the plant.
pub fn run(
    cfg: &RunConfig,
    params_name: &str,
    controller: &mut dyn PlantDriver,
) -> Result<RunResult, String> {
    run_with_progress(cfg, params_name, controller, &mut |_, _| {})
}

/// [`run`], calling `progress(done, total)` with control steps done about
/// every simulated 0.1 s.
pub fn run_with_progress(
    cfg: &RunConfig,
    params_name: &str,
    controller: &mut dyn PlantDriver,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<RunResult, String> {
    cfg.validate()?;
    let mut plant = Plant::new(cfg.params, cfg.start_apex_m).map_err(|e| e.to_string())?;
    let steps = (cfg.duration_s / cfg.control_dt_s).round() as u64;
    let sample_every = if cfg.sample_dt_s > 0.0 {
        ((cfg.sample_dt_s / cfg.control_dt_s).round() as u64).max(1)
    } else {
        0
    };
    let mut samples = Vec::new();
    let mut events = Vec::new();
    let mut max_residual: f64 = 0.0;
    // |nut speed|, m/s: the motor speed is this over the screw radius (one
    // division at the end instead of one per period, same value).
    let mut peak_nut_speed: f64 = 0.0;
    let mut peak_stroke: f64 = 0.0;
    let mut peak_current: f64 = 0.0;
    if sample_every > 0 {
        samples.push(sample_of(&plant, controller.winding_c()));
    }
    let report_every = ((0.1 / cfg.control_dt_s).round() as u64).max(1);
    // Motor work at the first touchdown, then over the first stance.
    let mut first_touchdown_work_j: Option<f64> = None;
    let mut first_stance_work_j: Option<f64> = None;
    let mut tracker = HopTracker {
        last: Ledger::default(),
        last_apex_s: 0.0,
        stance_copper_j: 0.0,
        flight_copper_j: 0.0,
        hops: Vec::new(),
    };
    // The copper loss at the winding's resistance: the firmware's thermal
    // estimate's `R(T)` each period, or without firmware the stand-in
    // motor's at the ambient temperature.
    let start_resistance_ohm = controller.winding_resistance_ohm().unwrap_or_else(|| {
        let t = hopper_control::thermal::ThermalConfig::default();
        f64::from(t.resistance_at_ohm(t.ambient_c))
    });
    plant.set_winding_resistance_ohm(start_resistance_ohm);
    // Count-downs to the next progress report and sample: a `k % n` per
    // period is an integer division, a noticeable share of a 100 ns period.
    let (mut to_report, mut to_sample) = (report_every, sample_every);
    for k in 1..=steps {
        to_report -= 1;
        if to_report == 0 {
            to_report = report_every;
            progress(k, steps);
        }
        let cmd = controller.current_command_a(&plant);
        if let Some(e) = controller.failure() {
            return Err(e);
        }
        if let Some(r_ohm) = controller.winding_resistance_ohm() {
            plant.set_winding_resistance_ohm(r_ohm);
        }
        let (t0_s, w0_j, n_events) = (plant.time_s(), plant.ledger().motor_work_j, events.len());
        let (on_ground, copper0_j) = (plant.mode() != Mode::Flight, plant.ledger().copper_loss_j);
        plant
            .advance(cfg.control_dt_s, cmd, &mut |e| events.push(e))
            .map_err(|e: PlantError| format!("simulation failed: {e}"))?;
        if first_stance_work_j.is_none() && events.len() > n_events {
            // Events fire inside the period, where the ledger cannot be read:
            // interpolate the work linearly in time (the current is constant
            // over the period, so the error is a fraction of one period's work).
            let (t1_s, w1_j) = (plant.time_s(), plant.ledger().motor_work_j);
            let work_at = |t_s: f64| w0_j + (w1_j - w0_j) * (t_s - t0_s) / (t1_s - t0_s);
            for e in &events[n_events..] {
                match (*e, first_touchdown_work_j) {
                    (Event::Touchdown { t_s, .. }, None) => {
                        first_touchdown_work_j = Some(work_at(t_s));
                    }
                    (Event::Liftoff { t_s, .. }, Some(w_td)) => {
                        first_stance_work_j.get_or_insert(work_at(t_s) - w_td);
                    }
                    _ => {}
                }
            }
        }
        tracker.heat(
            on_ground,
            t0_s,
            plant.time_s(),
            plant.ledger().copper_loss_j - copper0_j,
            &events[n_events..],
        );
        if events.len() > n_events {
            for e in &events[n_events..] {
                if let Event::Apex { t_s, toe_height_m } = *e {
                    tracker.apex(&plant, t_s, toe_height_m);
                }
            }
        }
        raise(&mut max_residual, plant.energy_residual_j().abs());
        let s = plant.state();
        raise(&mut peak_nut_speed, s.pd_mps.abs());
        raise(&mut peak_stroke, s.p_m);
        raise(&mut peak_current, plant.motor_current_a().abs());
        if sample_every > 0 {
            to_sample -= 1;
            if to_sample == 0 {
                to_sample = sample_every;
                samples.push(sample_of(&plant, controller.winding_c()));
            }
        }
    }
    let peak_speed = plant.motor_speed_at_rad_s(peak_nut_speed);
    let summary = summarize(
        cfg,
        params_name,
        controller.name(),
        &plant,
        &events,
        max_residual,
    );
    let contact_latency = controller.contact_times().map(|c| {
        let of = |want_touchdown: bool| -> Vec<f64> {
            events
                .iter()
                .filter_map(|e| match *e {
                    Event::Touchdown { t_s, .. } if want_touchdown => Some(t_s),
                    Event::Liftoff { t_s, .. } if !want_touchdown => Some(t_s),
                    _ => None,
                })
                .collect()
        };
        let end_s = plant.time_s();
        ContactLatency {
            touchdown: LatencyStats::pair(&c.touchdowns_s, &of(true), end_s),
            liftoff: LatencyStats::pair(&c.liftoffs_s, &of(false), end_s),
        }
    });
    Ok(RunResult {
        samples,
        events,
        summary: {
            let faults = controller.faults();
            let target = controller.target_apex_m();
            Summary {
                peak_motor_speed_rad_s: peak_speed,
                peak_stroke_m: peak_stroke,
                peak_current_a: peak_current,
                max_stroke_m: peak_stroke,
                max_current_a: peak_current,
                target_apex_m: target,
                hops_to_converge: target
                    .and_then(|t| hops_to_converge(&summary.apex_heights_m, t, 0.02)),
                first_fault_s: faults.first().map(|f| f.time_s),
                max_abs_current_after_fault_a: controller.max_abs_current_after_fault_a(),
                faults,
                estimated_events: controller.estimator_events(),
                contact_latency,
                arm_refused: controller.arm_refusal(),
                thermal: controller.thermal().map(|mut t| {
                    let steady = match tracker.hops.len() {
                        n if n >= 6 && summary.steady_apex_m.is_some() => {
                            HopEnergy::rms_over(&tracker.hops[n - 5..])
                        }
                        _ => None,
                    };
                    t.heading_for(steady);
                    t
                }),
                firmware_hops: controller.hop_ledgers(),
                hil: controller.hil(),
                first_stance_motor_work_j: first_stance_work_j,
                steady_hop: match tracker.hops.len() {
                    n if n >= 6 => HopEnergy::mean(&tracker.hops[n - 5..]),
                    _ => None,
                },
                hop_ledger: tracker.hops,
                ..summary
            }
        },
    })
}

fn summarize(
    cfg: &RunConfig,
    params_name: &str,
    controller: &str,
    plant: &Plant,
    events: &[Event],
    max_residual: f64,
) -> Summary {
    let mut apexes = Vec::new();
    let mut stance_times = Vec::new();
    let mut hops = 0;
    let mut last_td: Option<f64> = None;
    let mut in_stance_since: Option<f64> = None;
    let mut stop_impacts = 0;
    for e in events {
        match *e {
            Event::Apex { toe_height_m, .. } => apexes.push(toe_height_m),
            Event::Touchdown { t_s, .. } => {
                hops += 1;
                last_td = Some(t_s);
                in_stance_since = Some(t_s);
            }
            Event::Liftoff { t_s, .. } => {
                if let Some(t0) = in_stance_since.take() {
                    stance_times.push(t_s - t0);
                }
                last_td = None;
            }
            Event::StopImpact { .. } => stop_impacts += 1,
            _ => {}
        }
    }
    let end = plant.time_s();
    let stopped_at_s = match (plant.mode(), last_td) {
        (Mode::Flight, _) | (_, None) => None,
        (_, Some(t)) => (end - t >= STOPPED_AFTER_S).then_some(t),
    };
    Summary {
        controller: controller.to_string(),
        params: params_name.to_string(),
        start_apex_m: cfg.start_apex_m,
        duration_s: cfg.duration_s,
        steady_apex_m: steady_apex(&apexes),
        apex_heights_m: apexes,
        hops,
        stance_time_s: (!stance_times.is_empty())
            .then(|| stance_times.iter().sum::<f64>() / stance_times.len() as f64),
        stopped_at_s,
        energy_residual_j: plant.energy_residual_j(),
        max_abs_energy_residual_j: max_residual,
        initial_energy_j: plant.initial_energy_j(),
        final_energy_j: plant.energy_j(),
        ledger: *plant.ledger(),
        peak_motor_speed_rad_s: 0.0,
        no_load_speed_rad_s: plant.params().no_load_speed_rad_s(),
        peak_stroke_m: 0.0,
        peak_current_a: 0.0,
        stop_impacts,
        target_apex_m: None,
        hops_to_converge: None,
        max_stroke_m: 0.0,
        max_current_a: 0.0,
        faults: Vec::new(),
        first_fault_s: None,
        max_abs_current_after_fault_a: None,
        estimated_events: None,
        contact_latency: None,
        arm_refused: None,
        thermal: None,
        firmware_hops: Vec::new(),
        first_stance_motor_work_j: None,
        hop_ledger: Vec::new(),
        steady_hop: None,
        hil: None,
    }
}

/// The columns of `trajectory.csv`, in order: [`TrajectoryRow`]'s fields.
/// Written by hand so that a run without samples still has its header.
pub const TRAJECTORY_COLUMNS: [&str; 11] = [
    "time_s",
    "phase",
    "z_m",
    "zd_mps",
    "p_m",
    "pd_mps",
    "toe_height_m",
    "spring_force_n",
    "torque_nm",
    "energy_j",
    "winding_c",
];

/// One row of `trajectory.csv`: a [`Sample`] with its columns' decimals
/// (forces and torque 1 uN m, time 1 us, lengths 1 nm, temperature 1 mK;
/// an empty temperature without firmware).
#[derive(Serialize)]
struct TrajectoryRow {
    time_s: Fixed<6>,
    phase: &'static str,
    z_m: Fixed<9>,
    zd_mps: Fixed<9>,
    p_m: Fixed<9>,
    pd_mps: Fixed<9>,
    toe_height_m: Fixed<9>,
    spring_force_n: Fixed<6>,
    torque_nm: Fixed<6>,
    energy_j: Fixed<9>,
    winding_c: Option<Fixed<3>>,
}

impl From<&Sample> for TrajectoryRow {
    fn from(s: &Sample) -> Self {
        TrajectoryRow {
            time_s: Fixed(s.t_s),
            phase: s.phase.name(),
            z_m: Fixed(s.z_m),
            zd_mps: Fixed(s.zd_mps),
            p_m: Fixed(s.p_m),
            pd_mps: Fixed(s.pd_mps),
            toe_height_m: Fixed(s.toe_height_m),
            spring_force_n: Fixed(s.spring_force_n),
            torque_nm: Fixed(s.torque_nm),
            energy_j: Fixed(s.energy_j),
            winding_c: s.winding_c.map(Fixed),
        }
    }
}

/// A trajectory sample's fields ([`Sample`] as JSON), the schema of the
/// `/telemetry` channel of a run's `telemetry.mcap`.
pub const SAMPLE_FIELDS: [hopper_mcap::Field; 11] = {
    use hopper_mcap::field as f;
    [
        f("t_s", "number", "simulated time, s"),
        f(
            "phase",
            "string",
            "contact mode: flight, stance or standing",
        ),
        f("z_m", "number", "body coordinate z, m"),
        f("zd_mps", "number", "body velocity, m/s"),
        f("p_m", "number", "nut displacement p, m"),
        f("pd_mps", "number", "nut velocity, m/s"),
        f("toe_height_m", "number", "toe height above the ground, m"),
        f("spring_force_n", "number", "spring force, N"),
        f("torque_nm", "number", "motor torque, N m"),
        f("energy_j", "number", "total mechanical energy, J"),
        f(
            "winding_c",
            "number",
            "the firmware's winding temperature estimate, C (null without firmware)",
        ),
    ]
};

/// Writes a run as MCAP at `path` (Foxglove, PlotJuggler): `/telemetry`
/// (every trajectory sample at its time), `/hop` (the firmware's ledger of
/// each hop, at the apex that ends it), `/fault` (each latched fault at
/// the period that latched it) and `/parameters` (the firmware's, at 0 s).
pub fn write_mcap(
    path: &std::path::Path,
    result: &RunResult,
    parameters: &[(&str, f32)],
) -> Result<(), String> {
    use hopper_mcap::{Mcap, FAULT_FIELDS, HOP_FIELDS};
    let mut m = Mcap::create(path)?;
    let telemetry = m.channel("/telemetry", "hopper.SimSample", &SAMPLE_FIELDS)?;
    let hop = m.channel("/hop", "hopper.Hop", &HOP_FIELDS)?;
    let fault = m.channel("/fault", "hopper.Fault", &FAULT_FIELDS)?;
    let params = m.map_channel("/parameters", "hopper.Parameters")?;
    let values: std::collections::BTreeMap<&str, Option<f32>> = parameters
        .iter()
        .map(|(n, v)| (*n, v.is_finite().then_some(*v)))
        .collect();
    m.log(params, 0.0, &values)?;
    // Each hop's ledger closes at the apex after its stance.
    let mut stances = 0usize;
    let mut ends = Vec::new();
    for e in &result.events {
        match e {
            Event::Touchdown { .. } => stances += 1,
            Event::Apex { t_s, .. } if stances > ends.len() => ends.push(*t_s),
            _ => {}
        }
    }
    let last_s = result.samples.last().map_or(0.0, |s| s.t_s);
    let mut hops = result.summary.firmware_hops.iter().enumerate().peekable();
    let mut faults = result.summary.faults.iter().peekable();
    for s in &result.samples {
        while let Some((i, h)) = hops.next_if(|(i, _)| ends.get(*i).is_some_and(|t| *t <= s.t_s)) {
            m.log(hop, ends.get(i).copied().unwrap_or(last_s), h)?;
        }
        while let Some(f) = faults.next_if(|f| f.time_s <= s.t_s) {
            m.log(fault, f.time_s, &serde_json::json!({ "faults": f.name }))?;
        }
        m.log(telemetry, s.t_s, s)?;
    }
    for (i, h) in hops {
        m.log(hop, ends.get(i).copied().unwrap_or(last_s).max(last_s), h)?;
    }
    for f in faults {
        m.log(fault, f.time_s, &serde_json::json!({ "faults": f.name }))?;
    }
    m.finish()
}

/// Write the trajectory as CSV ([`TRAJECTORY_COLUMNS`]).
pub fn write_csv(samples: &[Sample], w: &mut impl std::io::Write) -> std::io::Result<()> {
    let mut out = csv::WriterBuilder::new().has_headers(false).from_writer(w);
    out.write_record(TRAJECTORY_COLUMNS)?;
    for s in samples {
        out.serialize(TrajectoryRow::from(s))?;
    }
    out.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steady_apex_needs_five_within_two_percent() {
        assert_eq!(steady_apex(&[0.1, 0.1, 0.1, 0.1]), None);
        let s = steady_apex(&[0.3, 0.1, 0.1, 0.1, 0.101, 0.1]).unwrap();
        assert!((s - 0.1002).abs() < 1e-12);
        assert_eq!(steady_apex(&[0.1, 0.1, 0.1, 0.1, 0.11]), None);
    }

    /// The hand-written header names the struct's fields, in order.
    #[test]
    fn trajectory_header_is_the_row_struct() {
        let s = Sample {
            t_s: 0.0,
            phase: Phase::Flight,
            z_m: 0.0,
            zd_mps: 0.0,
            p_m: 0.0,
            pd_mps: 0.0,
            toe_height_m: 0.0,
            spring_force_n: 0.0,
            torque_nm: 0.0,
            energy_j: 0.0,
            winding_c: Some(25.0),
        };
        let mut w = csv::Writer::from_writer(Vec::new());
        w.serialize(TrajectoryRow::from(&s)).unwrap();
        let text = String::from_utf8(w.into_inner().unwrap()).unwrap();
        assert_eq!(
            text.lines().next(),
            Some(TRAJECTORY_COLUMNS.join(",").as_str())
        );
        let mut empty = Vec::new();
        write_csv(&[], &mut empty).unwrap();
        assert_eq!(
            empty,
            format!("{}\n", TRAJECTORY_COLUMNS.join(",")).into_bytes()
        );
    }

    #[test]
    fn run_config_rejects_bad_settings() {
        let mut c = RunConfig::new(Params::design());
        c.start_apex_m = -0.1;
        assert!(c.validate().unwrap_err().contains("start apex"));
        c.start_apex_m = 0.1;
        c.duration_s = f64::NAN;
        assert!(c.validate().unwrap_err().contains("duration"));
    }
}
