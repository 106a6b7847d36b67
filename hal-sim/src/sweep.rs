//! Parameter sweeps (`hopper-sim sweep`): a grid of runs around a base
//! scenario, run in parallel on every core, summarised one CSV row per run
//! and plotted (a line for one swept parameter, a heat map for two).
//!
//! A swept parameter is `NAME=START:END:N` (`N` evenly spaced values from
//! `START` to `END`, both included). `NAME` is a plant parameter field
//! ([`crate::params::FIELDS`], e.g. `screw_lead_m`) or a controller setting:
//! `torque`, `target_apex`, `start_apex`, `ke` (energy-law gain),
//! `flight_kp`, `flight_kd` (or their column names, e.g. `torque_nm`).

use crate::csv_out::Shown;
use crate::params::{field, FieldSpec, FIELDS};
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

/// Controller settings a sweep accepts: (short name, column name, knob).
const SETTING_KNOBS: [(&str, &str, Knob); 14] = [
    ("torque", "torque_nm", Knob::Torque),
    ("target_apex", "target_apex_m", Knob::TargetApex),
    ("start_apex", "start_apex_m", Knob::StartApex),
    ("ke", "energy_gain_nm_per_j", Knob::EnergyGain),
    ("flight_kp", "flight_kp_a_per_rad", Knob::FlightKp),
    ("flight_kd", "flight_kd_a_s_per_rad", Knob::FlightKd),
    ("seed", "noise_seed", Knob::Seed),
    (
        "spin_up",
        "shaped_spin_up_fraction",
        Knob::Param(&fw::SHAPED_SPIN_UP_FRACTION),
    ),
    (
        "switch",
        "shaped_switch_fraction",
        Knob::Param(&fw::SHAPED_SWITCH_FRACTION),
    ),
    (
        "brake",
        "shaped_brake_fraction",
        Knob::Param(&fw::SHAPED_BRAKE_FRACTION),
    ),
    (
        "level_ki",
        "shaped_level_gain_per_j",
        Knob::Param(&fw::SHAPED_LEVEL_GAIN),
    ),
    (
        "level_kp",
        "shaped_level_proportional_per_j",
        Knob::Param(&fw::SHAPED_LEVEL_PROPORTIONAL),
    ),
    (
        "braking_margin",
        "shaped_braking_margin",
        Knob::Param(&fw::SHAPED_BRAKING_MARGIN),
    ),
    (
        "integral_start",
        "shaped_integral_start",
        Knob::Param(&fw::SHAPED_INTEGRAL_START),
    ),
];

/// Short names of plant parameters, the thesis's symbols (`k`, `c`: the
/// leg spring's stiffness and damping, section 2.2) and the ball-screw
/// `lead` (Table 2.1), so `--param k=8000:20000:13` works as written.
const PLANT_ALIASES: [(&str, &str); 3] = [
    ("k", "spring_stiffness_n_per_m"),
    ("c", "spring_damping_ns_per_m"),
    ("lead", "screw_lead_m"),
];

impl Knob {
    /// Look a name up: a plant field (or its short name), or a setting's
    /// short or column name.
    pub fn parse(name: &str) -> Option<Knob> {
        let name = PLANT_ALIASES
            .iter()
            .find(|(short, _)| *short == name)
            .map_or(name, |(_, full)| full);
        if let Some(f) = field(name) {
            return Some(Knob::Plant(f));
        }
        SETTING_KNOBS
            .iter()
            .find(|(short, column, _)| *short == name || *column == name)
            .map(|(_, _, k)| *k)
            .or_else(|| match Dedicated::of(name) {
                // The table's names for settings with a knob of their own.
                Some(Dedicated::TargetApex) => Some(Knob::TargetApex),
                Some(Dedicated::FlightKp) => Some(Knob::FlightKp),
                Some(Dedicated::FlightKd) => Some(Knob::FlightKd),
                Some(Dedicated::Torque) => Some(Knob::Torque),
                Some(Dedicated::EnergyGain) => Some(Knob::EnergyGain),
                Some(Dedicated::Controller) => None,
                None => fw::find(name).map(Knob::Param),
            })
    }

    /// CSV column name (with its unit).
    pub fn column(&self) -> &'static str {
        match self {
            Knob::Plant(f) => f.name,
            // A table parameter without a column of its own is named as in
            // the table.
            Knob::Param(p) => SETTING_KNOBS
                .iter()
                .find(|(_, _, k)| k.same(self))
                .map_or(p.name, |(_, column, _)| column),
            other => SETTING_KNOBS
                .iter()
                .find(|(_, _, k)| k.same(other))
                .map_or("?", |(_, column, _)| column),
        }
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

    /// Whether two knobs change the same setting.
    fn same(&self, other: &Knob) -> bool {
        match (self, other) {
            (Knob::Param(a), Knob::Param(b)) => a.name == b.name,
            (Knob::Plant(a), Knob::Plant(b)) => a.name == b.name,
            (a, b) => std::mem::discriminant(a) == std::mem::discriminant(b),
        }
    }

    /// Why sweeping this knob would change nothing for `controller`, if so.
    fn unused_by(&self, controller: ControllerKind) -> Option<&'static str> {
        use ControllerKind as C;
        match self {
            Knob::Param(p) if !param_applies(p, controller) => Some(crate::controller::owner_of(p)),
            Knob::Torque if !matches!(controller, C::OpenTorque | C::ModifiedTorque) => {
                Some("open-torque and modified-torque")
            }
            Knob::EnergyGain if !matches!(controller, C::Energy | C::EnergyApex) => {
                Some("energy and energy-apex")
            }
            Knob::FlightKp | Knob::FlightKd if controller == C::Shaped => {
                Some("the controllers with the flight PD (every one but passive and shaped)")
            }
            Knob::FlightKp | Knob::FlightKd | Knob::TargetApex if controller == C::Passive => {
                Some("every controller but passive")
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
        let settings: Vec<&str> = SETTING_KNOBS.iter().map(|(s, _, _)| *s).collect();
        let short: Vec<String> = PLANT_ALIASES
            .iter()
            .map(|(s, full)| format!("{s} = {full}"))
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
}

/// Metric columns, in CSV order, with the label plots use.
pub const METRICS: [(&str, &str); 12] = [
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
];

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
        }
    }

    /// From its values in [`METRICS`] order, as [`Metrics::values`] gives
    /// them (a merged shard's CSV row); None when a count is not a whole
    /// number or a value that is always defined is missing.
    pub fn from_values(v: &[Option<f64>; METRICS.len()]) -> Option<Metrics> {
        let count = |x: Option<f64>| -> Option<usize> {
            let x = x?;
            (x >= 0.0 && x.fract() == 0.0 && x <= usize::MAX as f64).then_some(x as usize)
        };
        let [steady, converge, last, hops, work, impact, per_stance, first_work, current, stroke, faults, first_apex] =
            *v;
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
        ]
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

/// What a shard's directory says about the grid it is a slice of: what
/// `sweep merge` needs to check the parts belong together and to draw the
/// plots of the whole.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PartManifest {
    /// Layout version (1).
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
        let c = dir.join(PART_CSV);
        let csv = std::fs::read_to_string(&c).map_err(|e| format!("{}: {e}", c.display()))?;
        Ok((manifest, csv))
    };
    let (first, _) = read(first_dir)?;
    if first.format != 1 {
        return Err(format!(
            "{}: part format {}, this hopper-sim reads 1",
            first_dir.display(),
            first.format
        ));
    }
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
            return Err(format!(
                "{}: columns {got:?}, not {header:?}",
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
            let metrics = Metrics::from_values(&metrics)
                .ok_or_else(|| format!("{}: a metric is missing or not a count", at()))?;
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
    let missing: Vec<String> = seen
        .iter()
        .enumerate()
        .filter(|(_, s)| !**s)
        .map(|(i, _)| format!("{}/{}", i + 1, first.of))
        .collect();
    if !missing.is_empty() {
        return Err(format!(
            "sweep merge: missing shards {}",
            missing.join(", ")
        ));
    }
    let rows = rows
        .into_iter()
        .enumerate()
        .map(|(i, r)| r.ok_or_else(|| format!("sweep merge: grid point {i} is in no part")))
        .collect::<Result<Vec<Row>, String>>()?;
    Ok((sweep, rows, first.title))
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
            format: 1,
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
            let cells: Vec<Option<Shown>> = i
                .map(|i| Shown(i as f64))
                .into_iter()
                .map(Some)
                .chain(r.values.iter().map(|&v| Some(Shown(v))))
                .chain(r.metrics.values().iter().map(|m| m.map(Shown)))
                .collect();
            out.serialize(cells).map_err(failed)?;
        }
        let bytes = out
            .into_inner()
            .map_err(|e| format!("cannot format sweep.csv: {}", e.error()))?;
        String::from_utf8(bytes).map_err(|e| format!("cannot format sweep.csv: {e}"))
    }

    /// The plotted value of a row: the metric, except that the default
    /// metric falls back to the last apex where the run never became steady.
    /// The flag says a fallback was used.
    pub fn plotted(&self, m: &Metrics) -> Option<(f64, bool)> {
        match m.get(&self.metric) {
            Some(v) => Some((v, false)),
            None if self.metric == DEFAULT_METRIC => m.last_apex_m.map(|v| (v, true)),
            None => None,
        }
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
        let res = match self.axes.len() {
            1 => self.line_plot(&root, rows, title),
            _ => self.heat_map(&root, rows, title),
        };
        res.and_then(|()| root.present().map_err(Into::into))
            .map_err(|e| format!("cannot draw the sweep plot: {e}"))
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
        title: &str,
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let pts: Vec<(f64, f64, bool)> = rows
            .iter()
            .filter_map(|r| self.plotted(&r.metrics).map(|(v, fb)| (r.values[0], v, fb)))
            .collect();
        let (x_lo, x_hi) = padded(self.axes[0].values.iter().copied(), 0.03);
        let (y_lo, y_hi) = padded(pts.iter().map(|p| p.1), 0.08);
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 20))
            .margin(16)
            .margin_top(24)
            .x_label_area_size(48)
            .y_label_area_size(80)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
        chart
            .configure_mesh()
            .x_desc(self.axes[0].knob.column())
            .y_desc(self.metric_label())
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        chart.draw_series(LineSeries::new(
            pts.iter().map(|p| (p.0, p.1)),
            BLUE.stroke_width(2),
        ))?;
        chart
            .draw_series(
                pts.iter()
                    .filter(|p| !p.2)
                    .map(|p| Circle::new((p.0, p.1), 5, BLUE.filled())),
            )?
            .label(self.metric_label())
            .legend(|(x, y)| Circle::new((x + 10, y), 5, BLUE.filled()));
        if pts.iter().any(|p| p.2) {
            chart
                .draw_series(
                    pts.iter()
                        .filter(|p| p.2)
                        .map(|p| Cross::new((p.0, p.1), 6, RED.stroke_width(2))),
                )?
                .label("last apex (never steady)")
                .legend(|(x, y)| Cross::new((x + 10, y), 6, RED.stroke_width(2)));
        }
        crate::plot::legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        Ok(())
    }

    fn heat_map<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        rows: &[Row],
        title: &str,
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let (main, bar) = root.split_horizontally(PLOT_SIZE.0 - 150);
        let xe = cell_edges(&self.axes[0].values);
        let ye = cell_edges(&self.axes[1].values);
        let range = |e: &[f64]| {
            e.iter()
                .fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(*v), b.max(*v)))
        };
        let ((x_lo, x_hi), (y_lo, y_hi)) = (range(&xe), range(&ye));
        let vals: Vec<Option<(f64, bool)>> =
            rows.iter().map(|r| self.plotted(&r.metrics)).collect();
        let (v_lo, v_hi) = vals
            .iter()
            .flatten()
            .fold((f64::MAX, f64::MIN), |(a, b), (v, _)| {
                (a.min(*v), b.max(*v))
            });
        let (v_lo, v_hi) = if v_lo > v_hi {
            (0.0, 1.0)
        } else if v_hi - v_lo < 1e-12 {
            (v_lo - 0.5, v_hi + 0.5)
        } else {
            (v_lo, v_hi)
        };
        let mut chart = ChartBuilder::on(&main)
            .caption(title, ("sans-serif", 20))
            .margin(16)
            .margin_top(24)
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
        let n1 = self.axes[1].values.len();
        chart.draw_series(rows.iter().zip(&vals).enumerate().map(|(k, (_, v))| {
            let (i, j) = (k / n1, k % n1);
            let color = match v {
                Some((v, _)) => viridis((v - v_lo) / (v_hi - v_lo)),
                None => RGBColor(200, 200, 200),
            };
            Rectangle::new([(xe[i], ye[j]), (xe[i + 1], ye[j + 1])], color.filled())
        }))?;
        // Runs that never became steady, plotted with their last apex.
        chart.draw_series(rows.iter().zip(&vals).filter_map(|(r, v)| match v {
            Some((_, true)) => Some(Cross::new(
                (r.values[0], r.values[1]),
                5,
                WHITE.stroke_width(2),
            )),
            _ => None,
        }))?;
        if vals.iter().flatten().any(|(_, fallback)| *fallback) {
            chart
                .draw_series(std::iter::once(Cross::new(
                    (x_lo, y_lo),
                    0,
                    WHITE.stroke_width(2),
                )))?
                .label("x: never steady, last apex shown")
                .legend(|(x, y)| Cross::new((x + 8, y), 5, BLACK.stroke_width(2)));
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font(("sans-serif", 14))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()?;
        }
        let mut scale = ChartBuilder::on(&bar)
            .margin_top(60)
            .margin_bottom(64)
            .margin_right(8)
            .y_label_area_size(100)
            .build_cartesian_2d(0.0..1.0, v_lo..v_hi)?;
        scale
            .configure_mesh()
            .disable_x_axis()
            .disable_mesh()
            .y_desc(self.metric_label())
            .y_label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 15))
            .draw()?;
        const STEPS: usize = 100;
        scale.draw_series((0..STEPS).map(|k| {
            let a = v_lo + (v_hi - v_lo) * k as f64 / STEPS as f64;
            let b = v_lo + (v_hi - v_lo) * (k + 1) as f64 / STEPS as f64;
            Rectangle::new(
                [(0.0, a), (1.0, b)],
                viridis(k as f64 / STEPS as f64).filled(),
            )
        }))?;
        Ok(())
    }
}

/// Plot size, pixels.
const PLOT_SIZE: (u32, u32) = (1000, 700);

/// Value range with `frac` of its span added on each side (never empty).
fn padded(values: impl Iterator<Item = f64>, frac: f64) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
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

/// The viridis colour map at `t` in 0..=1 (plotters' `ViridisRGB`).
fn viridis(t: f64) -> RGBColor {
    // plotters clamps into 0..=1 but turns a NaN into an index and panics:
    // a point whose metric cannot be normalised gets the low end instead.
    let t = if t.is_finite() { t } else { 0.0 };
    ViridisRGB::get_color(t)
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
        assert!(k.knob.same(&full.knob));
        let err = parse_axis("kk=1:2:2").err().unwrap_or_default();
        assert!(err.contains("unknown parameter `kk`"), "{err}");
        assert!(err.contains("k = spring_stiffness_n_per_m"), "{err}");
    }
}
