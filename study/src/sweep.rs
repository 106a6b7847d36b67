//! Parameter sweeps (`hopper-sim sweep`): a grid of runs around a base
//! scenario, run in parallel on every core, summarised one CSV row per run
//! and plotted (a line for one swept parameter, a heat map for two). The
//! printed table, the CSV and the plot say of each point whether it
//! converged, when the motor's thermal protection derated its current limit
//! and which fault latched when: a point that stopped on a fault or hopped
//! on less current is not a point of the controller as designed.
//!
//! A swept parameter is `NAME=START:END:N` (`N` evenly spaced values from
//! `START` to `END`, both included). `NAME` is a plant parameter field
//! ([`crate::params::FIELDS`], e.g. `screw_lead_m`) or a controller setting:
//! `torque`, `target_apex`, `start_apex`, `ke` (energy-law gain),
//! `flight_kp`, `flight_kd` (or their column names, e.g. `torque_nm`).

use crate::csv_out::Shown;
use crate::names;
use crate::params::{field, FieldSpec, FIELDS};
use crate::plot::viridis;
use crate::run::{self, Summary};
use crate::scenario::{Dedicated, Settings};
use hopper_control::hopper::HopperConfig;
use hopper_control::laws::ControllerKind;
use hopper_control::params::{self as fw, Param};
use plotters::coord::Shift;
use plotters::prelude::*;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Most values one swept parameter may take.
pub const MAX_VALUES: usize = 1000;
/// Most runs one sweep may make.
pub const MAX_RUNS: usize = 100_000;

/// Built-in named sweeps (`hopper-sim sweep --preset NAME`): the scenario
/// files of `scenarios/`, compiled in so they work from any directory.
pub const PRESETS: [(&str, &str); 1] = [(
    "lead-study",
    include_str!("../../scenarios/lead-study.toml"),
)];

/// What one swept value changes.
#[derive(Clone, Copy)]
pub enum Knob {
    /// A plant parameter field.
    Plant(&'static FieldSpec),
    /// Torque of open-torque / modified-torque, N m.
    Torque,
    /// Apex target, m.
    TargetApex,
    /// Start toe height, m.
    StartApex,
    /// Energy-law gain `K_e`, N m/J.
    EnergyGain,
    /// Flight PD proportional gain, A/rad.
    FlightKp,
    /// Flight PD derivative gain, A s/rad.
    FlightKd,
    /// Sensor-noise seed (rounded to a whole number): a sweep over seeds
    /// repeats one scenario under different noise.
    Seed,
    /// A firmware parameter by its table name ([`hopper_control::params`]),
    /// e.g. `shaped.switch_fraction` (the shaped law's constants are these).
    Param(&'static Param),
}

impl Knob {
    /// Look a name up: a plant field, a firmware parameter or a run
    /// setting, by its name or an alias ([`crate::names`]: a sweep's short
    /// name or column name).
    pub fn parse(name: &str) -> Option<Knob> {
        let name = names::resolve(name);
        if let Some(f) = field(name) {
            return Some(Knob::Plant(f));
        }
        match name {
            "start_apex_m" => return Some(Knob::StartApex),
            "noise_seed" => return Some(Knob::Seed),
            _ => {}
        }
        match Dedicated::of(name) {
            // The settings with a flag of their own have a knob of their own.
            Some(Dedicated::TargetApex) => Some(Knob::TargetApex),
            Some(Dedicated::FlightKp) => Some(Knob::FlightKp),
            Some(Dedicated::FlightKd) => Some(Knob::FlightKd),
            Some(Dedicated::Torque) => Some(Knob::Torque),
            Some(Dedicated::EnergyGain) => Some(Knob::EnergyGain),
            Some(Dedicated::Controller) => None,
            None => fw::find(name).map(Knob::Param),
        }
    }

    /// The quantity's one name ([`crate::names`]).
    fn name(&self) -> &'static str {
        match self {
            Knob::Plant(f) => f.name,
            Knob::Param(p) => p.name,
            Knob::Torque => fw::CONSTANT_TORQUE_NM.name,
            Knob::TargetApex => fw::TARGET_APEX_M.name,
            Knob::StartApex => "start_apex_m",
            Knob::EnergyGain => fw::ENERGY_GAIN.name,
            Knob::FlightKp => fw::FLIGHT_KP.name,
            Knob::FlightKd => fw::FLIGHT_KD.name,
            Knob::Seed => "noise_seed",
        }
    }

    /// CSV column name (with its unit): the alias's column, else the name.
    pub fn column(&self) -> &'static str {
        names::column(self.name())
    }

    /// Set the value in `s`.
    pub fn apply(&self, s: &mut Settings, v: f64) {
        match self {
            Knob::Plant(f) => (f.set)(&mut s.params, v),
            Knob::Torque => s.torque_nm = Some(v),
            Knob::TargetApex => s.target_apex_m = v,
            Knob::StartApex => s.start_apex_m = v,
            Knob::EnergyGain => s.energy_gain_nm_per_j = Some(v),
            Knob::FlightKp => s.flight_kp_a_per_rad = Some(v),
            Knob::FlightKd => s.flight_kd_a_s_per_rad = Some(v),
            // Axis values are finite (checked when parsed); negative seeds
            // saturate to 0.
            Knob::Seed => s.sensors.seed = v.round().max(0.0) as u64,
            Knob::Param(p) => {
                // The last value given for a parameter wins.
                s.firmware_params.retain(|(q, _)| q.name != p.name);
                s.firmware_params.push((p, v as f32));
            }
        }
    }

    /// Why sweeping this knob would change nothing for `controller`, if so.
    fn unused_by(&self, controller: ControllerKind) -> Option<String> {
        use ControllerKind as C;
        match self {
            Knob::Param(p) if !param_applies(p, controller) => Some(crate::controller::owner_of(p)),
            Knob::Torque if !matches!(controller, C::OpenTorque | C::ModifiedTorque) => {
                Some("open-torque and modified-torque".into())
            }
            Knob::EnergyGain if !matches!(controller, C::Energy | C::EnergyApex) => {
                Some("energy and energy-apex".into())
            }
            Knob::FlightKp | Knob::FlightKd if controller == C::Shaped => {
                Some("the controllers with the flight PD (every one but passive and shaped)".into())
            }
            Knob::FlightKp | Knob::FlightKd | Knob::TargetApex if controller == C::Passive => {
                Some("every controller but passive".into())
            }
            _ => None,
        }
    }
}

/// Whether firmware parameter `p` belongs to `controller` (or to every one).
fn param_applies(p: &Param, controller: ControllerKind) -> bool {
    let cfg = HopperConfig {
        strategy: controller.default_strategy(),
        ..HopperConfig::default()
    };
    fw::get(&cfg, p.name).is_ok()
}

/// One swept parameter and its values.
#[derive(Clone)]
pub struct Axis {
    /// The spec as given.
    pub spec: String,
    /// What it changes.
    pub knob: Knob,
    /// The values, in order.
    pub values: Vec<f64>,
}

/// Parse `NAME=START:END:N`.
pub fn parse_axis(spec: &str) -> Result<Axis, String> {
    let bad = |why: String| {
        format!("bad --param `{spec}`: {why} (expected NAME=START:END:N, e.g. screw_lead_m=0.002:0.010:9)")
    };
    let (name, range) = spec.split_once('=').ok_or_else(|| bad("no `=`".into()))?;
    let name = name.trim();
    let knob = Knob::parse(name).ok_or_else(|| {
        let plant: Vec<&str> = FIELDS.iter().map(|f| f.name).collect();
        let is_plant = |a: &&names::Alias| field(a.name()).is_some();
        let settings: Vec<&str> = names::ALIASES
            .iter()
            .filter(|a| !is_plant(a))
            .filter_map(|a| a.short)
            .collect();
        let short: Vec<String> = names::ALIASES
            .iter()
            .filter(is_plant)
            .filter_map(|a| Some(format!("{} = {}", a.short?, a.name())))
            .collect();
        bad(format!(
            "unknown parameter `{name}`: expected a controller setting {settings:?} or a plant parameter {plant:?} (short names: {})",
            short.join(", ")
        ))
    })?;
    let parts: Vec<&str> = range.split(':').map(str::trim).collect();
    let [start, end, n] = parts[..] else {
        return Err(bad(format!("`{range}` is not START:END:N")));
    };
    let num = |s: &str, what: &str| -> Result<f64, String> {
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| bad(format!("{what} `{s}` is not a finite number")))
    };
    let (start, end) = (num(start, "START")?, num(end, "END")?);
    let n: usize = n
        .parse()
        .ok()
        .filter(|n| (1..=MAX_VALUES).contains(n))
        .ok_or_else(|| bad(format!("N `{n}` is not a count in 1 ..= {MAX_VALUES}")))?;
    if n == 1 && start != end {
        return Err(bad("N = 1 needs START = END".into()));
    }
    let values = (0..n)
        .map(|i| {
            let v = if n == 1 {
                start
            } else {
                start + (end - start) * i as f64 / (n - 1) as f64
            };
            // Round off the last bits of the step arithmetic (0.009 rather
            // than 0.009000000000000001) so the CSV shows the values meant.
            format!("{v:.12e}").parse().unwrap_or(v)
        })
        .collect();
    Ok(Axis {
        spec: spec.to_string(),
        knob,
        values,
    })
}

/// Summary metrics of one run, as CSV columns.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Metrics {
    /// Mean of the last 5 apexes if steady, m.
    pub steady_apex_m: Option<f64>,
    /// First hop from which the apex stays within 2% of the target.
    pub hops_to_converge: Option<usize>,
    /// Last apex of the run, m.
    pub last_apex_m: Option<f64>,
    /// Stance phases.
    pub hops: usize,
    /// Net motor work over the run, J.
    pub motor_work_j: f64,
    /// Energy lost in nut impacts on the stops, J.
    pub stop_impact_loss_j: f64,
    /// Motor work per stance (motor work / hops), J.
    pub energy_per_stance_j: Option<f64>,
    /// Motor work in the first stance, J.
    pub first_stance_motor_work_j: Option<f64>,
    /// Largest |motor current|, A.
    pub max_current_a: f64,
    /// Largest nut displacement, m.
    pub max_stroke_m: f64,
    /// Faults the firmware latched.
    pub fault_count: usize,
    /// First apex after a liftoff, m: with the start apex, what the first
    /// stance did to the hop (the motor's work also spins the rotor, and
    /// that part does not lift the body).
    pub first_apex_m: Option<f64>,
    /// When the motor's thermal protection first derated the current
    /// limit, s (None: never, with the protection off, or no firmware): a
    /// point that derated hopped on less current from then on.
    pub first_derated_s: Option<f64>,
    /// Hottest winding temperature the firmware estimated, C (None: no
    /// firmware).
    pub peak_winding_c: Option<f64>,
    /// When the first fault latched, s (None: no fault).
    pub first_fault_s: Option<f64>,
    /// Which fault latched first (its kebab-case name, e.g.
    /// `overtemperature`; None: no fault). Text, so not one of [`METRICS`]:
    /// it is sweep.csv's [`FIRST_FAULT_COLUMN`].
    pub first_fault: Option<&'static str>,
}

/// Metric columns, in CSV order, with the label plots use. sweep.csv has
/// the swept columns, these, then [`FIRST_FAULT_COLUMN`]; columns are only
/// ever appended, so a metric added later goes after that one.
pub const METRICS: [(&str, &str); 15] = [
    ("steady_apex_m", "steady apex [m]"),
    ("hops_to_converge", "hops to converge"),
    ("last_apex_m", "last apex [m]"),
    ("hops", "hops"),
    ("motor_work_j", "motor work [J]"),
    ("stop_impact_loss_j", "stop-impact loss [J]"),
    ("energy_per_stance_j", "motor work per stance [J]"),
    (
        "first_stance_motor_work_j",
        "energy added in the first stance [J]",
    ),
    ("max_current_a", "max current [A]"),
    ("max_stroke_m", "max stroke [m]"),
    ("fault_count", "faults"),
    ("first_apex_m", "first apex [m]"),
    ("first_derated_s", "current limit derated from [s]"),
    ("peak_winding_c", "peak winding temperature [C]"),
    ("first_fault_s", "first fault at [s]"),
];

/// sweep.csv's last column: the name of the fault that latched first
/// (empty: none), beside [`METRICS`]' `first_fault_s`.
pub const FIRST_FAULT_COLUMN: &str = "first_fault";

/// The metrics that count something, printed as whole numbers.
const COUNT_METRICS: [&str; 3] = ["hops_to_converge", "hops", "fault_count"];

/// What a grey (valueless) cell means for a metric: why a run has no value
/// of it.
fn missing_meaning(metric: &str) -> &'static str {
    match metric {
        "hops_to_converge" => "did not converge",
        "steady_apex_m" | "last_apex_m" | "first_apex_m" => "no hop",
        "energy_per_stance_j" | "first_stance_motor_work_j" => "no stance",
        "first_derated_s" => "never derated",
        "first_fault_s" => "no fault",
        "peak_winding_c" => "no winding estimate",
        _ => "no value",
    }
}

/// A fault's name as the firmware spells it, for a merged part's
/// `first_fault` cell (None: no such fault).
pub fn fault_name(text: &str) -> Option<&'static str> {
    hopper_control::supervisor::Fault::ALL
        .iter()
        .map(|f| f.name())
        .find(|n| *n == text)
}

/// The metric plotted when none is asked for.
pub const DEFAULT_METRIC: &str = "steady_apex_m";

impl Metrics {
    /// From a run's summary.
    pub fn of(s: &Summary) -> Metrics {
        Metrics {
            steady_apex_m: s.steady_apex_m,
            hops_to_converge: s.hops_to_converge,
            last_apex_m: s.apex_heights_m.last().copied(),
            hops: s.hops,
            motor_work_j: s.ledger.motor_work_j,
            stop_impact_loss_j: s.ledger.stop_impact_loss_j,
            energy_per_stance_j: (s.hops > 0).then(|| s.ledger.motor_work_j / s.hops as f64),
            first_stance_motor_work_j: s.first_stance_motor_work_j,
            max_current_a: s.max_current_a,
            max_stroke_m: s.max_stroke_m,
            fault_count: s.faults.len(),
            first_apex_m: s.apex_heights_m.first().copied(),
            first_derated_s: s.thermal.and_then(|t| t.first_derated_s),
            peak_winding_c: s.thermal.map(|t| t.peak_winding_c),
            first_fault_s: s.faults.first().map(|f| f.time_s),
            first_fault: s.faults.first().map(|f| f.name),
        }
    }

    /// From its values in [`METRICS`] order, as [`Metrics::values`] gives
    /// them (a merged shard's CSV row), and the first fault's name (the
    /// [`FIRST_FAULT_COLUMN`]); None when a count is not a whole number, a
    /// value that is always defined is missing, or the fault's name and its
    /// time are not both there or both absent.
    pub fn from_values(
        v: &[Option<f64>; METRICS.len()],
        first_fault: Option<&'static str>,
    ) -> Option<Metrics> {
        let count = |x: Option<f64>| -> Option<usize> {
            let x = x?;
            (x >= 0.0 && x.fract() == 0.0 && x <= usize::MAX as f64).then_some(x as usize)
        };
        let [steady, converge, last, hops, work, impact, per_stance, first_work, current, stroke, faults, first_apex, derated, winding, fault_at] =
            *v;
        // A fault's name, its time and the count come from one list of
        // faults: a row where they disagree was not written by a run.
        if first_fault.is_some() != fault_at.is_some()
            || first_fault.is_some() != (count(faults)? > 0)
        {
            return None;
        }
        Some(Metrics {
            steady_apex_m: steady,
            hops_to_converge: match converge {
                None => None,
                c => Some(count(c)?),
            },
            last_apex_m: last,
            hops: count(hops)?,
            motor_work_j: work?,
            stop_impact_loss_j: impact?,
            energy_per_stance_j: per_stance,
            first_stance_motor_work_j: first_work,
            max_current_a: current?,
            max_stroke_m: stroke?,
            fault_count: count(faults)?,
            first_apex_m: first_apex,
            first_derated_s: derated,
            peak_winding_c: winding,
            first_fault_s: fault_at,
            first_fault,
        })
    }

    /// Every metric in [`METRICS`] order (None: not defined for this run).
    pub fn values(&self) -> [Option<f64>; METRICS.len()] {
        [
            self.steady_apex_m,
            self.hops_to_converge.map(|h| h as f64),
            self.last_apex_m,
            Some(self.hops as f64),
            Some(self.motor_work_j),
            Some(self.stop_impact_loss_j),
            self.energy_per_stance_j,
            self.first_stance_motor_work_j,
            Some(self.max_current_a),
            Some(self.max_stroke_m),
            Some(self.fault_count as f64),
            self.first_apex_m,
            self.first_derated_s,
            self.peak_winding_c,
            self.first_fault_s,
        ]
    }

    /// What became of the run, in words, for the printed table: converged
    /// or not, and when the current limit derated and which fault latched,
    /// e.g. `not converged; derated from 11.65 s; faulted: overtemperature
    /// at 14.33 s`.
    ///
    /// `convergence`: whether to say if the apex converged to the target
    /// (a sweep of an apex metric); without it and with nothing to report,
    /// `no derating, no fault`.
    pub fn outcome(&self, convergence: bool) -> String {
        let mut parts = Vec::new();
        if convergence {
            parts.push(match self.hops_to_converge {
                Some(k) => format!("converged from hop {k}"),
                None => "not converged".to_string(),
            });
        }
        if let Some(t) = self.first_derated_s {
            parts.push(format!("derated from {t:.2} s"));
        }
        if let (Some(name), Some(t)) = (self.first_fault, self.first_fault_s) {
            let more = match self.fault_count {
                0 | 1 => String::new(),
                n => format!(" (+{} more)", n - 1),
            };
            parts.push(format!("faulted: {name} at {t:.2} s{more}"));
        }
        if parts.is_empty() {
            return "no derating, no fault".to_string();
        }
        parts.join("; ")
    }

    /// One metric by column name.
    pub fn get(&self, name: &str) -> Option<f64> {
        METRICS
            .iter()
            .position(|(n, _)| *n == name)
            .and_then(|i| self.values()[i])
    }
}

/// A deterministic slice of a grid: shard `index` (1-based) of `count`
/// takes the points `i = a n + b` (row `a`, last-axis index `b` of `n`)
/// with `(a + b) mod count = index - 1`: diagonal stripes, so that every
/// slice has its share of both axes' values (the slices of a grid whose
/// run time grows along an axis cost about the same, also when `count`
/// shares factors with `n`: 1000 shards of a 1000 x 1000 grid each get
/// every value of both axes once).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// Which slice, 1..=count.
    pub index: usize,
    /// How many slices.
    pub count: usize,
}

impl Shard {
    /// The whole grid.
    pub const WHOLE: Shard = Shard { index: 1, count: 1 };

    /// `K/N`, 1 <= K <= N.
    pub fn parse(spec: &str) -> Result<Shard, String> {
        let bad = || format!("--shard `{spec}`: expected K/N with 1 <= K <= N, e.g. 3/8");
        let (k, n) = spec.split_once('/').ok_or_else(bad)?;
        let (index, count) = (
            k.trim().parse::<usize>().map_err(|_| bad())?,
            n.trim().parse::<usize>().map_err(|_| bad())?,
        );
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }

    /// Whether grid point `point` is in this slice, the last axis having
    /// `last_len` values.
    pub fn owns(&self, point: usize, last_len: usize) -> bool {
        let n = last_len.max(1);
        (point / n + point % n) % self.count == self.index - 1
    }
}

/// A shard's CSV: `point` (the grid index), then sweep.csv's columns.
pub const PART_CSV: &str = "sweep-part.csv";
/// A shard's manifest: which grid, which slice ([`PartManifest`]).
pub const PART_MANIFEST: &str = "sweep-part.json";
/// The parts' layout version: 2 since sweep.csv gained the derating and
/// fault columns (a version-1 part lacks them, and its runs' derating was
/// not kept, so it cannot be merged with a version-2 one).
pub const PART_FORMAT: u32 = 2;

/// What a shard's directory says about the grid it is a slice of: what
/// `sweep merge` needs to check the parts belong together and to draw the
/// plots of the whole.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PartManifest {
    /// Layout version ([`PART_FORMAT`]).
    pub format: u32,
    /// Fingerprint of the grid's settings, axes and metric (FNV-1a, hex):
    /// parts of different sweeps never merge.
    pub grid: String,
    /// This slice: `shard` of `of`.
    pub shard: usize,
    /// How many slices.
    pub of: usize,
    /// Points in the whole grid.
    pub runs: usize,
    /// The axes as given (`NAME=START:END:N`).
    pub axes: Vec<String>,
    /// The plotted metric.
    pub metric: String,
    /// The plots' title.
    pub title: String,
}

/// `sweep merge`: the parts of one sharded grid, checked to be every
/// slice of the same grid exactly once, as the whole grid's [`Sweep`]
/// (its base settings the defaults: what a grid writes depends on its axes
/// and metric only, the title carries the rest), its rows in grid order
/// and the title.
pub fn merge(parts: &[PathBuf]) -> Result<(Sweep, Vec<Row>, String), String> {
    let Some(first_dir) = parts.first() else {
        return Err("sweep merge: no part directories given".into());
    };
    let read = |dir: &Path| -> Result<(PartManifest, String), String> {
        let m = dir.join(PART_MANIFEST);
        let text = std::fs::read_to_string(&m).map_err(|e| {
            format!(
                "{}: {e} (not a `hopper-sim sweep --shard` output directory?)",
                m.display()
            )
        })?;
        let manifest: PartManifest =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", m.display()))?;
        if manifest.format != PART_FORMAT {
            return Err(format!(
                "{}: part format {}, this hopper-sim reads {PART_FORMAT} (written by another hopper-sim version: run that shard again)",
                m.display(),
                manifest.format
            ));
        }
        let c = dir.join(PART_CSV);
        let csv = std::fs::read_to_string(&c).map_err(|e| format!("{}: {e}", c.display()))?;
        Ok((manifest, csv))
    };
    let (first, _) = read(first_dir)?;
    let axes = first
        .axes
        .iter()
        .map(|a| parse_axis(a))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| format!("{}: {e}", first_dir.display()))?;
    let sweep = Sweep {
        base: Settings::resolve(None, &crate::scenario::Overrides::default()),
        axes,
        metric: first.metric.clone(),
    };
    let header: Vec<String> = sweep.header(true).into_iter().map(String::from).collect();
    let n_axes = sweep.axes.len();
    let last_len = sweep.axes.last().map_or(1, |a| a.values.len());
    let grid: usize = sweep.axes.iter().map(|a| a.values.len()).product();
    if first.runs != grid || first.of == 0 || first.of > MAX_VALUES * MAX_VALUES {
        return Err(format!(
            "{}: {} runs in {} shards does not fit its axes' {grid} points",
            first_dir.display(),
            first.runs,
            first.of
        ));
    }
    let mut rows: Vec<Option<Row>> = vec![None; first.runs];
    let mut seen = vec![false; first.of];
    for dir in parts {
        let (m, csv) = read(dir)?;
        if m.grid != first.grid || m.of != first.of || m.runs != first.runs {
            return Err(format!(
                "{} is a slice of another sweep than {} (grid {} of {} shards, not {} of {})",
                dir.display(),
                first_dir.display(),
                m.grid,
                m.of,
                first.grid,
                first.of
            ));
        }
        match seen.get_mut(m.shard.wrapping_sub(1)) {
            Some(s) if !*s => *s = true,
            Some(_) => {
                return Err(format!(
                    "shard {}/{} given twice ({})",
                    m.shard,
                    m.of,
                    dir.display()
                ))
            }
            None => return Err(format!("{}: shard {} of {}?", dir.display(), m.shard, m.of)),
        }
        let path = dir.join(PART_CSV);
        let mut r = csv::ReaderBuilder::new()
            .has_headers(true)
            .from_reader(csv.as_bytes());
        let got: Vec<String> = r
            .headers()
            .map_err(|e| format!("{}: {e}", path.display()))?
            .iter()
            .map(String::from)
            .collect();
        if got != header {
            // Name the first difference only (a part's header is some twenty
            // columns; the usual cause is a part from another version), and
            // of a foreign file's cell only its start.
            let k = got
                .iter()
                .zip(&header)
                .position(|(a, b)| a != b)
                .unwrap_or(got.len().min(header.len()));
            let clip = |c: &String| c.chars().take(40).collect::<String>();
            let what = match (got.get(k).map(clip), header.get(k)) {
                (Some(g), Some(h)) => format!("column {} is `{g}`, not `{h}`", k + 1),
                (None, Some(h)) => format!("no column {} (`{h}`)", k + 1),
                (Some(g), None) => format!("an extra column {} (`{g}`)", k + 1),
                (None, None) => "columns differ".to_string(),
            };
            return Err(format!(
                "{}: {what} (written by another hopper-sim version? run that shard again)",
                path.display()
            ));
        }
        for (line, rec) in r.records().enumerate() {
            let at = || format!("{} row {}", path.display(), line + 1);
            let rec = rec.map_err(|e| format!("{}: {e}", at()))?;
            let cell = |i: usize| -> Result<Option<f64>, String> {
                match rec.get(i) {
                    None | Some("") => Ok(None),
                    Some(t) => t
                        .parse::<f64>()
                        .map(Some)
                        .map_err(|_| format!("{}: `{t}` is not a number", at())),
                }
            };
            let point = cell(0)?
                .filter(|p| p.fract() == 0.0 && *p >= 0.0)
                .map(|p| p as usize)
                .ok_or_else(|| format!("{}: no grid index", at()))?;
            let shard = Shard {
                index: m.shard,
                count: m.of,
            };
            if !shard.owns(point, last_len) {
                return Err(format!(
                    "{}: point {point} is not in shard {}/{}",
                    at(),
                    m.shard,
                    m.of
                ));
            }
            let values = (1..=n_axes)
                .map(|i| cell(i)?.ok_or_else(|| format!("{}: no swept value", at())))
                .collect::<Result<Vec<f64>, String>>()?;
            if values != sweep.point(point).0 {
                return Err(format!(
                    "{}: the swept values {values:?} are not grid point {point}'s",
                    at()
                ));
            }
            let mut metrics = [None; METRICS.len()];
            for (k, slot) in metrics.iter_mut().enumerate() {
                *slot = cell(1 + n_axes + k)?;
            }
            let first_fault = match rec.get(1 + n_axes + METRICS.len()) {
                None | Some("") => None,
                Some(t) => Some(
                    fault_name(t)
                        .ok_or_else(|| format!("{}: `{t}` is not a fault's name", at()))?,
                ),
            };
            let metrics = Metrics::from_values(&metrics, first_fault).ok_or_else(|| {
                format!(
                    "{}: a metric is missing or not a count, or the faults disagree",
                    at()
                )
            })?;
            match rows.get_mut(point) {
                Some(slot @ None) => *slot = Some(Row { values, metrics }),
                Some(Some(_)) => return Err(format!("{}: point {point} twice", at())),
                None => {
                    return Err(format!(
                        "{}: point {point} beyond the grid's {} points",
                        at(),
                        first.runs
                    ))
                }
            }
        }
    }
    let missing: Vec<usize> = seen
        .iter()
        .enumerate()
        .filter(|(_, s)| !**s)
        .map(|(i, _)| i + 1)
        .collect();
    if !missing.is_empty() {
        return Err(missing_shards(&missing, first.of));
    }
    let rows = rows
        .into_iter()
        .enumerate()
        .map(|(i, r)| r.ok_or_else(|| format!("sweep merge: grid point {i} is in no part")))
        .collect::<Result<Vec<Row>, String>>()?;
    Ok((sweep, rows, first.title))
}

/// Most missing shards a merge error names: a 1000-shard grid given one
/// part would otherwise print a line of 999 numbers.
const MISSING_SHOWN: usize = 5;

/// The merge error for the `missing` shards (1-based) of `of`: how many,
/// and the first few.
fn missing_shards(missing: &[usize], of: usize) -> String {
    let shown: Vec<String> = missing
        .iter()
        .take(MISSING_SHOWN)
        .map(usize::to_string)
        .collect();
    let more = if missing.len() > MISSING_SHOWN {
        ", ..."
    } else {
        ""
    };
    format!(
        "sweep merge: {} of {of} shards missing: {}{more} (give every sweep-part directory of the grid)",
        missing.len(),
        shown.join(", ")
    )
}

/// FNV-1a over `bytes`.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// A sweep to run.
pub struct Sweep {
    /// The settings every run starts from.
    pub base: Settings,
    /// One or two swept parameters.
    pub axes: Vec<Axis>,
    /// Column of [`METRICS`] to plot.
    pub metric: String,
}

/// One run of the grid.
#[derive(Clone, Debug)]
pub struct Row {
    /// The swept values, in axis order.
    pub values: Vec<f64>,
    /// What the run gave.
    pub metrics: Metrics,
}

impl Sweep {
    /// Every grid point's swept values (first axis outermost) and settings,
    /// each checked: an error names the point and what is wrong with it.
    pub fn points(&self) -> Result<Vec<(Vec<f64>, Settings)>, String> {
        Ok(self
            .shard_points(Shard::WHOLE)?
            .into_iter()
            .map(|(_, v, s)| (v, s))
            .collect())
    }

    /// How many points each of `count` slices holds (slice 1 first), every
    /// point of the grid checked once: what `--slurm` writes is known to
    /// run, without building a slice's points `count` times over.
    pub fn slice_sizes(&self, count: usize) -> Result<Vec<usize>, String> {
        let runs = self.grid_runs()?;
        let last_len = self.axes.last().map_or(1, |a| a.values.len()).max(1);
        let slices = count.max(1);
        let mut sizes = vec![0; slices];
        for i in 0..runs {
            sizes[(i / last_len + i % last_len) % slices] += 1;
            let (vals, s) = self.point(i);
            s.check()
                .map_err(|e| format!("sweep point {}: {e}", self.describe(&vals)))?;
        }
        if let Some(most) = sizes.iter().copied().filter(|&n| n > MAX_RUNS).max() {
            return Err(format!(
                "{most} runs is too many for one task (at most {MAX_RUNS}; give more tasks)"
            ));
        }
        Ok(sizes)
    }

    /// The points of `shard` with their grid indices, each checked (a
    /// shard builds its own points only: a 10^6-point grid in 100 shards
    /// holds 10^4 settings at a time). At most [`MAX_RUNS`] a shard.
    pub fn shard_points(&self, shard: Shard) -> Result<Vec<(usize, Vec<f64>, Settings)>, String> {
        let runs = self.grid_runs()?;
        let last_len = self.axes.last().map_or(1, |a| a.values.len());
        let mine = (0..runs).filter(|&i| shard.owns(i, last_len)).count();
        if mine > MAX_RUNS {
            return Err(format!(
                "{mine} runs is too many for one sweep (at most {MAX_RUNS}; split it with --shard K/N)"
            ));
        }
        let points: Vec<(usize, Vec<f64>, Settings)> = (0..runs)
            .filter(|&i| shard.owns(i, last_len))
            .map(|i| {
                let (vals, s) = self.point(i);
                (i, vals, s)
            })
            .collect();
        for (_, vals, s) in &points {
            s.check()
                .map_err(|e| format!("sweep point {}: {e}", self.describe(vals)))?;
        }
        Ok(points)
    }

    /// Grid point `index`'s swept values and settings (first axis
    /// outermost: the last axis's index varies fastest).
    pub fn point(&self, index: usize) -> (Vec<f64>, Settings) {
        let mut s = self.base.clone();
        let mut rest = index;
        let mut vals = vec![0.0; self.axes.len()];
        for (k, a) in self.axes.iter().enumerate().rev() {
            let n = a.values.len().max(1);
            let v = a.values.get(rest % n).copied().unwrap_or(f64::NAN);
            rest /= n;
            if let Some(slot) = vals.get_mut(k) {
                *slot = v;
            }
        }
        for (a, &v) in self.axes.iter().zip(&vals) {
            a.knob.apply(&mut s, v);
        }
        (vals, s)
    }

    /// The grid's checks (axes, metric, knobs) and its size.
    fn grid_runs(&self) -> Result<usize, String> {
        if self.axes.is_empty() || self.axes.len() > 2 {
            return Err(format!(
                "a sweep needs one or two --param, got {}",
                self.axes.len()
            ));
        }
        if let [a, b] = &self.axes[..] {
            if a.knob.column() == b.knob.column() {
                return Err(format!(
                    "`{}` is swept twice (`{}`, `{}`)",
                    a.knob.column(),
                    a.spec,
                    b.spec
                ));
            }
        }
        if !METRICS.iter().any(|(n, _)| *n == self.metric) {
            let names: Vec<&str> = METRICS.iter().map(|(n, _)| *n).collect();
            return Err(format!(
                "unknown --metric `{}`: expected one of {names:?}",
                self.metric
            ));
        }
        for a in &self.axes {
            if matches!(a.knob, Knob::Seed) && !self.base.sensors.noise {
                return Err(format!(
                    "--param `{}`: the noise seed changes nothing with sensor noise off",
                    a.spec
                ));
            }
            if let Some(users) = a.knob.unused_by(self.base.controller) {
                return Err(format!(
                    "--param `{}`: `{}` is used by {users} only, not by the `{}` controller",
                    a.spec,
                    a.knob.column(),
                    self.base.controller
                ));
            }
        }
        Ok(self.axes.iter().map(|a| a.values.len()).product())
    }

    /// `name=value, ...` of a point, for messages.
    pub fn describe(&self, values: &[f64]) -> String {
        self.axes
            .iter()
            .zip(values)
            .map(|(a, v)| format!("{}={v}", a.knob.column()))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Run the grid on every core (rayon). `progress` is called once per
    /// finished run, from the worker threads. Rows come back in grid order.
    pub fn run(&self, progress: &(dyn Fn() + Sync)) -> Result<Vec<Row>, String> {
        Ok(self
            .run_shard(Shard::WHOLE, progress)?
            .into_iter()
            .map(|(_, r)| r)
            .collect())
    }

    /// [`Self::run`] on the points of `shard` only, each with its grid index.
    pub fn run_shard(
        &self,
        shard: Shard,
        progress: &(dyn Fn() + Sync),
    ) -> Result<Vec<(usize, Row)>, String> {
        self.shard_points(shard)?
            .par_iter()
            .map(|(i, vals, s)| {
                let i = *i;
                let cfg = s.run_config(0.0);
                let mut ctl = s
                    .controller_spec()
                    .and_then(|spec| spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s))
                    .map_err(|e| format!("sweep point {}: {e}", self.describe(vals)))?;
                let result = run::run(&cfg, &s.params_name, &mut ctl)
                    .map_err(|e| format!("sweep point {}: {e}", self.describe(vals)))?;
                progress();
                Ok((
                    i,
                    Row {
                        values: vals.clone(),
                        metrics: Metrics::of(&result.summary),
                    },
                ))
            })
            .collect()
    }

    /// The grid's fingerprint: its resolved settings, axes and metric.
    pub fn fingerprint(&self) -> String {
        let specs: Vec<&str> = self.axes.iter().map(|a| a.spec.as_str()).collect();
        let text = format!("{:?}|{specs:?}|{}", self.base, self.metric);
        format!("{:016x}", fnv1a(text.as_bytes()))
    }

    /// Write shard `shard`'s rows (grid index and row) into `dir`: its CSV
    /// ([`PART_CSV`]) and manifest ([`PART_MANIFEST`]), whole or not at all.
    pub fn write_part(
        &self,
        shard: Shard,
        rows: &[(usize, Row)],
        dir: &Path,
        title: &str,
    ) -> Result<Vec<PathBuf>, String> {
        let manifest = PartManifest {
            format: PART_FORMAT,
            grid: self.fingerprint(),
            shard: shard.index,
            of: shard.count,
            runs: self.axes.iter().map(|a| a.values.len()).product(),
            axes: self.axes.iter().map(|a| a.spec.clone()).collect(),
            metric: self.metric.clone(),
            title: title.to_string(),
        };
        let json = serde_json::to_string_pretty(&manifest)
            .map_err(|e| format!("cannot format {PART_MANIFEST}: {e}"))?;
        let csv = self.table(true, rows.iter().map(|(i, r)| (Some(*i), r)))?;
        crate::out_dir::write_whole(dir, |staging| {
            let io =
                |n: &str, e: std::io::Error| format!("cannot write {}: {e}", dir.join(n).display());
            std::fs::write(staging.join(PART_CSV), &csv).map_err(|e| io(PART_CSV, e))?;
            std::fs::write(staging.join(PART_MANIFEST), &json).map_err(|e| io(PART_MANIFEST, e))?;
            Ok(vec![PART_CSV.to_string(), PART_MANIFEST.to_string()])
        })
    }

    /// The CSV text: the swept columns, then [`METRICS`]; empty cells for
    /// undefined metrics. The columns depend on the sweep, so a row is a
    /// sequence, not a struct.
    pub fn csv(&self, rows: &[Row]) -> Result<String, String> {
        self.table(false, rows.iter().map(|r| (None, r)))
    }

    /// The header of sweep.csv (with `point` first for a shard's part).
    fn header(&self, point: bool) -> Vec<&str> {
        point
            .then_some("point")
            .into_iter()
            .chain(self.axes.iter().map(|a| a.knob.column()))
            .chain(METRICS.iter().map(|(n, _)| *n))
            .chain(std::iter::once(FIRST_FAULT_COLUMN))
            .collect()
    }

    /// sweep.csv's text, or a part's with each row's grid index first.
    fn table<'a>(
        &self,
        point: bool,
        rows: impl Iterator<Item = (Option<usize>, &'a Row)>,
    ) -> Result<String, String> {
        let header = self.header(point);
        let mut out = csv::WriterBuilder::new()
            .has_headers(false)
            .from_writer(Vec::new());
        let failed = |e: csv::Error| format!("cannot format sweep.csv: {e}");
        out.write_record(&header).map_err(failed)?;
        for (i, r) in rows {
            let numbers: Vec<Option<Shown>> = i
                .map(|i| Shown(i as f64))
                .into_iter()
                .map(Some)
                .chain(r.values.iter().map(|&v| Some(Shown(v))))
                .chain(r.metrics.values().iter().map(|m| m.map(Shown)))
                .collect();
            out.serialize((numbers, r.metrics.first_fault.unwrap_or("")))
                .map_err(failed)?;
        }
        let bytes = out
            .into_inner()
            .map_err(|e| format!("cannot format sweep.csv: {}", e.error()))?;
        String::from_utf8(bytes).map_err(|e| format!("cannot format sweep.csv: {e}"))
    }

    /// The plotted value of a row: the metric, except that the default
    /// metric falls back to the last apex where the run never became steady.
    /// The flag says a fallback was used.
    pub fn plotted(&self, m: &Metrics) -> Plotted {
        match m.get(&self.metric) {
            Some(v) => Some((v, false)),
            None if self.metric == DEFAULT_METRIC => m.last_apex_m.map(|v| (v, true)),
            None => None,
        }
    }

    /// A row's metric as the printed table shows it: counts whole, the
    /// default metric's fallback said so, `-` for no value.
    fn shown(&self, m: &Metrics) -> String {
        match self.plotted(m) {
            Some((v, false)) if COUNT_METRICS.contains(&self.metric.as_str()) => format!("{v:.0}"),
            Some((v, false)) => format!("{v:.4}"),
            Some((v, true)) => format!("{v:.4} (last apex, never steady)"),
            None => "-".to_string(),
        }
    }

    /// Whether the plotted metric is about the apex, so that whether each
    /// run converged to its target belongs in the table and the tally (a
    /// lead study's first-stance work says nothing of convergence).
    pub fn about_the_apex(&self) -> bool {
        matches!(
            self.metric.as_str(),
            "steady_apex_m" | "hops_to_converge" | "last_apex_m"
        )
    }

    /// The printed table, a header line and one line a point: its swept
    /// values, the metric and what became of the run ([`Metrics::outcome`]:
    /// converged or not, derated from when, which fault latched when).
    pub fn text_table(&self, rows: &[Row]) -> Vec<String> {
        let swept: Vec<&str> = self.axes.iter().map(|a| a.knob.column()).collect();
        let head = (swept.join(", "), self.metric.clone(), "outcome".to_string());
        let cells: Vec<(String, String, String)> = rows
            .iter()
            .map(|r| {
                let vals: Vec<String> = r.values.iter().map(|v| format!("{v:.6}")).collect();
                (
                    vals.join(", "),
                    self.shown(&r.metrics),
                    r.metrics.outcome(self.about_the_apex()),
                )
            })
            .collect();
        let width = |f: fn(&(String, String, String)) -> usize| {
            cells.iter().chain([&head]).map(f).max().unwrap_or(0)
        };
        let (w0, w1) = (width(|c| c.0.len()), width(|c| c.1.len()));
        std::iter::once(&head)
            .chain(&cells)
            .map(|(a, b, c)| format!("  {a:>w0$}  {b:>w1$}  {c}"))
            .collect()
    }

    /// Write `sweep.csv`, `sweep.png` and `sweep.svg` into `dir` (created if
    /// missing), whole or not at all ([`crate::out_dir::write_whole`]).
    pub fn write(&self, rows: &[Row], dir: &Path, title: &str) -> Result<Vec<PathBuf>, String> {
        crate::plot::ensure_font()?;
        let csv = self.csv(rows)?;
        let mut svg = String::new();
        self.draw(
            SVGBackend::with_string(&mut svg, PLOT_SIZE).into_drawing_area(),
            rows,
            title,
        )?;
        crate::out_dir::write_whole(dir, |staging| {
            let names = ["sweep.csv", "sweep.png", "sweep.svg"];
            let io =
                |n: &str, e: std::io::Error| format!("cannot write {}: {e}", dir.join(n).display());
            std::fs::write(staging.join(names[0]), &csv).map_err(|e| io(names[0], e))?;
            self.draw(
                BitMapBackend::new(&staging.join(names[1]), PLOT_SIZE).into_drawing_area(),
                rows,
                title,
            )?;
            std::fs::write(staging.join(names[2]), &svg).map_err(|e| io(names[2], e))?;
            Ok(names.map(String::from).to_vec())
        })
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, Shift>,
        rows: &[Row],
        title: &str,
    ) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        // The title spans the figure, over the plot and its side column.
        let res = (|| -> Result<(), Box<dyn std::error::Error>> {
            root.fill(&WHITE)?;
            let (head, body) = root.split_vertically(TITLE_PX);
            head.titled(title, ("sans-serif", 20))?;
            match self.axes.len() {
                1 => self.line_plot(&body, rows),
                _ => self.heat_map(&body, rows),
            }
        })();
        res.and_then(|()| root.present().map_err(Into::into))
            .map_err(|e| format!("cannot draw the sweep plot: {e}"))
    }

    /// Whether a plot marks this point's fault: when it faulted, unless
    /// the plotted metric is the fault's time (its colour says so).
    fn marks_fault(&self, m: &Metrics) -> bool {
        m.fault_count > 0 && self.metric != "first_fault_s"
    }

    /// Whether a plot marks this point's derating: when it derated, unless
    /// the plotted metric is the derating's time.
    fn marks_derating(&self, m: &Metrics) -> bool {
        m.first_derated_s.is_some() && self.metric != "first_derated_s"
    }

    fn metric_label(&self) -> &'static str {
        METRICS
            .iter()
            .find(|(n, _)| *n == self.metric)
            .map_or("", |(_, l)| l)
    }

    fn line_plot<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        rows: &[Row],
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        let (main, side) = root.split_horizontally(PLOT_SIZE.0 - SIDE_PX);
        let vals: Vec<Plotted> = rows.iter().map(|r| self.plotted(&r.metrics)).collect();
        let (x_lo, x_hi) = padded(self.axes[0].values.iter().copied(), 0.03);
        let (y_lo, y_hi) = padded(vals.iter().flatten().map(|p| p.0), 0.08);
        // Points without a value sit on a line in the bottom margin, below
        // every value (the range is padded by 8%).
        let floor = y_lo + (y_hi - y_lo) * 0.025;
        let mut chart = ChartBuilder::on(&main)
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(80)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
        let count = COUNT_METRICS.contains(&self.metric.as_str());
        let label = |v: &f64| whole_or_blank(*v, count);
        chart
            .configure_mesh()
            .x_desc(self.axes[0].knob.column())
            .y_desc(self.metric_label())
            .y_label_formatter(&label)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        // A point without a value breaks the line rather than being bridged.
        let mut segments: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for (r, v) in rows.iter().zip(&vals) {
            match (v, segments.last_mut()) {
                (Some((y, _)), Some(seg)) => seg.push((r.values[0], *y)),
                (None, Some(seg)) if seg.is_empty() => {}
                _ => segments.push(Vec::new()),
            }
        }
        for seg in segments.into_iter().filter(|s| !s.is_empty()) {
            chart.draw_series(LineSeries::new(seg, BLUE.stroke_width(2)))?;
        }
        // A fault's X goes through its point, under the point's own mark
        // so that both show; the derating's triangle sits above.
        let at = |r: &Row, v: &Plotted| (r.values[0], v.map_or(floor, |p| p.0));
        let area = chart.plotting_area();
        for (r, v) in rows.iter().zip(&vals) {
            if self.marks_fault(&r.metrics) {
                draw_mark(area, at(r, v), Mark::Fault, 9, (0, 0))?;
            }
            if self.marks_derating(&r.metrics) {
                draw_mark(area, at(r, v), Mark::Derated, 6, (0, -16))?;
            }
        }
        chart.draw_series(rows.iter().zip(&vals).filter_map(|(r, v)| match v {
            Some((y, false)) => Some(Circle::new((r.values[0], *y), 5, BLUE.filled())),
            _ => None,
        }))?;
        let area = chart.plotting_area();
        for (r, v) in rows.iter().zip(&vals) {
            match v {
                Some((_, true)) => draw_mark(area, at(r, v), Mark::LastApex, 5, (0, 0))?,
                None => draw_mark(area, at(r, v), Mark::NoValue, 5, (0, 0))?,
                Some(_) => {}
            }
        }
        let mut top = 16;
        if vals.iter().all(Option::is_none) {
            top = self.no_value_note(&side, top)?;
        }
        self.legend(&side, top, rows, &vals, true)?;
        Ok(())
    }

    fn heat_map<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        rows: &[Row],
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        let (main, side) = root.split_horizontally(PLOT_SIZE.0 - SIDE_PX);
        let xe = cell_edges(&self.axes[0].values);
        let ye = cell_edges(&self.axes[1].values);
        let ((x_lo, x_hi), (y_lo, y_hi)) = (
            crate::plot::extent(xe.iter().copied()),
            crate::plot::extent(ye.iter().copied()),
        );
        let vals: Vec<Plotted> = rows.iter().map(|r| self.plotted(&r.metrics)).collect();
        let scale = value_range(vals.iter().flatten().map(|(v, _)| *v));
        let mut chart = ChartBuilder::on(&main)
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(80)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
        chart
            .configure_mesh()
            .x_desc(self.axes[0].knob.column())
            .y_desc(self.axes[1].knob.column())
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .disable_mesh()
            .draw()?;
        let (n0, n1) = (self.axes[0].values.len(), self.axes[1].values.len());
        chart.draw_series(vals.iter().enumerate().map(|(k, v)| {
            let (i, j) = (k / n1, k % n1);
            let color = match (v, scale) {
                (Some((v, _)), Some((lo, hi))) => viridis((v - lo) / (hi - lo)),
                _ => NO_VALUE,
            };
            Rectangle::new([(xe[i], ye[j]), (xe[i + 1], ye[j + 1])], color.filled())
        }))?;
        // Marks scale with the cells (a 1000 x 1000 grid's are under a
        // pixel): the fault's in the middle, the derating's and the last
        // apex's in opposite corners, so that all three can share a cell.
        let (w, h) = chart.plotting_area().dim_in_pixel();
        let cell_px = (f64::from(w) / n0.max(1) as f64).min(f64::from(h) / n1.max(1) as f64);
        let size = (cell_px * 0.16).clamp(1.0, 8.0) as i32;
        let off = (cell_px * 0.3) as i32;
        let area = chart.plotting_area();
        for (r, v) in rows.iter().zip(&vals) {
            let at = (r.values[0], r.values[1]);
            if let Some((_, true)) = v {
                draw_mark(area, at, Mark::LastApex, size, (off, off))?;
            }
            if self.marks_derating(&r.metrics) {
                draw_mark(area, at, Mark::Derated, size, (-off, -off))?;
            }
            if self.marks_fault(&r.metrics) {
                draw_mark(area, at, Mark::Fault, size, (0, 0))?;
            }
        }
        let (bar, key) = side.split_vertically(440);
        match scale {
            Some((v_lo, v_hi)) => {
                let mut scale = ChartBuilder::on(&bar)
                    .margin_top(16)
                    .margin_bottom(10)
                    .margin_left(10)
                    .margin_right(100)
                    .y_label_area_size(100)
                    .build_cartesian_2d(0.0..1.0, v_lo..v_hi)?;
                // A count's scale is labelled at whole numbers only (a
                // quarter hop means nothing), one label each when few.
                let count = COUNT_METRICS.contains(&self.metric.as_str());
                let label = |v: &f64| whole_or_blank(*v, count);
                let labels = if count && v_hi - v_lo <= 10.0 {
                    (v_hi - v_lo).round() as usize + 1
                } else {
                    10
                };
                scale
                    .configure_mesh()
                    .disable_x_axis()
                    .disable_mesh()
                    .y_desc(self.metric_label())
                    .y_labels(labels)
                    .y_label_formatter(&label)
                    .y_label_style(("sans-serif", 14))
                    .axis_desc_style(("sans-serif", 15))
                    .draw()?;
                crate::plot::colour_strip(&mut scale, v_lo, v_hi)?;
            }
            None => {
                self.no_value_note(&bar, 16)?;
            }
        }
        self.legend(&key, 10, rows, &vals, false)?;
        Ok(())
    }

    /// Say in `area`, from `top` down, that no run has a value of the
    /// metric (so there is no colour or value scale); returns the line
    /// below the note.
    fn no_value_note<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        top: i32,
    ) -> Result<i32, DrawingAreaErrorKind<DB::ErrorType>> {
        let note = if self.axes.len() == 1 {
            format!(
                "No value scale: no run has a value of {} (every point at the bottom).",
                self.metric_label()
            )
        } else {
            format!(
                "No colour scale: no run has a value of {} (every cell grey).",
                self.metric_label()
            )
        };
        let style = ("sans-serif", 15).into_font().color(&BLACK);
        let mut y = top;
        for line in wrap(&note, 28) {
            area.draw(&Text::new(line, (10, y), style.clone()))?;
            y += 19;
        }
        Ok(y + 20)
    }

    /// The legend of a sweep plot in `area` (the column beside the data,
    /// so it covers none), from `top` down: what a point without a value
    /// means, and the marks for faulted, derated and (the default metric)
    /// never-steady points, each with how many points it marks. `line`:
    /// the 1-axis plot's entries (the line, points without a value on the
    /// bottom) rather than the heat map's (grey cells).
    fn legend<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        top: i32,
        rows: &[Row],
        vals: &[Plotted],
        line: bool,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let count = |f: &dyn Fn(&Row, &Plotted) -> bool| {
            rows.iter().zip(vals).filter(|(r, v)| f(r, v)).count()
        };
        let missing = missing_meaning(&self.metric);
        let mut entries: Vec<(Key, String)> = Vec::new();
        if line {
            entries.push((Key::Line, self.metric_label().to_string()));
        }
        if self.metric == DEFAULT_METRIC {
            let n = count(&|_, v| matches!(v, Some((_, true))));
            entries.push((
                Key::Mark(Mark::LastApex),
                format!("never steady: last apex shown ({n})"),
            ));
        }
        let n = count(&|_, v| v.is_none());
        entries.push(if line {
            (
                Key::Mark(Mark::NoValue),
                format!("no value ({missing}), drawn at the bottom ({n})"),
            )
        } else {
            (Key::Grey, format!("{missing} ({n})"))
        });
        let kinds = fault_kinds(rows);
        let faulted: usize = kinds.iter().map(|(_, n)| n).sum();
        // A metric that is the fault's or the derating's time shows it as
        // the colour: no mark, the entry says so.
        let (fault_key, fault_what) = if self.metric == "first_fault_s" {
            (Key::Plain, "coloured: faulted")
        } else {
            (Key::Mark(Mark::Fault), "faulted")
        };
        entries.push((
            fault_key,
            format!(
                "{fault_what} ({faulted}){}",
                if faulted > 0 { ", first fault:" } else { "" }
            ),
        ));
        const KINDS_SHOWN: usize = 3;
        for (name, n) in kinds.iter().take(KINDS_SHOWN) {
            entries.push((Key::Detail, format!("{name} {n}")));
        }
        if kinds.len() > KINDS_SHOWN {
            let rest: usize = kinds.iter().skip(KINDS_SHOWN).map(|(_, n)| n).sum();
            entries.push((Key::Detail, format!("others {rest}")));
        }
        let n = count(&|r, _| r.metrics.first_derated_s.is_some());
        entries.push(if self.metric == "first_derated_s" {
            (Key::Plain, format!("coloured: current limit derated ({n})"))
        } else {
            (
                Key::Mark(Mark::Derated),
                format!("current limit derated ({n})"),
            )
        });

        let style = ("sans-serif", 14).into_font().color(&BLACK);
        let (x, mut y) = (10, top + 14);
        let frame_top = top;
        for (key, label) in entries {
            let lines = wrap(&label, 28);
            let (kx, ky) = (x + 12, y + 8);
            match key {
                Key::Grey => area.draw(&Rectangle::new(
                    [(kx - 7, ky - 7), (kx + 7, ky + 7)],
                    NO_VALUE.filled(),
                ))?,
                Key::Line => {
                    area.draw(&PathElement::new(
                        vec![(kx - 11, ky), (kx + 11, ky)],
                        BLUE.stroke_width(2),
                    ))?;
                    area.draw(&Circle::new((kx, ky), 5, BLUE.filled()))?;
                }
                Key::Mark(m) => draw_mark(area, (kx, ky), m, 6, (0, 0))?,
                Key::Plain | Key::Detail => {}
            }
            let indent = if matches!(key, Key::Detail) { 46 } else { 30 };
            for l in lines {
                area.draw(&Text::new(l, (x + indent, y), style.clone()))?;
                y += 18;
            }
            y += 6;
        }
        let (w, _) = area.dim_in_pixel();
        area.draw(&Rectangle::new(
            [(x - 4, frame_top), (w as i32 - 10, y)],
            BLACK.stroke_width(1),
        ))?;
        Ok(())
    }
}

/// How many points faulted first with each fault, most first.
fn fault_kinds(rows: &[Row]) -> Vec<(&'static str, usize)> {
    let mut kinds: std::collections::BTreeMap<&'static str, usize> = Default::default();
    for f in rows.iter().filter_map(|r| r.metrics.first_fault) {
        *kinds.entry(f).or_default() += 1;
    }
    let mut kinds: Vec<(&'static str, usize)> = kinds.into_iter().collect();
    kinds.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(b.0)));
    kinds
}

/// One line on a whole sweep, printed under its table: how many points
/// converged, derated and faulted (by their first fault), e.g. `3 of 20
/// points converged; 9 derated; 7 faulted (overtemperature 5,
/// stroke-limit 2)`.
pub fn tally(rows: &[Row], convergence: bool) -> String {
    let converged = rows
        .iter()
        .filter(|r| r.metrics.hops_to_converge.is_some())
        .count();
    let derated = rows
        .iter()
        .filter(|r| r.metrics.first_derated_s.is_some())
        .count();
    let kinds = fault_kinds(rows);
    let faulted: usize = kinds.iter().map(|(_, n)| n).sum();
    let which = if kinds.is_empty() {
        String::new()
    } else {
        let named: Vec<String> = kinds.iter().map(|(f, n)| format!("{f} {n}")).collect();
        format!(" ({})", named.join(", "))
    };
    let n = rows.len();
    match convergence {
        true => format!(
            "{converged} of {n} points converged; {derated} derated; {faulted} faulted{which}"
        ),
        false => format!("{n} points; {derated} derated; {faulted} faulted{which}"),
    }
}

/// A point's plotted value ([`Sweep::plotted`]): the value, and whether it
/// is the default metric's fallback (the last apex); None: no value.
pub type Plotted = Option<(f64, bool)>;

/// What a legend entry shows left of its label.
#[derive(Clone, Copy)]
enum Key {
    /// A grey cell: the heat map's points without a value.
    Grey,
    /// The line plot's line and point.
    Line,
    /// A point's mark.
    Mark(Mark),
    /// Nothing: the label says it all.
    Plain,
    /// Nothing, the label indented: a detail of the entry above.
    Detail,
}

/// The marks a sweep plot puts on a point.
#[derive(Clone, Copy)]
enum Mark {
    /// A fault latched: a black X, in a white halo when big enough to be
    /// seen on the dark end of viridis.
    Fault,
    /// The current limit derated: an orange triangle, edged in black.
    Derated,
    /// Never steady, the last apex plotted instead: a white dot edged in
    /// black.
    LastApex,
    /// No value (the line plot, on its bottom margin): a grey dot.
    NoValue,
}

/// Colour of a cell or point without a value.
const NO_VALUE: RGBColor = RGBColor(200, 200, 200);
/// Colour of the derating mark (the hop plot's derating level's).
const DERATED: RGBColor = RGBColor(230, 140, 0);
/// Width of the column right of a sweep plot (colour bar, legend), px.
const SIDE_PX: u32 = 260;
/// Height of a sweep plot's title, px.
const TITLE_PX: u32 = 40;

/// Draw `mark` at `at` (in `area`'s coordinates), `offset` pixels away,
/// `size` pixels from its centre to its edge.
fn draw_mark<DB, CT>(
    area: &DrawingArea<DB, CT>,
    at: CT::From,
    mark: Mark,
    size: i32,
    offset: (i32, i32),
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend,
    CT: plotters::coord::CoordTranslate,
    CT::From: Clone,
{
    let here = || EmptyElement::at(at.clone());
    let edge = BLACK.stroke_width(1);
    match mark {
        Mark::Fault => {
            if size >= 4 {
                area.draw(&(here() + Cross::new(offset, size, WHITE.stroke_width(5))))?;
            }
            area.draw(&(here() + Cross::new(offset, size, BLACK.stroke_width(2))))
        }
        Mark::Derated => {
            // plotters fills every TriangleMarker: the edge is a path.
            let (dx, dy, r) = (offset.0, offset.1, f64::from(size + 1));
            let corner = |deg: f64| {
                let a = deg.to_radians();
                (
                    dx + (r * a.cos()).round() as i32,
                    dy + (r * a.sin()).round() as i32,
                )
            };
            let tri = vec![corner(-90.0), corner(30.0), corner(150.0), corner(-90.0)];
            area.draw(&(here() + Polygon::new(tri.clone(), DERATED.filled())))?;
            area.draw(&(here() + PathElement::new(tri, edge)))
        }
        Mark::LastApex => {
            area.draw(&(here() + Circle::new(offset, size, WHITE.filled())))?;
            area.draw(&(here() + Circle::new(offset, size, edge)))
        }
        Mark::NoValue => {
            area.draw(&(here() + Circle::new(offset, size, NO_VALUE.filled())))?;
            area.draw(&(here() + Circle::new(offset, size, RGBColor(120, 120, 120))))
        }
    }
}

/// An axis label: for a `count` metric whole numbers only (a quarter hop
/// means nothing), blank between them; otherwise plotters' own format.
fn whole_or_blank(v: f64, count: bool) -> String {
    use plotters::coord::ranged1d::ValueFormatter;
    if !count {
        plotters::coord::types::RangedCoordf64::format(&v)
    } else if (v - v.round()).abs() < 1e-9 {
        format!("{v:.0}")
    } else {
        String::new()
    }
}

/// `text` broken at spaces into lines of at most `width` characters (a
/// longer word keeps its own line).
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    for word in text.split_whitespace() {
        match lines.last_mut() {
            Some(l) if l.chars().count() + 1 + word.chars().count() <= width => {
                l.push(' ');
                l.push_str(word);
            }
            _ => lines.push(word.to_string()),
        }
    }
    lines
}

/// The colour scale's range over `values`: None when there are none; a
/// single value gets a unit-wide range around it.
fn value_range(values: impl Iterator<Item = f64> + Clone) -> Option<(f64, f64)> {
    let (lo, hi) = crate::plot::extent(values);
    if lo > hi {
        None
    } else if hi - lo < 1e-12 {
        Some((lo - 0.5, hi + 0.5))
    } else {
        Some((lo, hi))
    }
}

/// Plot size, pixels.
const PLOT_SIZE: (u32, u32) = (1000, 700);

/// Value range with `frac` of its span added on each side (never empty).
fn padded(values: impl Iterator<Item = f64> + Clone, frac: f64) -> (f64, f64) {
    let (lo, hi) = crate::plot::extent(values);
    if lo > hi {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * frac)
        .max(lo.abs().max(hi.abs()) * 0.01)
        .max(1e-9);
    (lo - pad, hi + pad)
}

/// Cell boundaries around evenly spaced values (one value: a cell of 10%
/// of its size, or of 1 around zero).
fn cell_edges(values: &[f64]) -> Vec<f64> {
    let half = match values {
        [a, b, ..] => (b - a) / 2.0,
        [a] => (a.abs() * 0.05).max(0.5 * f64::from(u8::from(*a == 0.0))),
        [] => 0.5,
    };
    let mut e: Vec<f64> = values.iter().map(|v| v - half).collect();
    e.push(values.last().map_or(half, |v| v + half));
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn viridis_ends_are_purple_and_yellow_and_bad_values_do_not_panic() {
        assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
        assert_eq!(viridis(1.0), RGBColor(254, 232, 37));
        assert_eq!(viridis(f64::NAN), viridis(0.0));
        assert_eq!(viridis(f64::INFINITY), viridis(0.0));
        assert_eq!(viridis(7.0), viridis(1.0));
        assert_eq!(viridis(-7.0), viridis(0.0));
    }

    /// A grid over `specs` with `metric`, around the default settings.
    fn grid(specs: &[&str], metric: &str) -> Sweep {
        Sweep {
            base: Settings::resolve(None, &crate::scenario::Overrides::default()),
            axes: specs
                .iter()
                .map(|s| parse_axis(s).unwrap_or_else(|e| panic!("{e}")))
                .collect(),
            metric: metric.to_string(),
        }
    }

    /// A run's metrics: converged at `converged` (a hop), derated at
    /// `derated` s, faulted with overtemperature at `fault` s.
    /// Rows at the target apexes 0.05, 0.1 and 0.15 m of a 3-point grid.
    fn on_targets(metrics: [Metrics; 3]) -> Vec<Row> {
        metrics
            .into_iter()
            .zip([0.05, 0.1, 0.15])
            .map(|(metrics, v)| Row {
                values: vec![v],
                metrics,
            })
            .collect()
    }

    fn ran(converged: Option<usize>, derated: Option<f64>, fault: Option<f64>) -> Metrics {
        Metrics {
            hops_to_converge: converged,
            steady_apex_m: converged.map(|_| 0.1),
            last_apex_m: Some(0.09),
            hops: 20,
            fault_count: usize::from(fault.is_some()),
            first_derated_s: derated,
            peak_winding_c: Some(if fault.is_some() { 150.0 } else { 140.0 }),
            first_fault_s: fault,
            first_fault: fault.map(|_| "overtemperature"),
            ..Metrics::default()
        }
    }

    /// The words of an SVG, its text elements joined by spaces (a label
    /// wrapped onto two lines reads as one).
    fn words(svg: &str) -> String {
        svg.split("<text")
            .skip(1)
            .filter_map(|t| t.split_once('>').and_then(|(_, r)| r.split_once("</text>")))
            .map(|(w, _)| w.trim())
            .collect::<Vec<_>>()
            .join(" ")
    }

    /// The SVG text of `sw`'s plot of `rows`.
    fn svg(sw: &Sweep, rows: &[Row]) -> String {
        crate::plot::ensure_font().unwrap_or_else(|e| panic!("{e}"));
        let mut text = String::new();
        sw.draw(
            SVGBackend::with_string(&mut text, PLOT_SIZE).into_drawing_area(),
            rows,
            "test",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        text
    }

    #[test]
    fn the_table_marks_each_point_converged_derated_or_faulted() {
        let sw = grid(&["target_apex=0.05:0.15:3"], "hops_to_converge");
        let rows = on_targets([
            ran(Some(4), None, None),
            ran(None, Some(11.652), None),
            ran(None, Some(7.97), Some(10.0612)),
        ]);
        let table = sw.text_table(&rows);
        assert_eq!(table.len(), 4, "{table:#?}");
        assert!(table[0].contains("hops_to_converge") && table[0].contains("outcome"));
        // A count prints whole; a point without a value prints `-`.
        assert!(
            table[1].ends_with("  4  converged from hop 4"),
            "{}",
            table[1]
        );
        assert!(
            table[2].ends_with("  -  not converged; derated from 11.65 s"),
            "{}",
            table[2]
        );
        assert!(
            table[3].ends_with(
                "  -  not converged; derated from 7.97 s; faulted: overtemperature at 10.06 s"
            ),
            "{}",
            table[3]
        );
        // The columns line up: every value ends at the same place.
        let end = |l: &String| l.find("  converged").or_else(|| l.find("  not"));
        assert_eq!(end(&table[1]), end(&table[2]));
        assert_eq!(
            tally(&rows, true),
            "1 of 3 points converged; 2 derated; 1 faulted (overtemperature 1)"
        );
        assert_eq!(
            tally(&rows, false),
            "3 points; 2 derated; 1 faulted (overtemperature 1)"
        );
        let more = Metrics {
            fault_count: 3,
            ..ran(None, None, Some(2.0))
        };
        assert_eq!(
            more.outcome(true),
            "not converged; faulted: overtemperature at 2.00 s (+2 more)"
        );
        assert_eq!(
            more.outcome(false),
            "faulted: overtemperature at 2.00 s (+2 more)"
        );
        assert_eq!(
            ran(None, None, None).outcome(false),
            "no derating, no fault"
        );
    }

    #[test]
    fn a_heat_map_without_values_says_so_and_keeps_its_legend() {
        let sw = grid(
            &["target_apex=0.05:0.15:3", "spin_up=0.4:1.0:2"],
            "hops_to_converge",
        );
        let rows: Vec<Row> = (0..6)
            .map(|i| Row {
                values: sw.point(i).0,
                metrics: ran(None, Some(9.0), (i % 2 == 1).then_some(12.0)),
            })
            .collect();
        let plot = svg(&sw, &rows);
        let text = words(&plot);
        assert!(
            text.contains(
                "No colour scale: no run has a value of hops to converge (every cell grey)."
            ),
            "{text}"
        );
        assert!(text.contains("did not converge (6)"), "{text}");
        assert!(
            text.contains("faulted (3), first fault: overtemperature 3"),
            "{text}"
        );
        assert!(text.contains("current limit derated (6)"), "{text}");
        // No colour bar: none of its 100 steps, so no bogus 0-1 scale.
        let fill = |c: RGBColor| format!("fill=\"#{:02X}{:02X}{:02X}\"", c.0, c.1, c.2);
        assert!(
            !plot.contains(&fill(viridis(0.5))),
            "a colour bar was drawn"
        );
        assert!(plot.contains(&fill(NO_VALUE)));
        // With values the colour bar is back, and the note is gone.
        let mut rows = rows;
        rows[0].metrics = ran(Some(3), None, None);
        rows[2].metrics = ran(Some(9), None, None);
        let plot = svg(&sw, &rows);
        let text = words(&plot);
        assert!(!text.contains("No colour scale"), "{text}");
        assert!(plot.contains(&fill(viridis(0.5))), "no colour bar");
        assert!(text.contains("did not converge (4)"), "{text}");
        // A whole-number scale: 3 to 9 labelled 3, 4, ... 9, no halves.
        assert!(text.contains(" 3 4 5 6 7 8 9 "), "{text}");
        assert!(!text.contains("6.5"), "{text}");
    }

    #[test]
    fn a_line_plot_marks_faulted_and_derated_points_in_a_side_legend() {
        let sw = grid(&["target_apex=0.05:0.15:3"], DEFAULT_METRIC);
        let rows = on_targets([
            ran(Some(4), None, None),
            ran(None, Some(11.0), None),
            ran(None, Some(8.0), Some(10.0)),
        ]);
        let text = words(&svg(&sw, &rows));
        assert!(text.contains("never steady: last apex shown (2)"), "{text}");
        assert!(
            text.contains("faulted (1), first fault: overtemperature 1"),
            "{text}"
        );
        assert!(text.contains("current limit derated (2)"), "{text}");
        assert!(
            text.contains("no value (no hop), drawn at the bottom (0)"),
            "{text}"
        );
    }

    #[test]
    fn marks_that_repeat_the_plotted_metric_are_left_out() {
        let sw = grid(
            &["target_apex=0.05:0.15:3", "spin_up=0.4:1.0:2"],
            "first_derated_s",
        );
        let m = ran(None, Some(9.0), Some(12.0));
        assert!(!sw.marks_derating(&m) && sw.marks_fault(&m));
        let sw = Sweep {
            metric: "first_fault_s".into(),
            ..sw
        };
        assert!(sw.marks_derating(&m) && !sw.marks_fault(&m));
    }

    #[test]
    fn metrics_round_trip_through_their_values_with_the_fault() {
        for m in [ran(Some(4), None, None), ran(None, Some(11.0), Some(13.5))] {
            assert_eq!(Metrics::from_values(&m.values(), m.first_fault), Some(m));
        }
        let m = ran(None, Some(11.0), Some(13.5));
        // A fault's time without its name, or a name without a count, is
        // not a run's.
        assert_eq!(Metrics::from_values(&m.values(), None), None);
        let none = ran(None, None, None);
        assert_eq!(
            Metrics::from_values(&none.values(), Some("overtemperature")),
            None
        );
        assert_eq!(fault_name("overtemperature"), Some("overtemperature"));
        assert_eq!(fault_name("stroke-limit"), Some("stroke-limit"));
        assert_eq!(fault_name("overheat"), None);
    }

    #[test]
    fn slice_sizes_count_what_each_shard_runs() {
        let sw = grid(
            &["k=8000:14000:7", "start_apex=0.05:0.15:5"],
            DEFAULT_METRIC,
        );
        for count in [1, 2, 3, 4, 35] {
            let sizes = sw.slice_sizes(count).unwrap_or_else(|e| panic!("{e}"));
            let each: Vec<usize> = (1..=count)
                .map(|index| {
                    sw.shard_points(Shard { index, count })
                        .unwrap_or_else(|e| panic!("{e}"))
                        .len()
                })
                .collect();
            assert_eq!(sizes, each, "{count} slices");
            assert_eq!(sizes.iter().sum::<usize>(), 35);
        }
        // A point that cannot run is refused by name.
        let bad = grid(&["start_apex=-0.05:0.15:3"], DEFAULT_METRIC);
        let e = bad.slice_sizes(2).err().unwrap_or_default();
        assert!(
            e.starts_with("sweep point start_apex_m=-0.05: start apex"),
            "{e}"
        );
    }

    #[test]
    fn merge_keeps_faults_and_names_missing_shards_briefly() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let sw = grid(&["target_apex=0.05:0.15:1000"], DEFAULT_METRIC);
        let part = |k: usize, m: Metrics| {
            let shard = Shard {
                index: k,
                count: 1000,
            };
            let i = k - 1;
            let row = Row {
                values: sw.point(i).0,
                metrics: m,
            };
            let out = dir.path().join(format!("part{k}"));
            sw.write_part(shard, &[(i, row)], &out, "t")
                .unwrap_or_else(|e| panic!("{e}"));
            out
        };
        let faulted = ran(None, Some(7.5), Some(9.25));
        let parts = [part(1, ran(Some(3), None, None)), part(2, faulted)];
        let err = merge(&parts).err().unwrap_or_default();
        assert_eq!(
            err,
            "sweep merge: 998 of 1000 shards missing: 3, 4, 5, 6, 7, ... (give every sweep-part directory of the grid)"
        );
        assert!(err.len() < 300);
        // Every shard: the fault's name and time come back as written.
        let all: Vec<PathBuf> = parts
            .into_iter()
            .chain((3..=1000).map(|k| part(k, ran(Some(3), None, None))))
            .collect();
        let (_, rows, _) = merge(&all).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(rows.len(), 1000);
        assert_eq!(rows[1].metrics, faulted);
        assert_eq!(rows[0].metrics, ran(Some(3), None, None));
        // A short list is given whole.
        assert_eq!(
            missing_shards(&[3], 3),
            "sweep merge: 1 of 3 shards missing: 3 (give every sweep-part directory of the grid)"
        );
    }

    #[test]
    fn short_plant_names_sweep_the_full_field() {
        let k = parse_axis("k=8000:20000:13").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(k.knob.column(), "spring_stiffness_n_per_m");
        assert_eq!(k.values.len(), 13);
        assert_eq!(k.values.first(), Some(&8000.0));
        assert_eq!(k.values.get(1), Some(&9000.0));
        assert_eq!(k.values.last(), Some(&20000.0));
        let lead = parse_axis("lead=0.002:0.010:5").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(lead.knob.column(), "screw_lead_m");
        let c = parse_axis("c=0:10:2").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.knob.column(), "spring_damping_ns_per_m");
        // The short name and the full one are the same knob.
        let full = parse_axis("spring_stiffness_n_per_m=1:2:2").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(k.knob.name(), full.knob.name());
        let err = parse_axis("kk=1:2:2").err().unwrap_or_default();
        assert!(err.contains("unknown parameter `kk`"), "{err}");
        assert!(err.contains("k = spring_stiffness_n_per_m"), "{err}");
    }
}
