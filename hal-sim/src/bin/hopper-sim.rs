//! `hopper-sim`: run the vertical hopper in simulation, print parameter sets.
//!
//! ```text
//! hopper-sim run [--params design|identified|PATH.toml] [--controller NAME]
//!                [--target-apex M] [--torque NM] [--noise off|default] [--seed N]
//!                [--start-apex M] [--duration S] [--out DIR] [--json]
//!                [--scenario FILE] [--inject KIND@TIME ...]   (flags override the file)
//! hopper-sim sweep --param NAME=START:END:N [--param ...] [--metric NAME]
//!                  [--scenario FILE | --preset lead-study | run's flags] --out DIR
//! hopper-sim params show design|identified
//! hopper-sim figures --out DIR
//! ```

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use hal_sim::inject::Injection;
use hal_sim::params::Params;
use hal_sim::params_toml;
use hal_sim::run;
use hal_sim::scenario::{self, Overrides, Scenario, Settings};
use hal_sim::sweep::{self, Sweep};
use hopper_control::laws::ControllerKind;
use std::path::PathBuf;

/// `println!` that hands a write error to the caller (`?`) instead of
/// panicking, so that a closed stdout (`hopper-sim run | head`) ends the
/// command quietly (see [`is_closed_pipe`]).
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)?
    }};
}

/// [`say!`] without the newline.
macro_rules! say_raw {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        write!(std::io::stdout().lock(), $($arg)*)?
    }};
}

#[derive(Parser)]
#[command(
    name = "hopper-sim",
    version,
    about = "Simulate the electrically actuated one-legged hopper (vertical model, thesis ch. 2.1)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Drop the hopper from a start apex and run a controller; prints a summary.
    Run(RunArgs),
    /// Run a grid of runs (one or two swept parameters) in parallel; writes
    /// sweep.csv and a plot (sweep.png, sweep.svg).
    Sweep(SweepArgs),
    /// The virtual robot: the firmware on the simulated hopper behind the
    /// link protocol on a TCP socket, in real time, for `hopper-link`
    /// (docs/link.md). It boots disarmed and standing, like the board.
    Serve(ServeArgs),
    /// Design a leg spring (thesis section 3.2, eqs 3.1-3.7): coils,
    /// pitch, lengths, stresses, allowable forces and stroke; optionally
    /// checked against the peak spring force of a simulated hop.
    Spring(SpringArgs),
    /// The actuator studies of thesis section 3.1 on the motor's own
    /// torque-speed curve (docs/design.md): `motors` (Table 3.1) and
    /// `leads` (Figures 3.1-3.3).
    Design {
        #[command(subcommand)]
        cmd: DesignCmd,
    },
    /// Identify plant parameters from a recorded hop (thesis section 4.5):
    /// a passive hop gives the planarizer and leg friction, an open-torque
    /// hop the effective stance torque and the nut mass (docs/design.md).
    Identify(IdentifyArgs),
    /// The planar one-legged runner of thesis section 2.2 (Table 2.2,
    /// passive dynamics and the forward-speed stabiliser of eq 2.79).
    Planar {
        #[command(subcommand)]
        cmd: PlanarCmd,
    },
    /// Parameter sets.
    Params {
        #[command(subcommand)]
        cmd: ParamsCmd,
    },
    /// Regenerate the simulation counterparts of the thesis's Figures 2.4-2.13
    /// and 4.4-4.9 as PNG and SVG (see docs/thesis-comparison.md).
    Figures {
        /// Directory for fig-2-4.png, fig-2-4.svg, ... (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Short runs (0.3 s of hopping) for quick checks.
        #[arg(long, hide = true)]
        quick: bool,
    },
}

/// `hopper-sim spring`: the thesis's worked example by default.
#[derive(Args)]
struct SpringArgs {
    /// Spring rate, N/m.
    #[arg(long, default_value_t = 10_000.0, value_name = "N_PER_M")]
    stiffness_n_per_m: f64,
    /// Wire material (Table 3.2): music-wire, oil-tempered, hard-drawn,
    /// chrome-vanadium, chrome-silicon.
    #[arg(long, default_value = "music-wire", value_parser = clap::builder::PossibleValuesParser::new(
        hal_sim::spring::MATERIALS.map(|m| m.name)
    ))]
    material: String,
    /// Wire diameter, mm.
    #[arg(long, default_value_t = 5.53, value_name = "MM")]
    wire_mm: f64,
    /// Outer coil diameter, mm.
    #[arg(long, default_value_t = 52.0, value_name = "MM")]
    outer_mm: f64,
    /// Free length, mm.
    #[arg(long, default_value_t = 235.0, value_name = "MM")]
    free_length_mm: f64,
    /// The longest solid length allowed, mm [default: no limit].
    #[arg(long, value_name = "MM")]
    max_solid_mm: Option<f64>,
    /// The shortest allowable stroke required, mm.
    #[arg(long, default_value_t = 100.0, value_name = "MM")]
    min_stroke_mm: f64,
    /// Also run a hop on the design machine with this spring (its rate with
    /// whole coils): the shaped controller from 0.05 m to this apex, 10 s,
    /// and compare its peak spring force with the allowable forces.
    #[arg(long, value_name = "APEX_M")]
    check_hop: Option<f64>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// `hopper-sim identify`.
#[derive(Args)]
struct IdentifyArgs {
    /// The log's directory: trajectory.csv (`hopper-sim run --out`) or
    /// telemetry.csv (`hopper-link record`), starting at the release from
    /// rest.
    #[arg(long, value_name = "DIR")]
    log: PathBuf,
    /// What the recorded hop was: passive (fits planarizer_friction_n and
    /// leg_friction_n) or open-torque (fits current_limit_a, the effective
    /// stance torque over k_t, and nut_mass_kg).
    #[arg(long, default_value = "passive", value_parser = ["passive", "open-torque"])]
    experiment: String,
    /// The torque the open-torque hop commanded, N m.
    #[arg(long, default_value_t = 1.0)]
    torque: f64,
    /// What is known of the machine: a preset or a TOML file (the fit
    /// starts from its values and keeps the rest) [default: design].
    #[arg(long)]
    params: Option<String>,
    /// Directory for identify.png and identify.svg: measured against fitted.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print the estimates as JSON under the parameter files' field names.
    #[arg(long)]
    json: bool,
}

/// Appendix A's terms on Table 2.2's runner (`--model appendix-a`).
#[derive(clap::Args)]
struct AppendixArgs {
    /// Appendix A: the trunk's centre ahead of the hip (body frame), m.
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    trunk_offset_x: Option<f64>,
    /// Appendix A: the trunk's centre above the hip (body frame), m.
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    trunk_offset_z: Option<f64>,
    /// Appendix A: the leg's centre from the hip along the leg, m.
    #[arg(long, value_name = "M")]
    leg_com: Option<f64>,
    /// Appendix A: the unsprung mass at the toe, kg.
    #[arg(long, value_name = "KG")]
    toe_mass: Option<f64>,
    /// Appendix A: the leg spring's damper, N s/m.
    #[arg(long, value_name = "NS_PER_M")]
    leg_damping: Option<f64>,
    /// Appendix A: the hip spring's damper, N m s/rad.
    #[arg(long, value_name = "NMS_PER_RAD")]
    hip_damping: Option<f64>,
    /// Appendix A: planarizer dry friction on the hip's motion, N.
    #[arg(long, value_name = "N")]
    planarizer_friction: Option<f64>,
    /// Appendix A: dry friction on the leg's sliding in stance, N.
    #[arg(long, value_name = "N")]
    leg_friction: Option<f64>,
    /// Appendix A: dry friction torque at the hip, N m.
    #[arg(long, value_name = "NM")]
    hip_friction: Option<f64>,
}

impl AppendixArgs {
    /// The runner `--model` names, with these terms; each term refused by
    /// its flag when out of range or given without `--model appendix-a`.
    fn model(&self, name: &str) -> Result<hal_sim::planar_sim::Model> {
        use hopper_plant::planar::{PlanarError, PlanarParams};
        use hopper_plant::planar_general::{GeneralParams, TERM_LIMITS};
        type Set = fn(&mut GeneralParams, f64);
        let terms: [(&str, &str, Option<f64>, Set); 9] = [
            (
                "--trunk-offset-x",
                "trunk_offset_x_m",
                self.trunk_offset_x,
                |p, v| p.trunk_offset_x_m = v,
            ),
            (
                "--trunk-offset-z",
                "trunk_offset_z_m",
                self.trunk_offset_z,
                |p, v| p.trunk_offset_z_m = v,
            ),
            ("--leg-com", "leg_com_from_hip_m", self.leg_com, |p, v| {
                p.leg_com_from_hip_m = v
            }),
            ("--toe-mass", "toe_mass_kg", self.toe_mass, |p, v| {
                p.toe_mass_kg = v
            }),
            (
                "--leg-damping",
                "leg_damping_ns_per_m",
                self.leg_damping,
                |p, v| p.leg_damping_ns_per_m = v,
            ),
            (
                "--hip-damping",
                "hip_damping_nms_per_rad",
                self.hip_damping,
                |p, v| p.hip_damping_nms_per_rad = v,
            ),
            (
                "--planarizer-friction",
                "planarizer_friction_n",
                self.planarizer_friction,
                |p, v| p.planarizer_friction_n = v,
            ),
            (
                "--leg-friction",
                "leg_friction_n",
                self.leg_friction,
                |p, v| p.leg_friction_n = v,
            ),
            (
                "--hip-friction",
                "hip_friction_nm",
                self.hip_friction,
                |p, v| p.hip_friction_nm = v,
            ),
        ];
        if name != "appendix-a" {
            if let Some((flag, ..)) = terms.iter().find(|t| t.2.is_some()) {
                bail!("{flag} is an Appendix A term: it needs --model appendix-a");
            }
            return Ok(hal_sim::planar_sim::Model::Section22);
        }
        let mut g = GeneralParams::from_section_2_2(&PlanarParams::table_2_2());
        for (_, _, v, set) in &terms {
            if let Some(v) = v {
                set(&mut g, *v);
            }
        }
        if let Err(PlanarError::NotPositive(f) | PlanarError::OutOfRange(f)) = g.validate() {
            let flag = terms.iter().find(|t| t.1 == f).map_or(f, |t| t.0);
            let value = terms
                .iter()
                .find(|t| t.1 == f)
                .and_then(|t| t.2)
                .map_or(String::new(), |v| format!(" {v}"));
            let range = TERM_LIMITS.iter().find(|l| l.field == f).map_or(
                String::from("out of range"),
                |l| {
                    // The leg's centre must also lie on the leg.
                    let max = if f == "leg_com_from_hip_m" {
                        l.max.min(g.leg_length_m)
                    } else {
                        l.max
                    };
                    format!("must be within {} ..= {} {}", l.min, max, l.unit)
                },
            );
            bail!("{flag}{value} {range}");
        }
        Ok(hal_sim::planar_sim::Model::AppendixA(g))
    }
}

#[derive(Subcommand)]
enum PlanarCmd {
    /// Run from the passive design's apex (T_step 0.5 s, rho 0.125): the
    /// apexes, their drift from the design's, what the touchdowns took.
    Run {
        /// Running speed, m/s.
        #[arg(long, default_value_t = 2.0)]
        speed: f64,
        /// The stabiliser's gain K_c (eq 2.79), N s/m; 0: passive.
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        kc: f64,
        /// Simulated time, s.
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// Start from the passive design's apex (eqs 2.76-2.78) or from the
        /// gait's fixed point of the apex return map (`planar stability`).
        #[arg(long, value_parser = ["design", "fixed-point"], default_value = "design")]
        start: String,
        /// The runner: section-2-2 (Table 2.2) or appendix-a (Table 2.2
        /// with Appendix A's terms, set by the flags below; all zero by
        /// default, which is the section 2.2 runner again).
        #[arg(long, value_parser = ["section-2-2", "appendix-a"], default_value = "section-2-2")]
        model: String,
        #[command(flatten)]
        appendix: AppendixArgs,
        /// Directory for trajectory.csv (every millisecond) and
        /// run.png/.svg (created if missing).
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Figures 2.18-2.22 (fig-2-18.png/.svg ...) into DIR.
    Figures {
        /// Directory (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
    /// The apex return map: each gait's fixed point by Newton iteration
    /// and how much a deviation grows per hop (the largest |eigenvalue| of
    /// the map's Jacobian off the energy family), over speeds x K_c.
    Stability {
        /// Speeds, m/s (comma-separated).
        #[arg(long, value_delimiter = ',', default_values_t = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0])]
        speeds: Vec<f64>,
        /// Stabiliser gains K_c, N s/m (comma-separated; 0 is passive).
        #[arg(long, allow_hyphen_values = true, value_delimiter = ',', default_values_t = [-1000.0, -500.0, 0.0, 250.0, 500.0, 750.0, 1000.0, 1250.0, 1500.0, 2000.0, 2500.0, 3000.0])]
        kc: Vec<f64>,
        /// Directory for stability.csv and stability.png/.svg.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Subcommand)]
enum DesignCmd {
    /// Table 3.1: the energy each candidate motor adds in the first stance
    /// (k = 10 kN/m, 5 mm lead), at the table's stall torque and, where a
    /// catalogue motor was found, with its datasheet constants.
    Motors {
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Figures 3.1-3.3: the design motor on its torque-speed curve through
    /// leads of 2 ..= 10 mm (k = 10 kN/m): the energy added in the first
    /// stance, the first apex, and with --out the plots.
    Leads {
        /// Directory for lead-study.png and lead-study.svg (created if
        /// missing).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// The machine that would hop: the smallest single change (friction,
    /// torque limit, lead, spring rate, preload) that makes the identified
    /// machine hold a 5 cm hop under shaped and under open-loop torque, and
    /// with --out the feasibility map over friction and torque limit.
    WouldHop {
        /// Directory for feasibility.png and feasibility.svg.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Subcommand)]
enum ParamsCmd {
    /// Print a preset as TOML that `--params PATH.toml` accepts.
    Show {
        /// Preset: design | identified
        preset: String,
    },
}

/// The settings of one run, shared by `run` and `sweep`. Each is an
/// `Option` so that a scenario file's value survives when the flag is not
/// given; the defaults live in `hal_sim::scenario` and apply when neither
/// sets a value.
#[derive(Args)]
struct BaseArgs {
    /// Scenario file (TOML: plant, controller, sensors, start apex,
    /// duration; see scenarios/). Flags given as well override it.
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Plant parameters: a preset (design: Table 2.1, no preload, and Table
    /// 2.1's flight PD for the Chapter 2 laws; identified: section 4.5) or a
    /// TOML file (`base = "design"` brings the design preset's flight PD
    /// too) [default: design].
    #[arg(long)]
    params: Option<String>,
    /// What the controller believes, separately from the plant (`--params`):
    /// a preset or a TOML file [default: the plant's parameters]. Try model
    /// error, e.g. a file with `base = "design"` and
    /// `spring_stiffness_n_per_m = 13200`.
    #[arg(long, value_name = "PRESET|PATH.toml")]
    model_params: Option<String>,
    /// Controller: passive, step-open, step-closed, open-torque, energy,
    /// energy-apex (apex-regulating energy law), velocity, modified-torque,
    /// shaped (docs/beat-the-thesis.md).
    /// Each is the firmware's control crate on the simulated sensors
    /// [default: passive].
    #[arg(long, value_parser = parse_controller)]
    controller: Option<ControllerKind>,
    /// Desired apex (toe height) H_D, m; sets the energy target E_D
    /// [default: 0.05].
    #[arg(long, allow_negative_numbers = true)]
    target_apex: Option<f64>,
    /// Motor torque for open-torque and modified-torque, N m (default 1.0).
    #[arg(long, allow_negative_numbers = true)]
    torque: Option<f64>,
    /// Energy-law gain K_e for energy and energy-apex, N m/J (default: the
    /// law's, 0.2 for energy, 3 for energy-apex).
    #[arg(long, allow_negative_numbers = true)]
    ke: Option<f64>,
    /// Flight PD proportional gain, A/rad (default: eq 4.13, 20.3152; with
    /// the design preset the Chapter 2 laws (step-open, step-closed,
    /// open-torque, energy, velocity) run Table 2.1's 8e4 N/m on the nut,
    /// 1.8953 A/rad).
    #[arg(long, allow_negative_numbers = true)]
    flight_kp: Option<f64>,
    /// Flight PD derivative gain, A s/rad (default: eq 4.13, 0.6077; the
    /// Chapter 2 laws on the design preset: Table 2.1's 300 N s/m on the
    /// nut, 0.0071073 A s/rad).
    #[arg(long, allow_negative_numbers = true)]
    flight_kd: Option<f64>,
    /// Sensor noise: default (load cell 2 N, potentiometer 0.1 mm, 1 sigma)
    /// or off [default: default].
    #[arg(long, value_parser = ["default", "off"])]
    noise: Option<String>,
    /// Seed of the sensor noise (same seed, same run) [default: 1].
    #[arg(long)]
    seed: Option<u64>,
    /// Start toe height above the ground (released at rest), m [default: 0.15].
    #[arg(long, allow_negative_numbers = true)]
    start_apex: Option<f64>,
    /// Simulated time, s [default: 5].
    #[arg(long, allow_negative_numbers = true)]
    duration: Option<f64>,
    /// Control rate, Hz [default: 10000].
    #[arg(long)]
    control_hz: Option<f64>,
    /// Inject a fault, KIND@TIME (s); repeatable. KIND: encoder-jump,
    /// encoder-frozen, loadcell-stuck, loadcell-saturated, pot-open, nan,
    /// noise-burst, estop, amp-fault, dac-error, overrun (docs/safety.md).
    /// Replaces the scenario file's `inject` list.
    #[arg(long = "inject", value_name = "KIND@TIME")]
    inject: Vec<String>,
    /// Set a firmware parameter by its name in the parameter table
    /// (docs/parameters.md), e.g. `--set shaped.switch_fraction=0.5`;
    /// repeatable, applied after every other setting.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
}

/// `--controller NAME`: one of the firmware's controllers, by name.
fn parse_controller(name: &str) -> std::result::Result<ControllerKind, String> {
    ControllerKind::from_name(name).ok_or_else(|| {
        format!(
            "unknown controller `{name}`: expected one of {:?}",
            hal_sim::controller::CONTROLLER_NAMES
        )
    })
}

impl BaseArgs {
    /// The flags that were given, as overrides.
    fn overrides(&self) -> Result<Overrides> {
        Ok(Overrides {
            plant: match &self.params {
                Some(p) => Some(params_toml::load(p).map_err(anyhow::Error::msg)?),
                None => None,
            },
            model: match &self.model_params {
                Some(p) => Some(
                    params_toml::load_as(p, "--model-params")
                        .map_err(|e| match e.location.as_str() {
                            "--model-params" => anyhow::anyhow!("{e}"),
                            _ => anyhow::anyhow!("--model-params {e}"),
                        })?
                        .params,
                ),
                None => None,
            },
            controller: self.controller,
            target_apex_m: self.target_apex,
            torque_nm: self.torque,
            energy_gain_nm_per_j: self.ke,
            flight_kp_a_per_rad: self.flight_kp,
            flight_kd_a_s_per_rad: self.flight_kd,
            noise: self.noise.as_deref().map(|n| n == "default"),
            seed: self.seed,
            start_apex_m: self.start_apex,
            duration_s: self.duration,
            control_hz: self.control_hz,
            inject: if self.inject.is_empty() {
                None
            } else {
                Some(
                    self.inject
                        .iter()
                        .map(|spec| Injection::parse(spec))
                        .collect::<Result<Vec<_>, _>>()
                        .map_err(anyhow::Error::msg)?,
                )
            },
            firmware_params: if self.set.is_empty() {
                None
            } else {
                Some(
                    self.set
                        .iter()
                        .map(|spec| hal_sim::scenario::parse_param_setting(spec))
                        .collect::<Result<Vec<_>, _>>()
                        .map_err(anyhow::Error::msg)?,
                )
            },
            ..Overrides::default()
        })
    }

    /// The scenario file, if one was given.
    fn scenario(&self) -> Result<Option<Scenario>> {
        self.scenario
            .as_deref()
            .map(scenario::load)
            .transpose()
            .map_err(anyhow::Error::msg)
    }
}

/// Flags over the scenario's settings over the defaults.
fn resolve(file: Option<&Scenario>, base: &BaseArgs) -> Result<Settings> {
    let cli = base.overrides()?;
    Ok(Settings::resolve(file.map(|s| &s.settings), &cli))
}

#[derive(Parser)]
struct RunArgs {
    #[command(flatten)]
    base: BaseArgs,
    /// Trajectory sample rate for the CSV and plot, Hz.
    #[arg(long, default_value_t = 1000.0)]
    sample_hz: f64,
    /// Directory for trajectory.csv and hop.png (created if missing).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print exactly one JSON object (the summary) on stdout.
    #[arg(long)]
    json: bool,
    /// Print the per-hop energy ledger (motor work, friction, touchdown,
    /// liftoff and stop-impact losses, actuator energy left at the apex) as
    /// a table. The JSON summary always has it (`hop_ledger`, `steady_hop`).
    #[arg(long)]
    ledger: bool,
}

#[derive(Parser)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
struct SweepArgs {
    /// `merge`: combine the parts of a sharded sweep.
    #[command(subcommand)]
    cmd: Option<SweepCmd>,
    #[command(flatten)]
    base: BaseArgs,
    /// A swept parameter, NAME=START:END:N (N values from START to END);
    /// repeat for a second one. NAME: a plant parameter (e.g. screw_lead_m)
    /// or torque, target_apex, start_apex, ke, flight_kp, flight_kd, seed
    /// (the noise seed: the same run under different noise), and for the
    /// shaped controller spin_up, switch, brake, level_ki, level_kp,
    /// braking_margin, integral_start.
    #[arg(long = "param")]
    param: Vec<String>,
    /// A named sweep instead of --scenario: lead-study (thesis Figures
    /// 3.1-3.3, the energy the motor adds in the first stance against the
    /// ball-screw lead).
    #[arg(long, conflicts_with = "scenario")]
    preset: Option<String>,
    /// Metric to plot: a sweep.csv column [default: the scenario's, else
    /// steady_apex_m, falling back to the last apex where not steady].
    #[arg(long)]
    metric: Option<String>,
    /// Run only slice K of N of the grid (1 <= K <= N: diagonal stripes,
    /// the points whose row and last-axis indexes sum to K-1 modulo N, so
    /// that every slice gets values of both axes) and write its part (sweep-part.csv and
    /// sweep-part.json) into --out; `sweep merge` combines the N parts into
    /// the sweep.csv and plots of the whole grid (docs/design.md, "Sweeps
    /// past one machine").
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
    /// Directory for sweep.csv, sweep.png and sweep.svg (created if missing).
    #[arg(long, required = true)]
    out: Option<PathBuf>,
}

#[derive(Subcommand)]
enum SweepCmd {
    /// Combine the parts of a sharded sweep (`sweep --shard K/N --out
    /// PART_DIR`, every K of the same N) into the sweep.csv and plots an
    /// unsharded run of the grid writes.
    Merge {
        /// The parts' directories, in any order.
        #[arg(required = true, value_name = "PART_DIR")]
        parts: Vec<PathBuf>,
        /// Directory for sweep.csv, sweep.png and sweep.svg (created if
        /// missing).
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(Parser)]
struct ServeArgs {
    #[command(flatten)]
    base: BaseArgs,
    /// Address to listen on, HOST:PORT (port 0: any free port; the address
    /// taken is printed).
    #[arg(long, value_name = "HOST:PORT")]
    tcp: String,
    /// Robot seconds per wall second (the host's heartbeats must still come
    /// within the 0.2 s link timeout of robot time: up to about 4 with
    /// hopper-link's 20 ms heartbeat).
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Stop after this much robot time, s [default: run until killed].
    #[arg(long = "for", value_name = "SECONDS")]
    limit: Option<f64>,
    /// A mis-calibrated load cell: it reads this much beyond the true
    /// spring force, N (for `hopper-link calibrate tare`).
    #[arg(long, default_value_t = 0.0, value_name = "N")]
    loadcell_bias_n: f64,
    /// A mis-calibrated potentiometer: it reads this much beyond the true
    /// leg compression, m.
    #[arg(long, default_value_t = 0.0, value_name = "M")]
    pot_bias_m: f64,
    /// Where the nut really is at boot, m below its upper stop (the
    /// firmware's incremental motor encoder takes it for 0: for
    /// `hopper-link calibrate home`).
    #[arg(long, default_value_t = 0.0, value_name = "M")]
    nut_start_m: f64,
    /// The real spring's rate off the configured one by this fraction, e.g.
    /// 0.15 (for `hopper-link calibrate spring`).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    spring_rate_error: f64,
    /// The firmware takes the boot height for this much more than it is, m
    /// (for `hopper-link calibrate height`).
    #[arg(
        long,
        default_value_t = 0.0,
        allow_negative_numbers = true,
        value_name = "M"
    )]
    height_zero_error_m: f64,
    /// A load cell whose gain is off by this fraction: it reads `F (1 + e)`
    /// for a spring force `F`, e.g. -0.05 reads 5% low (for `hopper-link
    /// calibrate weight`).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    loadcell_gain_error: f64,
    /// Keep the robot's flash in FILE (created on the first `hopper-link
    /// save`): a saved calibration then loads at the next start, as on a
    /// board [default: a flash that lasts as long as the simulator].
    #[arg(long, value_name = "FILE")]
    flash: Option<std::path::PathBuf>,
}

fn main() {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => bad_command_line(e),
    };
    let result = match cli.cmd {
        Cmd::Run(args) => cmd_run(args),
        Cmd::Sweep(args) => cmd_sweep(args),
        Cmd::Serve(args) => cmd_serve(args),
        Cmd::Params {
            cmd: ParamsCmd::Show { preset },
        } => cmd_params_show(&preset),
        Cmd::Figures { out, quick } => cmd_figures(&out, quick),
        Cmd::Spring(args) => cmd_spring(&args),
        Cmd::Design { cmd } => cmd_design(&cmd),
        Cmd::Identify(args) => cmd_identify(&args),
        Cmd::Planar { cmd } => cmd_planar(&cmd),
    };
    if let Err(e) = result {
        if is_closed_pipe(&e) {
            // The reader has all it wanted (`| head`): not an error, as for
            // any Unix filter whose reader went away.
            return;
        }
        eprintln!("hopper-sim: error: {e:#}");
        std::process::exit(2);
    }
}

/// Whether `e` is a write to a stdout whose reader has closed it. Rust
/// ignores SIGPIPE, so such a write fails with `BrokenPipe` instead of
/// ending the process the way the shell expects.
fn is_closed_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Help and version go out as clap prints them; any other command-line error
/// becomes one `hopper-sim: error:` line (clap's first line and its tip, if
/// any) with exit status 2, like every other bad input, instead of clap's
/// several-line usage block.
fn bad_command_line(e: clap::Error) -> ! {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    let text = e.render().to_string();
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let first = lines.next().unwrap_or("invalid command line");
    let first = first.strip_prefix("error: ").unwrap_or(first);
    let tip = lines
        .find_map(|l| l.strip_prefix("tip: "))
        .map(|t| format!("; {t}"))
        .unwrap_or_default();
    eprintln!("hopper-sim: error: {first}{tip} (see `hopper-sim --help`)");
    std::process::exit(2);
}

fn cmd_params_show(preset: &str) -> Result<()> {
    let Some(p) = Params::preset(preset) else {
        bail!(
            "unknown preset `{preset}`: expected one of {:?}",
            Params::PRESET_NAMES
        );
    };
    say_raw!("{}", params_toml::to_toml(&p, preset));
    Ok(())
}

/// A simulated hop's spring loads against a spring design.
#[derive(serde::Serialize)]
struct HopCheck {
    controller: &'static str,
    target_apex_m: f64,
    steady_apex_m: Option<f64>,
    spring_rate_n_per_m: f64,
    peak_spring_force_n: f64,
    peak_deflection_m: f64,
    fatigue_force_n: f64,
    allowable_stroke_m: f64,
    within: bool,
}

fn cmd_spring(a: &SpringArgs) -> Result<()> {
    use hal_sim::spring::{design, Material, SpringSpec};
    let Some(material) = Material::by_name(&a.material) else {
        bail!("unknown material `{}`", a.material);
    };
    let mm = |v: f64| v * 1e-3;
    let spec = SpringSpec {
        stiffness_n_per_m: a.stiffness_n_per_m,
        material,
        wire_m: mm(a.wire_mm),
        outer_m: mm(a.outer_mm),
        free_length_m: mm(a.free_length_mm),
        max_solid_m: a.max_solid_mm.map(mm),
        min_stroke_m: Some(mm(a.min_stroke_mm)),
    };
    let d = design(&spec).map_err(anyhow::Error::msg)?;
    let check = match a.check_hop {
        None => None,
        Some(apex) => {
            if !(apex.is_finite() && (0.01..=0.5).contains(&apex)) {
                bail!("--check-hop {apex} must be an apex within 0.01..=0.5 m");
            }
            let cli = hal_sim::scenario::Overrides {
                controller: Some(hopper_control::laws::ControllerKind::Shaped),
                target_apex_m: Some(apex),
                start_apex_m: Some(0.05),
                duration_s: Some(10.0),
                ..Default::default()
            };
            let mut settings = hal_sim::scenario::Settings::resolve(None, &cli);
            settings.params.spring_stiffness_n_per_m = d.rate_n_per_m;
            settings.check().map_err(anyhow::Error::msg)?;
            let cfg = settings.run_config(1.0 / settings.control_hz);
            let mut ctl = settings
                .controller_spec()
                .and_then(|spec| spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s))
                .map_err(anyhow::Error::msg)?;
            let r = run::run(&cfg, &settings.params_name, &mut ctl).map_err(anyhow::Error::msg)?;
            let peak = r
                .samples
                .iter()
                .map(|s| s.spring_force_n)
                .fold(0.0, f64::max);
            let deflection = peak / d.rate_n_per_m;
            Some(HopCheck {
                controller: "shaped",
                target_apex_m: apex,
                steady_apex_m: r.summary.steady_apex_m,
                spring_rate_n_per_m: d.rate_n_per_m,
                peak_spring_force_n: peak,
                peak_deflection_m: deflection,
                fatigue_force_n: d.fatigue_force_n,
                allowable_stroke_m: d.allowable_stroke_m,
                within: peak <= d.fatigue_force_n && deflection <= d.allowable_stroke_m,
            })
        }
    };
    if a.json {
        let v = serde_json::json!({ "design": d, "hop_check": check });
        say!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    for l in d.lines() {
        say!("{l}");
    }
    say!(
        "limits: {}",
        if d.meets_limits {
            "met (solid length, stroke)"
        } else {
            "NOT met: see the solid length and the allowable stroke"
        }
    );
    if let Some(c) = &check {
        say!(
            "hop check: shaped to {:.3} m (steady {}) on the design machine with a {:.0} N/m spring: peak spring force {:.0} N ({:.0}% of the fatigue force), deflection {:.1} mm of {:.1} mm allowed: {}",
            c.target_apex_m,
            c.steady_apex_m.map_or("none".to_string(), |a| format!("{a:.4} m")),
            c.spring_rate_n_per_m,
            c.peak_spring_force_n,
            100.0 * c.peak_spring_force_n / c.fatigue_force_n,
            c.peak_deflection_m * 1e3,
            c.allowable_stroke_m * 1e3,
            if c.within { "within" } else { "EXCEEDED" }
        );
    }
    Ok(())
}

fn planar_summary(r: &hal_sim::planar_sim::PlanarRun) -> String {
    let n = r.apex_heights_m.len();
    // A long run's apexes: the first 12 and the last 4.
    let apexes: Vec<String> = r
        .apex_heights_m
        .iter()
        .enumerate()
        .filter(|(k, _)| *k < 12 || *k + 4 >= n)
        .map(|(k, a)| {
            if k + 4 == n && n > 16 {
                format!("... {a:.4}")
            } else {
                format!("{a:.4}")
            }
        })
        .collect();
    let start = match r.start {
        hal_sim::planar_sim::Start::Design => format!("design {:.4}", r.design_apex_m),
        hal_sim::planar_sim::Start::FixedPoint => format!(
            "fixed point {:.4}, design {:.4}",
            r.start_apex_m, r.design_apex_m
        ),
    };
    let (model, lifts) = if r.model == "appendix-a" {
        (
            " (Appendix A)",
            format!(", {:.3} J by the liftoffs' pick-up", r.liftoff_loss_j),
        )
    } else {
        ("", String::new())
    };
    format!(
        "planar{model}: {} m/s, K_c {} N s/m: {} touchdowns ({:.3} J taken by their impacts{lifts}), {}; {n} apexes (m, {start}): {}; largest drift {:.4} m; largest leg force {:.0} N, stabiliser force {:.0} N",
        r.speed_mps,
        r.gain_ns_per_m,
        r.touchdowns,
        r.touchdown_loss_j,
        if r.fell { "fell" } else { "still running" },
        apexes.join(" "),
        r.apex_drift_m,
        r.max_leg_force_n,
        r.max_stabiliser_force_n
    )
}

fn cmd_planar_stability(
    speeds: &[f64],
    gains: &[f64],
    out: Option<&std::path::Path>,
    json: bool,
) -> Result<()> {
    use hal_sim::planar_stability::scan;
    if speeds.is_empty() || speeds.len() > 40 {
        bail!("--speeds takes 1 to 40 speeds");
    }
    if gains.is_empty() || gains.len() > 100 {
        bail!("--kc takes 1 to 100 gains");
    }
    if speeds.len() * gains.len() > 400 {
        bail!(
            "--speeds x --kc is {} fixed points; at most 400 (each takes up to a few seconds)",
            speeds.len() * gains.len()
        );
    }
    for &v in speeds {
        if !(v.is_finite() && v > 0.0 && v <= 10.0) {
            bail!("--speeds {v} must be within 0 (excluded) ..= 10 m/s");
        }
    }
    for &k in gains {
        if !(k.is_finite() && k.abs() <= 10_000.0) {
            bail!("--kc {k} must be within -10000 ..= 10000 N s/m");
        }
    }
    let bar = indicatif::ProgressBar::new((speeds.len() * gains.len()) as u64)
        .with_finish(indicatif::ProgressFinish::AndClear);
    bar.set_style(
        indicatif::ProgressStyle::with_template("fixed points {pos}/{len} {wide_bar} {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let rows = scan(speeds, gains, &mut || bar.inc(1));
    bar.finish_and_clear();
    let written = match out {
        Some(dir) => hal_sim::planar_stability::write_outputs(dir, &rows, gains)
            .map_err(anyhow::Error::msg)?,
        None => Vec::new(),
    };
    if json {
        say!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({ "kc_ns_per_m": gains, "speeds": rows })
            )?
        );
        return Ok(());
    }
    let opt = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{x:.3}"));
    let range =
        |r: Option<[f64; 2]>| r.map_or("none".to_string(), |r| format!("{} ..= {}", r[0], r[1]));
    say!("growth = largest |eigenvalue| of the apex map's Jacobian off the energy family (below 1: attracting)");
    say!(
        "{:>6} {:>8} {:>8} {:>9} {:>8} {:>22} {:>14}",
        "speed",
        "apex",
        "passive",
        "best K_c",
        "growth",
        "K_c lowering growth",
        "K_c attracting"
    );
    for row in &rows {
        // The passive gait's apex, else the first found.
        let apex = gains
            .iter()
            .position(|&g| g == 0.0)
            .and_then(|k| row.points[k].as_ref())
            .or_else(|| row.points.iter().flatten().next())
            .map(|f| format!("{:.4}", f.apex[0]));
        say!(
            "{:>4.1} m/s {:>6} m {:>8} {:>9} {:>8} {:>22} {:>14}",
            row.speed_mps,
            apex.unwrap_or_else(|| "-".into()),
            opt(row.passive_growth),
            row.best_gain_ns_per_m
                .map_or("-".into(), |g| format!("{g}")),
            opt(row.best_growth),
            range(row.helps_ns_per_m),
            range(row.attracts_ns_per_m)
        );
    }
    if speeds.len() * gains.len() <= 12 {
        for row in &rows {
            for (g, f) in gains.iter().zip(&row.points) {
                match f {
                    Some(f) => {
                        let eig: Vec<String> = f
                            .eigenvalues
                            .iter()
                            .map(|z| {
                                if z[1].abs() < 1e-9 {
                                    format!("{:.4}", z[0])
                                } else {
                                    format!("{:.4}{:+.4}i", z[0], z[1])
                                }
                            })
                            .collect();
                        say!(
                            "{} m/s, K_c {g}: apex {:.4} m, |P(a)-a| {:.1e}, eigenvalues {}",
                            row.speed_mps,
                            f.apex[0],
                            f.residual,
                            eig.join(" ")
                        );
                    }
                    None => say!("{} m/s, K_c {g}: no fixed point found", row.speed_mps),
                }
            }
        }
    }
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}

fn cmd_planar(cmd: &PlanarCmd) -> Result<()> {
    match cmd {
        PlanarCmd::Run {
            speed,
            kc,
            duration,
            start,
            model,
            appendix,
            out,
            json,
        } => {
            use hal_sim::planar_sim::{simulate_model, Start};
            let start = if start == "fixed-point" {
                Start::FixedPoint
            } else {
                Start::Design
            };
            let model = appendix.model(model)?;
            let r = simulate_model(*speed, *kc, *duration, start, &model)
                .map_err(anyhow::Error::msg)?;
            let written = match out {
                Some(dir) => hal_sim::planar_sim::write_run(dir, &r).map_err(anyhow::Error::msg)?,
                None => Vec::new(),
            };
            if *json {
                say!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                say!("{}", planar_summary(&r));
                for p in &written {
                    say!("  wrote {}", p.display());
                }
            }
        }
        PlanarCmd::Stability {
            speeds,
            kc,
            out,
            json,
        } => cmd_planar_stability(speeds, kc, out.as_deref(), *json)?,
        PlanarCmd::Figures { out } => {
            let (written, runs) =
                hal_sim::planar_sim::write_figures(out).map_err(anyhow::Error::msg)?;
            for r in &runs {
                say!("{}", planar_summary(r));
            }
            for p in &written {
                say!("  wrote {}", p.display());
            }
        }
    }
    Ok(())
}

fn cmd_identify(a: &IdentifyArgs) -> Result<()> {
    use hal_sim::identify::{identify, read_log, write_plot, Experiment};
    let base = match &a.params {
        Some(p) => params_toml::load(p).map_err(anyhow::Error::msg)?,
        None => params_toml::PlantSet::preset("design")
            .ok_or_else(|| anyhow::anyhow!("no design preset"))?,
    };
    let experiment = match a.experiment.as_str() {
        "open-torque" => {
            if !(a.torque.is_finite() && a.torque > 0.0 && a.torque <= 5.0) {
                bail!("--torque {} must be within 0 ..= 5 N m", a.torque);
            }
            Experiment::OpenTorque {
                torque_nm: a.torque,
            }
        }
        _ => Experiment::Passive,
    };
    let log = read_log(&a.log).map_err(anyhow::Error::msg)?;
    let bar =
        indicatif::ProgressBar::new_spinner().with_finish(indicatif::ProgressFinish::AndClear);
    bar.set_message(format!("fitting {} samples", log.t_s.len()));
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let id = identify(&log, &base.params, experiment).map_err(anyhow::Error::msg)?;
    bar.finish_and_clear();
    let written = match &a.out {
        Some(dir) => write_plot(
            &log,
            &id,
            &format!("identify ({}): {}", a.experiment, log.file),
            dir,
        )
        .map_err(anyhow::Error::msg)?,
        None => Vec::new(),
    };
    if a.json {
        let mut v = serde_json::Map::new();
        for e in &id.estimates {
            v.insert(e.field.into(), serde_json::json!(e.value));
        }
        if let Some(t) = id.stance_torque_nm {
            v.insert("stance_torque_nm".into(), serde_json::json!(t));
        }
        v.insert("fit".into(), serde_json::to_value(&id)?);
        say!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    say!(
        "identify: {} hop, {} samples over {:.3} s ({}), from the {} parameters",
        a.experiment,
        log.t_s.len(),
        log.t_s.last().copied().unwrap_or(0.0),
        log.file,
        base.name
    );
    for e in &id.estimates {
        say!(
            "  {} = {:.4} +- {:.4} (from {:.4})",
            e.field,
            e.value,
            e.std,
            e.start
        );
    }
    if let Some(t) = id.stance_torque_nm {
        say!("  effective stance torque {t:.4} N m (k_t x current_limit_a)");
    }
    say!(
        "  fit: toe-height residual {:.3} mm RMS over {} samples, {} simulations",
        id.rms_residual_m * 1e3,
        id.samples,
        id.simulations
    );
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}

fn cmd_design(cmd: &DesignCmd) -> Result<()> {
    use hal_sim::design::{first_stance, table_3_1, CATALOGUE, DESIGN_MOTOR, STUDY_LEADS_M};
    match cmd {
        DesignCmd::Motors { json } => {
            let table = table_3_1()
                .iter()
                .map(|m| first_stance(m, 0.005).map(|f| (*m, f)))
                .collect::<Result<Vec<_>, _>>()
                .map_err(anyhow::Error::msg)?;
            let catalogue = CATALOGUE
                .iter()
                .map(|m| first_stance(m, 0.005).map(|f| (*m, f)))
                .collect::<Result<Vec<_>, _>>()
                .map_err(anyhow::Error::msg)?;
            if *json {
                let row = |(m, f): &(hal_sim::design::Motor, hal_sim::design::FirstStance)| {
                    serde_json::json!({
                        "motor": m, "stall_torque_nm": m.stall_torque_nm(),
                        "no_load_speed_rad_s": m.no_load_speed_rad_s(), "first_stance": f
                    })
                };
                let v = serde_json::json!({
                    "table_3_1": table.iter().map(row).collect::<Vec<_>>(),
                    "catalogue": catalogue.iter().map(row).collect::<Vec<_>>(),
                });
                say!("{}", serde_json::to_string_pretty(&v)?);
                return Ok(());
            }
            say!("Table 3.1: energy added in the first stance (k = 10 kN/m, 5 mm lead, dropped from 0.15 m, the stall torque commanded on the motor's torque-speed line)");
            say!(
                "  {:<15} {:>10} {:>10} {:>10} {:>12} {:>11}",
                "motor",
                "stall N m",
                "thesis J",
                "here J",
                "first apex m",
                "peak rad/s"
            );
            for (m, f) in &table {
                say!(
                    "  {:<15} {:>10.3} {:>10.1} {:>10.2} {:>12.4} {:>11.0}",
                    m.thesis_name,
                    m.stall_torque_nm(),
                    m.thesis_energy_j,
                    f.motor_work_j,
                    f.first_apex_m,
                    f.peak_speed_rad_s
                );
            }
            say!("catalogue motors (datasheet constants, 24 V, the rotor plus the transmission's inertia):");
            for (m, f) in &catalogue {
                say!(
                    "  {} for \"{}\": stall {:.3} N m, no-load {:.0} rad/s: {:.2} J, first apex {:.4} m (thesis {:.1} J)",
                    m.model,
                    m.thesis_name,
                    m.stall_torque_nm(),
                    m.no_load_speed_rad_s(),
                    f.motor_work_j,
                    f.first_apex_m,
                    m.thesis_energy_j
                );
            }
        }
        DesignCmd::WouldHop { out, json } => {
            use hal_sim::design::{
                feasibility_map, smallest_changes, write_feasibility_plot, Holder,
            };
            let bar = indicatif::ProgressBar::new_spinner()
                .with_finish(indicatif::ProgressFinish::AndClear);
            bar.set_message("searching single changes and the maps (about 1,000 runs of 15 s)");
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            let started = std::time::Instant::now();
            let mut smallest = smallest_changes(true).map_err(anyhow::Error::msg)?;
            smallest.extend(smallest_changes(false).map_err(anyhow::Error::msg)?);
            let maps = match out {
                Some(_) => [true, false]
                    .iter()
                    .flat_map(|&p| Holder::ALL.iter().map(move |&h| (h, p)))
                    .map(|(h, p)| feasibility_map(h, p))
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(anyhow::Error::msg)?,
                None => Vec::new(),
            };
            bar.finish_and_clear();
            let written = match out {
                Some(dir) => write_feasibility_plot(&maps, dir).map_err(anyhow::Error::msg)?,
                None => Vec::new(),
            };
            if *json {
                say!("{}", serde_json::to_string_pretty(&smallest)?);
                return Ok(());
            }
            say!(
                "the smallest single change that makes the identified machine hold a 5 cm hop (released from 0.05 m, 15 s each; searched in {:.1} s):",
                started.elapsed().as_secs_f64()
            );
            for s in &smallest {
                let (name, unit) = s.change.label();
                let found = match (s.holds_at, s.apex_m) {
                    (Some(v), Some(a)) => format!("{v:.3} {unit} (steady apex {a:.4} m)"),
                    _ => format!("none of {} values tried holds it", s.tried),
                };
                say!(
                    "  {:<24} {:<12} {:<19} identified {:.3} {unit} -> {found}",
                    name,
                    s.holder.name(),
                    if s.thermal_protection {
                        "thermal protection"
                    } else {
                        "mechanics only"
                    },
                    s.identified
                );
            }
            for p in &written {
                say!("  wrote {}", p.display());
            }
        }
        DesignCmd::Leads { out, json } => {
            let study = STUDY_LEADS_M
                .iter()
                .map(|&l| first_stance(&DESIGN_MOTOR, l))
                .collect::<Result<Vec<_>, _>>()
                .map_err(anyhow::Error::msg)?;
            let written = match out {
                Some(dir) => hal_sim::design::write_lead_plot(&DESIGN_MOTOR, &study, dir)
                    .map_err(anyhow::Error::msg)?,
                None => Vec::new(),
            };
            if *json {
                say!("{}", serde_json::to_string_pretty(&study)?);
                return Ok(());
            }
            say!("lead study: the design motor (2.0 N m stall, 808 rad/s no-load) on its torque-speed curve, k = 10 kN/m, dropped from 0.15 m");
            say!(
                "  {:>8} {:>14} {:>12} {:>14} {:>11} {:>10}",
                "lead mm",
                "motor work J",
                "first apex m",
                "apex gain J",
                "peak rad/s",
                "stance ms"
            );
            for f in &study {
                say!(
                    "  {:>8.0} {:>14.2} {:>12.4} {:>14.2} {:>11.0} {:>10.1}",
                    f.lead_m * 1e3,
                    f.motor_work_j,
                    f.first_apex_m,
                    f.hop_energy_gain_j,
                    f.peak_speed_rad_s,
                    f.stance_s * 1e3
                );
            }
            for p in &written {
                say!("  wrote {}", p.display());
            }
        }
    }
    Ok(())
}

fn cmd_figures(out: &std::path::Path, quick: bool) -> Result<()> {
    let opts = hal_sim::figures::FigureOptions { quick };
    let report = hal_sim::figures::write_all(out, &opts).map_err(anyhow::Error::msg)?;
    for n in &report.notes {
        say!("{n}");
    }
    say!(
        "hopper-sim: wrote {} files to {}",
        report.files.len(),
        out.display()
    );
    Ok(())
}

fn cmd_serve(a: ServeArgs) -> Result<()> {
    let file = a.base.scenario()?;
    let settings = resolve(file.as_ref(), &a.base)?;
    settings.check().map_err(anyhow::Error::msg)?;
    if !(a.speed.is_finite() && a.speed > 0.0 && a.speed <= 100.0) {
        bail!("--speed {} must be in (0, 100]", a.speed);
    }
    if let Some(l) = a.limit {
        if !(l.is_finite() && l > 0.0) {
            bail!("--for {l} must be a positive number of seconds");
        }
    }
    // Standing, as a robot is powered up (released 1 mm above the ground,
    // it settles in about 0.3 s), unless --start-apex holds it up there
    // until armed.
    let held = a.base.start_apex.is_some();
    let start_apex_m = a.base.start_apex.unwrap_or(0.001);
    if !(a.loadcell_bias_n.is_finite() && a.loadcell_bias_n.abs() <= 200.0) {
        bail!(
            "--loadcell-bias-n {} must be within +-200 N",
            a.loadcell_bias_n
        );
    }
    if !(a.pot_bias_m.is_finite() && a.pot_bias_m.abs() <= 0.01) {
        bail!("--pot-bias-m {} must be within +-0.01 m", a.pot_bias_m);
    }
    let cfg = settings.run_config(0.0);
    if !(a.nut_start_m.is_finite() && (0.0..=cfg.params.stroke_m).contains(&a.nut_start_m)) {
        bail!(
            "--nut-start-m {} must be within the stroke, 0 ..= {} m",
            a.nut_start_m,
            cfg.params.stroke_m
        );
    }
    if !(a.spring_rate_error.is_finite() && a.spring_rate_error.abs() <= 0.5) {
        bail!(
            "--spring-rate-error {} must be within +-0.5",
            a.spring_rate_error
        );
    }
    if !(a.height_zero_error_m.is_finite() && a.height_zero_error_m.abs() <= 0.1) {
        bail!(
            "--height-zero-error-m {} must be within +-0.1 m",
            a.height_zero_error_m
        );
    }
    if !(a.loadcell_gain_error.is_finite() && a.loadcell_gain_error.abs() <= 0.5) {
        bail!(
            "--loadcell-gain-error {} must be within +-0.5",
            a.loadcell_gain_error
        );
    }
    // The firmware is configured for the nominal machine, started where it
    // believes; the plant is the real one.
    let mis = hopper_plant::robot::Miscalibration {
        loadcell_bias_n: a.loadcell_bias_n,
        pot_bias_m: a.pot_bias_m,
        nut_start_m: a.nut_start_m,
        spring_rate_error: a.spring_rate_error,
        height_zero_error_m: a.height_zero_error_m,
        loadcell_gain_error: a.loadcell_gain_error,
    };
    let (runner, hal) = settings
        .controller_spec()
        .and_then(|mut spec| {
            spec.sensors = mis.sensors(spec.sensors);
            spec.runner(
                &cfg.params,
                mis.believed_start_apex_m(start_apex_m),
                cfg.control_dt_s,
                false,
            )
        })
        .map_err(anyhow::Error::msg)?;
    let plant = mis
        .plant(cfg.params, start_apex_m)
        .map_err(|e| anyhow::anyhow!("plant: {e:?}"))?;
    let hal = mis.hal(hal, &plant);
    let robot = hopper_plant::robot::VirtualRobot::new(plant, hal, runner, cfg.control_dt_s);
    let mut robot = if held { robot.hold() } else { robot };
    let (flash, record) =
        hal_sim::serve::Flash::open(a.flash.as_deref()).map_err(anyhow::Error::msg)?;
    hal_sim::serve::load_at_boot(&mut robot, record.as_deref());
    let listener = std::net::TcpListener::bind(&a.tcp)
        .with_context(|| format!("cannot listen on {}", a.tcp))?;
    let addr = listener.local_addr().context("socket address")?;
    println!(
        "hopper-sim: virtual robot listening on {addr} ({} controller, {} parameters, {:.0} Hz, {}x real time, {}); connect with `hopper-link --tcp {addr} status`",
        settings.controller.name(),
        settings.params_name,
        1.0 / cfg.control_dt_s,
        a.speed,
        if held {
            format!("held {start_apex_m} m up until armed")
        } else {
            "standing".to_string()
        }
    );
    use std::io::Write as _;
    let _ = std::io::stdout().flush();
    hal_sim::serve::serve(
        robot,
        flash,
        &listener,
        hal_sim::serve::ServeOptions {
            speed: a.speed,
            limit_s: a.limit,
            dt_s: cfg.control_dt_s,
        },
    )
    .map_err(anyhow::Error::msg)
}

fn cmd_run(a: RunArgs) -> Result<()> {
    // Validate everything before touching the file system.
    let file = a.base.scenario()?;
    let settings = resolve(file.as_ref(), &a.base)?;
    let params_name = settings.params_name.clone();
    if !(a.sample_hz.is_finite() && a.sample_hz > 0.0) {
        bail!(
            "--sample-hz {} must be a positive number of Hz",
            a.sample_hz
        );
    }
    settings.check().map_err(anyhow::Error::msg)?;
    let cfg = settings.run_config(if a.out.is_some() {
        1.0 / a.sample_hz
    } else {
        0.0
    });
    let mut ctl = settings
        .controller_spec()
        .and_then(|spec| spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s))
        .map_err(anyhow::Error::msg)?;
    // A progress bar on stderr for runs long enough to wait for; indicatif
    // draws nothing when stderr is not a terminal.
    let bar = indicatif::ProgressBar::new(1000);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} simulating [{bar:40}] {msg} ({eta} left)",
        )
        .map_err(anyhow::Error::msg)?
        .progress_chars("=> "),
    );
    if cfg.duration_s < 60.0 {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let duration_s = cfg.duration_s;
    let result = run::run_with_progress(&cfg, &params_name, &mut ctl, &mut |done, total| {
        bar.set_position(done * 1000 / total.max(1));
        bar.set_message(format!(
            "{:.1} / {duration_s} s",
            duration_s * done as f64 / total.max(1) as f64
        ));
    })
    .map_err(anyhow::Error::msg)?;
    bar.finish_and_clear();
    let s = &result.summary;

    let mut written = Vec::new();
    if let Some(dir) = &a.out {
        let title = format!(
            "{} hopping, {} parameters, start apex {:.3} m",
            s.controller, s.params, s.start_apex_m
        );
        written = hal_sim::out_dir::write_whole(dir, |staging| {
            let csv_path = staging.join("trajectory.csv");
            let io = |e: std::io::Error| {
                format!("cannot write {}: {e}", dir.join("trajectory.csv").display())
            };
            let mut f = std::io::BufWriter::new(std::fs::File::create(&csv_path).map_err(io)?);
            run::write_csv(&result.samples, &mut f).map_err(io)?;
            std::io::Write::flush(&mut f).map_err(io)?;
            hal_sim::plot::hop_plot_with_heat(
                &result.samples,
                &title,
                s.target_apex_m,
                s.thermal.map(|t| hal_sim::plot::HeatLevels {
                    derate_c: t.derate_winding_c,
                    trip_c: t.trip_winding_c,
                    protect: t.protect,
                }),
                &staging.join("hop.png"),
            )?;
            Ok(vec!["trajectory.csv".into(), "hop.png".into()])
        })
        .map_err(anyhow::Error::msg)?;
    }

    if a.json {
        say!("{}", serde_json::to_string(s)?);
        return Ok(());
    }
    let l = &s.ledger;
    let fmt_opt = |v: Option<f64>, unit: &str, scale: f64| match v {
        Some(x) => format!("{:.4} {unit}", x * scale),
        None => "-".to_string(),
    };
    say!(
        "hopper-sim: {} controller, {} parameters, released from {:.3} m, {:.2} s simulated",
        s.controller,
        s.params,
        s.start_apex_m,
        s.duration_s
    );
    let n = s.apex_heights_m.len();
    let shown: Vec<String> = if n <= 14 {
        s.apex_heights_m.iter().map(|h| format!("{h:.4}")).collect()
    } else {
        let head = s.apex_heights_m[..10].iter().map(|h| format!("{h:.4}"));
        let tail = s.apex_heights_m[n - 3..].iter().map(|h| format!("{h:.4}"));
        head.chain(std::iter::once("...".to_string()))
            .chain(tail)
            .collect()
    };
    say!("  hops (stances)     {}", s.hops);
    say!(
        "  apex heights [m]   {}",
        if shown.is_empty() {
            "-".into()
        } else {
            shown.join(" ")
        }
    );
    if let Some(t) = s.target_apex_m {
        say!(
            "  target apex        {t:.4} m, {}",
            match s.hops_to_converge {
                Some(k) => format!("within 2% from hop {k} on"),
                None => match s.thermal.and_then(|t| t.first_derated_s) {
                    Some(d) => format!(
                        "not converged (within 2%); the motor's current limit derated from {d:.2} s (motor heat)"
                    ),
                    None => "not converged (within 2%)".to_string(),
                },
            }
        );
    }
    say!(
        "  faults             {}",
        if s.faults.is_empty() {
            "none".to_string()
        } else {
            format!(
                "{} (first at {:.4} s)",
                s.faults
                    .iter()
                    .map(|f| format!("{} at {:.4} s", f.name, f.time_s))
                    .collect::<Vec<_>>()
                    .join(", "),
                s.first_fault_s.unwrap_or(0.0)
            )
        }
    );
    if let Some(t) = &s.thermal {
        say!("  motor heat         {}", hal_sim::controller::heat_line(t));
    }
    say!(
        "  steady apex        {}",
        fmt_opt(s.steady_apex_m, "m", 1.0)
    );
    say!(
        "  mean stance time   {}",
        fmt_opt(s.stance_time_s, "ms", 1000.0)
    );
    say!("  hopping stopped at {}", fmt_opt(s.stopped_at_s, "s", 1.0));
    say!(
        "  energy [J]         start {:.3}, end {:.3}; motor work {:+.3}, friction {:.3}, damping {:.3},",
        s.initial_energy_j, s.final_energy_j, l.motor_work_j, l.friction_j, l.damping_j
    );
    say!(
        "                     touchdown {:.3}, liftoff {:.3}, stop impacts {:.3}, settling {:.3}; residual {:.2e}",
        l.touchdown_loss_j, l.liftoff_loss_j, l.stop_impact_loss_j, l.settle_loss_j, s.energy_residual_j
    );
    say!(
        "  motor              peak speed {:.0} rad/s ({:.0}% of no-load {:.0} rad/s), peak current {:.1} A, peak stroke {:.1} mm",
        s.peak_motor_speed_rad_s,
        100.0 * s.peak_motor_speed_rad_s / s.no_load_speed_rad_s,
        s.no_load_speed_rad_s,
        s.peak_current_a,
        s.peak_stroke_m * 1000.0
    );
    if let Some(h) = &s.steady_hop {
        say!(
            "  steady hop [J]     motor work {:.2}, friction {:.2}, touchdown {:.2}, liftoff {:.2}, stop impacts {:.2}; at apex rotor {:.2}, spring {:.2} (mean of the last 5 hops)",
            h.motor_work_j,
            h.friction_j,
            h.touchdown_loss_j,
            h.liftoff_loss_j,
            h.stop_impact_loss_j,
            h.actuator_kinetic_j,
            h.actuator_spring_j,
        );
    }
    if a.ledger {
        say!("  per-hop energy ledger, J (previous apex to this apex; rotor and spring: actuator energy left at this apex)");
        say!(
            "  {:>4} {:>8} {:>8} {:>8} {:>8} {:>9} {:>8} {:>8} {:>8} {:>8}",
            "hop",
            "time s",
            "apex m",
            "motor",
            "friction",
            "touchdown",
            "liftoff",
            "stops",
            "rotor",
            "spring"
        );
        for (i, h) in s.hop_ledger.iter().enumerate() {
            say!(
                "  {:>4} {:>8.3} {:>8.4} {:>8.3} {:>8.3} {:>9.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3}",
                i + 1,
                h.apex_time_s,
                h.apex_m,
                h.motor_work_j,
                h.friction_j,
                h.touchdown_loss_j,
                h.liftoff_loss_j,
                h.stop_impact_loss_j,
                h.actuator_kinetic_j,
                h.actuator_spring_j
            );
        }
    }
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}

/// `1 thread`, `2 threads`.
fn threads(n: usize) -> String {
    match n {
        1 => "1 thread".to_string(),
        n => format!("{n} threads"),
    }
}

/// Most points a sweep prints one line each for; a bigger grid gets the
/// tally only (sweep.csv has every point).
const TABLE_ROWS: usize = 40;

/// A finished sweep's table (small grids) and its tally: each point's
/// metric and whether it converged, derated or faulted.
fn print_table(sw: &Sweep, rows: &[sweep::Row]) -> Result<()> {
    if rows.len() <= TABLE_ROWS {
        for line in sw.text_table(rows) {
            say!("{line}");
        }
    }
    say!("  {}", sweep::tally(rows, sw.about_the_apex()));
    Ok(())
}

fn cmd_sweep_merge(parts: &[PathBuf], out: &std::path::Path) -> Result<()> {
    let (sw, rows, title) = sweep::merge(parts).map_err(anyhow::Error::msg)?;
    let written = sw.write(&rows, out, &title).map_err(anyhow::Error::msg)?;
    say!(
        "hopper-sim sweep merge: {} parts, {} runs",
        parts.len(),
        rows.len()
    );
    print_table(&sw, &rows)?;
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}

fn cmd_sweep(a: SweepArgs) -> Result<()> {
    if let Some(SweepCmd::Merge { parts, out }) = &a.cmd {
        return cmd_sweep_merge(parts, out);
    }
    let Some(out) = a.out.clone() else {
        bail!("--out DIR is required");
    };
    let shard = a
        .shard
        .as_deref()
        .map(sweep::Shard::parse)
        .transpose()
        .map_err(anyhow::Error::msg)?;
    // Everything is parsed and every grid point checked before any run or
    // any file: bad input writes nothing.
    let file = match &a.preset {
        Some(name) => {
            let Some((_, text)) = sweep::PRESETS.iter().find(|(n, _)| n == name) else {
                let names: Vec<&str> = sweep::PRESETS.iter().map(|(n, _)| *n).collect();
                bail!("unknown sweep preset `{name}`: expected one of {names:?}");
            };
            Some(
                scenario::from_toml_str(text, &format!("scenarios/{name}.toml"))
                    .map_err(anyhow::Error::msg)?,
            )
        }
        None => a.base.scenario()?,
    };
    let base = resolve(file.as_ref(), &a.base)?;
    let specs: Vec<String> = if a.param.is_empty() {
        file.as_ref()
            .map(|f| f.sweep.params.clone())
            .unwrap_or_default()
    } else {
        a.param.clone()
    };
    if specs.is_empty() {
        bail!(
            "nothing to sweep: give --param NAME=START:END:N (or a scenario with a [sweep] table)"
        );
    }
    let axes = specs
        .iter()
        .map(|s| sweep::parse_axis(s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(anyhow::Error::msg)?;
    let metric = a
        .metric
        .clone()
        .or_else(|| file.as_ref().and_then(|f| f.sweep.metric.clone()))
        .unwrap_or_else(|| sweep::DEFAULT_METRIC.to_string());
    let sw = Sweep { base, axes, metric };
    let slice = shard.unwrap_or(sweep::Shard::WHOLE);
    let runs = sw.shard_points(slice).map_err(anyhow::Error::msg)?.len();
    let grid_runs: usize = sw.axes.iter().map(|x| x.values.len()).product();

    // A progress bar for sweeps worth waiting for; indicatif also draws
    // nothing when stderr is not a terminal.
    let bar = indicatif::ProgressBar::new(runs as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} sweep [{bar:40}] {pos}/{len} runs ({eta} left)",
        )
        .map_err(anyhow::Error::msg)?
        .progress_chars("=> "),
    );
    if runs as f64 * sw.base.duration_s < 60.0 {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let started = std::time::Instant::now();
    let indexed = sw
        .run_shard(slice, &|| bar.inc(1))
        .map_err(anyhow::Error::msg)?;
    bar.finish_and_clear();
    let elapsed_s = started.elapsed().as_secs_f64();

    let swept: Vec<&str> = sw.axes.iter().map(|x| x.knob.column()).collect();
    // A sweep run without the motor's thermal protection says so.
    let protect_off = sw
        .base
        .firmware_params
        .iter()
        .rev()
        .find(|(p, _)| p.name == hopper_control::params::THERMAL_PROTECT.name)
        .is_some_and(|(_, v)| *v == 0.0);
    let title = format!(
        "{} sweep: {} controller, {} parameters{}",
        swept.join(" x "),
        sw.base.controller,
        sw.base.params_name,
        if protect_off {
            ", no motor thermal limit"
        } else {
            ""
        }
    );
    if let Some(k) = shard {
        let written = sw
            .write_part(k, &indexed, &out, &title)
            .map_err(anyhow::Error::msg)?;
        say!(
            "hopper-sim sweep: shard {}/{}: {runs} of {grid_runs} runs of {} s in {elapsed_s:.1} s on {}",
            k.index,
            k.count,
            sw.base.duration_s,
            threads(rayon::current_num_threads())
        );
        for p in &written {
            say!("  wrote {}", p.display());
        }
        return Ok(());
    }
    let rows: Vec<sweep::Row> = indexed.into_iter().map(|(_, r)| r).collect();
    let written = sw.write(&rows, &out, &title).map_err(anyhow::Error::msg)?;

    say!(
        "hopper-sim sweep: {runs} runs of {} s ({} controller, {} parameters) in {elapsed_s:.1} s on {}",
        sw.base.duration_s,
        sw.base.controller,
        sw.base.params_name,
        threads(rayon::current_num_threads())
    );
    print_table(&sw, &rows)?;
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}
