//! Scenario files: everything one `hopper-sim run` needs, in one TOML file
//! (`hopper-sim run --scenario FILE`), and how file, flags and defaults
//! combine.
//!
//! ```toml
//! description = "what this scenario shows"
//! plant = { base = "design", spring_stiffness_n_per_m = 10000.0 }  # or plant = "identified"
//! model = "design"          # optional: what the controller believes (default: the plant)
//! motor = "re40"            # optional: a catalogue motor on the plant, its thermal data in the firmware
//! start_apex_m = 0.10
//! duration_s = 15.0
//! control_hz = 10000.0
//! inject = ["estop@1.0"]    # faults to inject, KIND@TIME (as `--inject`)
//!
//! [controller]              # or controller = "energy-apex"
//! name = "energy-apex"
//! target_apex_m = 0.05
//! torque_nm = 1.0           # open-torque, modified-torque
//! energy_gain_nm_per_j = 3.0     # K_e of eq 2.52 (energy, energy-apex)
//! flight_kp_a_per_rad = 20.3152  # flight PD (eq 4.13; default: the preset's)
//! flight_kd_a_s_per_rad = 0.6077
//!
//! [sensors]
//! noise = true
//! seed = 1
//! loadcell_sigma_n = 2.0
//! pot_sigma_m = 1e-4
//!
//! [params]                  # firmware parameters by name (docs/parameters.md)
//! "energy_apex.integral_gain" = 0.4
//!
//! [sweep]                   # only `hopper-sim sweep` reads this
//! param = ["screw_lead_m=0.002:0.010:9"]
//! metric = "first_stance_motor_work_j"
//! ```
//!
//! Every key is optional. Precedence: a command-line flag, then the file,
//! then the documented default of `hopper-sim run`. Unknown keys, wrong types
//! and out-of-range values are errors naming the file, the line and the key.

use crate::controller::{ControllerSpec, CONTROLLER_NAMES};
use crate::flight_stability::{self, FlightLoop};
use crate::inject::Injection;
use crate::params::{Params, Range};
use crate::params_toml::{self, ParamsFileError, PlantSet};
use crate::run::RunConfig;
use crate::sim_io::SensorConfig;
use hopper_control::estimator::EstimatorConfig;
use hopper_control::hopper::{ApexLoop, Strategy};
use hopper_control::laws::ControllerKind;
use hopper_control::laws::{energy, flight_pd, StanceLaw};
use hopper_control::params::Param;
use hopper_control::pd_design::PdGains;
use serde::Deserialize;
use std::collections::HashMap;
use std::path::Path;

/// Controller run when neither file nor flag names one.
pub const DEFAULT_CONTROLLER: ControllerKind = ControllerKind::Passive;
/// Plant preset used when neither file nor flag gives one.
pub const DEFAULT_PARAMS: &str = "design";
/// Default apex target, m.
pub const DEFAULT_TARGET_APEX_M: f64 = 0.05;
/// Default start toe height, m.
pub const DEFAULT_START_APEX_M: f64 = 0.15;
/// Default simulated time, s.
pub const DEFAULT_DURATION_S: f64 = 5.0;
/// Default control rate, Hz.
pub const DEFAULT_CONTROL_HZ: f64 = 10_000.0;

/// Allowed ranges of the numeric settings, inclusive unless noted, in the
/// units of their names. Shared by the file reader and [`Settings::check`],
/// so a flag and a file key are held to the same limits.
pub mod limits {
    use hopper_control::params::{self as fw, Param};

    /// A firmware parameter's range ([`hopper_control::params`], the one
    /// definition), in f64.
    const fn of(p: &Param) -> (f64, f64) {
        (p.min as f64, p.max as f64)
    }

    /// Apex target, m.
    pub const TARGET_APEX_M: (f64, f64) = of(&fw::TARGET_APEX_M);
    /// Open-loop torque, N m (`constant_torque.torque_nm`, the same range as
    /// `modified_torque.torque_nm`).
    pub const TORQUE_NM: (f64, f64) = of(&fw::CONSTANT_TORQUE_NM);
    /// Energy-law gain `K_e`, N m/J (`energy.gain_nm_per_j`, the same range
    /// as `energy_apex.gain_nm_per_j`).
    pub const ENERGY_GAIN_NM_PER_J: (f64, f64) = of(&fw::ENERGY_GAIN);
    /// Flight PD proportional gain, A/rad.
    pub const FLIGHT_KP_A_PER_RAD: (f64, f64) = of(&fw::FLIGHT_KP);
    /// Flight PD derivative gain, A s/rad.
    pub const FLIGHT_KD_A_S_PER_RAD: (f64, f64) = of(&fw::FLIGHT_KD);
    /// Load-cell noise, N (1 sigma).
    pub const LOADCELL_SIGMA_N: (f64, f64) = (0.0, 1000.0);
    /// Potentiometer noise, m (1 sigma).
    pub const POT_SIGMA_M: (f64, f64) = (0.0, 0.1);
    /// Control rate, Hz (the runner's 1e-6 ..= 0.01 s period).
    pub const CONTROL_HZ: (f64, f64) = (100.0, 1e6);
}

/// A firmware parameter with a flag (and scenario key) of its own: such
/// parameters are set there only, so that one precedence (flag over file)
/// and the run's checks (the flight PD's stability, the reported target)
/// apply to them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dedicated {
    /// `controller`.
    Controller,
    /// `target_apex_m`.
    TargetApex,
    /// `flight.kp_a_per_rad`.
    FlightKp,
    /// `flight.kd_a_s_per_rad`.
    FlightKd,
    /// `constant_torque.torque_nm`, `modified_torque.torque_nm`.
    Torque,
    /// `energy.gain_nm_per_j`, `energy_apex.gain_nm_per_j`.
    EnergyGain,
}

impl Dedicated {
    /// The dedicated setting of firmware parameter `name`, if it has one
    /// (its alias has a flag, [`crate::names`]).
    pub fn of(name: &str) -> Option<Self> {
        let alias = crate::names::of(name).filter(|a| a.flag.is_some())?;
        Some(match alias.name() {
            "controller" => Dedicated::Controller,
            "target_apex_m" => Dedicated::TargetApex,
            "flight.kp_a_per_rad" => Dedicated::FlightKp,
            "flight.kd_a_s_per_rad" => Dedicated::FlightKd,
            "constant_torque.torque_nm" => Dedicated::Torque,
            "energy.gain_nm_per_j" => Dedicated::EnergyGain,
            // A run setting (the start height, the seed), not a firmware
            // parameter.
            _ => return None,
        })
    }

    /// The firmware parameter it stands for (the first, where it sets two).
    fn name(self) -> &'static str {
        use hopper_control::params as fw;
        match self {
            Dedicated::Controller => fw::CONTROLLER.name,
            Dedicated::TargetApex => fw::TARGET_APEX_M.name,
            Dedicated::FlightKp => fw::FLIGHT_KP.name,
            Dedicated::FlightKd => fw::FLIGHT_KD.name,
            Dedicated::Torque => fw::CONSTANT_TORQUE_NM.name,
            Dedicated::EnergyGain => fw::ENERGY_GAIN.name,
        }
    }

    /// Where to set it: `--flag / scenario.key`.
    pub fn flag(self) -> String {
        crate::names::of(self.name())
            .and_then(crate::names::Alias::setter)
            .unwrap_or_default()
    }
}

/// Why a firmware parameter setting was refused ([`table_setting`]).
enum SettingError<E> {
    /// It is set by its own flag.
    Dedicated(Dedicated),
    /// The value could not be read.
    Value(E),
    /// The value (given here) is outside the parameter's range.
    OutOfRange(f64),
}

/// The one check of a firmware parameter setting, for `--set` and a
/// scenario's `[params]`, in this order: `p` has no setting of its own, its
/// value can be read, and the value is in its range.
fn table_setting<E>(
    p: &'static Param,
    value: impl FnOnce() -> Result<f64, E>,
) -> Result<f32, SettingError<E>> {
    if let Some(d) = Dedicated::of(p.name) {
        return Err(SettingError::Dedicated(d));
    }
    let v = value().map_err(SettingError::Value)?;
    p.check(v as f32).map_err(|_| SettingError::OutOfRange(v))
}

/// Parses `NAME=VALUE` for a firmware parameter of the table
/// ([`hopper_control::params`]): the name must exist and the value be in its
/// range (flags 0/1, choices by index or name).
pub fn parse_param_setting(spec: &str) -> Result<(&'static Param, f32), String> {
    let (name, value) = spec.split_once('=').ok_or_else(|| {
        format!("bad --set `{spec}`: expected NAME=VALUE, e.g. shaped.switch_fraction=0.5")
    })?;
    let (name, value) = (name.trim(), value.trim());
    let p = hopper_control::params::find(name).ok_or_else(|| {
        format!("bad --set `{spec}`: no firmware parameter `{name}` (see docs/parameters.md)")
    })?;
    let read = || match p.kind {
        // A choice may be given by its name.
        hopper_control::params::Kind::Choice(names) => match names.iter().position(|n| *n == value)
        {
            Some(i) => Ok(i as f64),
            None => value
                .parse::<f64>()
                .map_err(|_| format!("bad --set `{spec}`: `{name}` is one of {names:?}")),
        },
        _ => value
            .parse::<f64>()
            .map_err(|_| format!("bad --set `{spec}`: `{value}` is not a number")),
    };
    let v = table_setting(p, read).map_err(|e| match e {
        SettingError::Dedicated(d) => {
            format!("bad --set `{spec}`: set `{name}` with {}", d.flag())
        }
        SettingError::Value(message) => message,
        SettingError::OutOfRange(_) => {
            let unit = crate::controller::unit_suffix(p);
            format!(
                "bad --set `{spec}`: `{name}` must be in {}{unit} ..= {}{unit}",
                p.min, p.max
            )
        }
    })?;
    Ok((p, v))
}

/// Settings that may or may not be given: by a scenario file or by flags.
/// `None` means "not given here".
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Overrides {
    /// A robot file (`--robot`) and the plant it describes: the plant
    /// unless `plant` is given, the firmware's entries before any other
    /// named parameter (its `model.*` ones unless `model` is given).
    pub robot: Option<(hopper_robot_file::Robot, PlantSet)>,
    /// Plant parameters, the name they are reported under, their preset.
    pub plant: Option<PlantSet>,
    /// What the controller believes (default: the plant).
    pub model: Option<Params>,
    /// A catalogue motor on the plant, its thermal data in the firmware
    /// ([`crate::motors`]).
    pub motor: Option<&'static crate::motors::CatalogueMotor>,
    /// Controller name, one of [`CONTROLLER_NAMES`].
    pub controller: Option<ControllerKind>,
    /// Apex target, m.
    pub target_apex_m: Option<f64>,
    /// Torque of open-torque / modified-torque, N m.
    pub torque_nm: Option<f64>,
    /// Energy-law gain `K_e` (energy, energy-apex), N m/J.
    pub energy_gain_nm_per_j: Option<f64>,
    /// Flight PD proportional gain, A/rad.
    pub flight_kp_a_per_rad: Option<f64>,
    /// Flight PD derivative gain, A s/rad.
    pub flight_kd_a_s_per_rad: Option<f64>,
    /// Sensor noise on or off.
    pub noise: Option<bool>,
    /// Noise seed.
    pub seed: Option<u64>,
    /// Load-cell noise, N (1 sigma).
    pub loadcell_sigma_n: Option<f64>,
    /// Potentiometer noise, m (1 sigma).
    pub pot_sigma_m: Option<f64>,
    /// Start toe height, m.
    pub start_apex_m: Option<f64>,
    /// Simulated time, s.
    pub duration_s: Option<f64>,
    /// Control rate, Hz.
    pub control_hz: Option<f64>,
    /// Faults to inject (a given list replaces the other layer's whole list).
    pub inject: Option<Vec<Injection>>,
    /// Firmware parameters set by name (a given list replaces the other
    /// layer's whole list).
    pub firmware_params: Option<Vec<(&'static Param, f32)>>,
}

impl Overrides {
    /// `self` with every setting `over` gives replaced by `over`'s.
    pub fn overridden_by(&self, over: &Overrides) -> Overrides {
        Overrides {
            robot: over.robot.clone().or_else(|| self.robot.clone()),
            plant: over.plant.clone().or_else(|| self.plant.clone()),
            model: over.model.or(self.model),
            motor: over.motor.or(self.motor),
            controller: over.controller.or(self.controller),
            target_apex_m: over.target_apex_m.or(self.target_apex_m),
            torque_nm: over.torque_nm.or(self.torque_nm),
            energy_gain_nm_per_j: over.energy_gain_nm_per_j.or(self.energy_gain_nm_per_j),
            flight_kp_a_per_rad: over.flight_kp_a_per_rad.or(self.flight_kp_a_per_rad),
            flight_kd_a_s_per_rad: over.flight_kd_a_s_per_rad.or(self.flight_kd_a_s_per_rad),
            noise: over.noise.or(self.noise),
            seed: over.seed.or(self.seed),
            loadcell_sigma_n: over.loadcell_sigma_n.or(self.loadcell_sigma_n),
            pot_sigma_m: over.pot_sigma_m.or(self.pot_sigma_m),
            start_apex_m: over.start_apex_m.or(self.start_apex_m),
            duration_s: over.duration_s.or(self.duration_s),
            control_hz: over.control_hz.or(self.control_hz),
            inject: over.inject.clone().or_else(|| self.inject.clone()),
            firmware_params: over
                .firmware_params
                .clone()
                .or_else(|| self.firmware_params.clone()),
        }
    }
}

/// Every setting of a run, resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Plant parameters.
    pub params: Params,
    /// Name the parameters are reported under (preset, file or scenario).
    pub params_name: String,
    /// The preset the plant starts from (its controller defaults apply:
    /// the design preset's Table 2.1 flight law).
    pub preset: Option<&'static str>,
    /// What the controller believes (None: the plant).
    pub model: Option<Params>,
    /// The catalogue motor on the plant (None: the plant's own).
    pub motor: Option<&'static crate::motors::CatalogueMotor>,
    /// Controller name.
    pub controller: ControllerKind,
    /// Apex target, m.
    pub target_apex_m: f64,
    /// Torque of open-torque / modified-torque (None: the law's 1 N m), N m.
    pub torque_nm: Option<f64>,
    /// Energy-law gain (None: the law's default), N m/J.
    pub energy_gain_nm_per_j: Option<f64>,
    /// Flight PD proportional gain (None: the preset's, else eq 4.13), A/rad.
    pub flight_kp_a_per_rad: Option<f64>,
    /// Flight PD derivative gain (None: the preset's, else eq 4.13), A s/rad.
    pub flight_kd_a_s_per_rad: Option<f64>,
    /// Sensor noise and amplifier lag.
    pub sensors: SensorConfig,
    /// Firmware parameters set by name ([`hopper_control::params`]; a
    /// sweep sets them), applied last.
    pub firmware_params: Vec<(&'static Param, f32)>,
    /// Start toe height, m.
    pub start_apex_m: f64,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Control rate, Hz.
    pub control_hz: f64,
    /// Faults to inject.
    pub inject: Vec<Injection>,
}

impl Settings {
    /// Layer `cli` over `file` over the defaults.
    pub fn resolve(file: Option<&Overrides>, cli: &Overrides) -> Settings {
        let o = file.cloned().unwrap_or_default().overridden_by(cli);
        let d = SensorConfig::DEFAULT;
        // A robot file's entries come first: the motor's and the named
        // parameters override them. What the controller believes, when
        // given apart (`model`), keeps the robot's `model.*` out.
        let robot_params: Vec<(&'static Param, f32)> = o
            .robot
            .as_ref()
            .map(|(r, _)| {
                r.values
                    .iter()
                    .copied()
                    .filter(|(p, _)| o.model.is_none() || !p.name.starts_with("model."))
                    .collect()
            })
            .unwrap_or_default();
        let plant = o.plant.or_else(|| o.robot.map(|(_, plant)| plant));
        let plant = plant.unwrap_or_else(|| PlantSet {
            params: Params::design(),
            name: DEFAULT_PARAMS.to_string(),
            preset: Params::preset_name(DEFAULT_PARAMS),
        });
        // A motor replaces the plant's motor and sets the firmware's thermal
        // data. Its settings and the named parameters apply layer by layer:
        // a layer's own parameters after its motor, the flags' motor after
        // the file's parameters (the flags win, as everywhere).
        let (params, params_name, motor_settings) = match o.motor {
            Some(m) => (
                m.on(&plant.params),
                format!("{}+{}", plant.name, m.name),
                m.firmware_settings(),
            ),
            None => (plant.params, plant.name, Vec::new()),
        };
        let named = o.firmware_params.unwrap_or_default();
        let motor_from_flags_over_file_params =
            cli.motor.is_some() && cli.firmware_params.is_none();
        let firmware_params: Vec<_> = if motor_from_flags_over_file_params {
            robot_params
                .into_iter()
                .chain(named)
                .chain(motor_settings)
                .collect()
        } else {
            robot_params
                .into_iter()
                .chain(motor_settings)
                .chain(named)
                .collect()
        };
        Settings {
            params,
            params_name,
            preset: plant.preset,
            model: o.model,
            motor: o.motor,
            controller: o.controller.unwrap_or(DEFAULT_CONTROLLER),
            target_apex_m: o.target_apex_m.unwrap_or(DEFAULT_TARGET_APEX_M),
            torque_nm: o.torque_nm,
            energy_gain_nm_per_j: o.energy_gain_nm_per_j,
            flight_kp_a_per_rad: o.flight_kp_a_per_rad,
            flight_kd_a_s_per_rad: o.flight_kd_a_s_per_rad,
            sensors: SensorConfig {
                noise: o.noise.unwrap_or(d.noise),
                seed: o.seed.unwrap_or(d.seed),
                loadcell_sigma_n: o.loadcell_sigma_n.unwrap_or(d.loadcell_sigma_n),
                pot_sigma_m: o.pot_sigma_m.unwrap_or(d.pot_sigma_m),
                ..d
            },
            firmware_params,
            start_apex_m: o.start_apex_m.unwrap_or(DEFAULT_START_APEX_M),
            duration_s: o.duration_s.unwrap_or(DEFAULT_DURATION_S),
            control_hz: o.control_hz.unwrap_or(DEFAULT_CONTROL_HZ),
            inject: o.inject.unwrap_or_default(),
        }
    }

    /// The runner's configuration; `sample_dt_s = 0` records no trajectory.
    pub fn run_config(&self, sample_dt_s: f64) -> RunConfig {
        RunConfig {
            params: self.params,
            start_apex_m: self.start_apex_m,
            duration_s: self.duration_s,
            control_dt_s: 1.0 / self.control_hz,
            sample_dt_s,
        }
    }

    /// The controller to build, with the gains overridden where given.
    pub fn controller_spec(&self) -> Result<ControllerSpec, String> {
        let mut spec = ControllerSpec {
            target_apex_m: self.target_apex_m,
            torque_nm: self.torque_nm,
            sensors: self.sensors,
            model: self.model,
            preset: self.preset,
            injections: self.inject.clone(),
            ..ControllerSpec::new(self.controller.name())
        };
        spec.params = self.firmware_params.clone();
        if let Some(ke) = self.energy_gain_nm_per_j {
            check_range(
                "energy_gain_nm_per_j",
                ke,
                limits::ENERGY_GAIN_NM_PER_J,
                "N m/J",
            )?;
            spec.strategy_override = Some(match self.controller {
                ControllerKind::Energy => Strategy::Thesis(StanceLaw::Energy(energy::Config {
                    gain_nm_per_j: ke as f32,
                    ..energy::Config::default()
                })),
                ControllerKind::EnergyApex => {
                    let d = ApexLoop::default();
                    Strategy::EnergyApex(ApexLoop {
                        law: energy::Config {
                            gain_nm_per_j: ke as f32,
                            ..d.law
                        },
                        ..d
                    })
                }
                other => {
                    return Err(format!(
                        "the energy-law gain (ke, energy_gain_nm_per_j) applies to the energy and energy-apex controllers only, not `{other}`"
                    ))
                }
            });
        }
        if self.flight_kp_a_per_rad.is_some() || self.flight_kd_a_s_per_rad.is_some() {
            if self.controller == ControllerKind::Shaped {
                return Err(
                    "the flight PD gains (--flight-kp, --flight-kd) do not apply to the shaped controller: it has its own braking-curve back-drive"
                        .into(),
                );
            }
            let d = flight_pd::Config {
                gains: spec.default_flight_gains(self.model.as_ref().unwrap_or(&self.params))?,
                ..flight_pd::Config::default()
            };
            let kp = self.flight_kp_a_per_rad.unwrap_or(f64::from(d.gains.kp));
            let kd = self.flight_kd_a_s_per_rad.unwrap_or(f64::from(d.gains.kd));
            check_range(
                &Dedicated::FlightKp.flag(),
                kp,
                limits::FLIGHT_KP_A_PER_RAD,
                "A/rad",
            )?;
            check_range(
                &Dedicated::FlightKd.flag(),
                kd,
                limits::FLIGHT_KD_A_S_PER_RAD,
                "A s/rad",
            )?;
            spec.flight_override = Some(flight_pd::Config {
                gains: PdGains {
                    kp: kp as f32,
                    kd: kd as f32,
                },
                ..d
            });
        }
        Ok(spec)
    }

    /// Check everything a run needs, without running: the run settings, the
    /// controller name and settings, and that the firmware accepts its
    /// configuration.
    pub fn check(&self) -> Result<(), String> {
        if !(self.control_hz.is_finite() && self.control_hz > 0.0) {
            // The runner checks the period's range; this catches 0 and NaN first.
            return Err(format!(
                "--control-hz {} must be a positive number of Hz",
                self.control_hz
            ));
        }
        let s = &self.sensors;
        check_range(
            "loadcell_sigma_n",
            s.loadcell_sigma_n,
            limits::LOADCELL_SIGMA_N,
            "N",
        )?;
        check_range("pot_sigma_m", s.pot_sigma_m, limits::POT_SIGMA_M, "m")?;
        let cfg = self.run_config(0.0);
        cfg.validate()?;
        self.check_model_stroke()?;
        if let Some(late) = self.inject.iter().find(|i| i.time_s >= self.duration_s) {
            return Err(format!(
                "fault injection `{late}` is at or after the end of the run ({} s)",
                self.duration_s
            ));
        }
        let spec = self.controller_spec()?;
        self.check_flight_pd(&spec)?;
        spec.build(&cfg.params, cfg.start_apex_m, cfg.control_dt_s)
            .map(|_| ())
    }

    /// The believed model may not claim more stroke than the plant has: the
    /// supervisor's soft limits come from the model's stroke, so a longer one
    /// would let the firmware drive the nut into the real stop at speed.
    fn check_model_stroke(&self) -> Result<(), String> {
        let Some(model) = &self.model else {
            return Ok(());
        };
        if model.stroke_m > self.params.stroke_m {
            return Err(format!(
                "model.stroke_m = {} m is larger than the plant's mechanical stroke plant.stroke_m = {} m: the controller's model may not exceed the hardware",
                model.stroke_m, self.params.stroke_m
            ));
        }
        Ok(())
    }

    /// Reject flight PD gains (given or default) that make the sampled
    /// flight loop grow at this control rate on this plant
    /// ([`crate::flight_stability`]). Checked here, where the rate and the
    /// plant are known, so `run`, every sweep point and scenario files all
    /// get it; the passive strategy never runs the flight PD.
    /// The eq 4.1 filter gain the firmware will run with (the table's
    /// `estimator.velocity_filter_gain` when set, else its default).
    fn filter_gain(&self) -> f64 {
        self.firmware_params
            .iter()
            .rev()
            .find(|(p, _)| p.name == hopper_control::params::EST_FILTER_GAIN.name)
            .map_or(
                f64::from(EstimatorConfig::default().velocity_filter_gain),
                |(_, v)| f64::from(*v),
            )
    }

    fn check_flight_pd(&self, spec: &ControllerSpec) -> Result<(), String> {
        if self.controller == ControllerKind::Passive {
            return Ok(());
        }
        let gains = match spec.flight_override {
            Some(f) => f.gains,
            None => spec.default_flight_gains(self.model.as_ref().unwrap_or(&self.params))?,
        };
        let (kp, kd) = (f64::from(gains.kp), f64::from(gains.kd));
        let lp = FlightLoop {
            plant_gain: flight_stability::plant_gain(&self.params),
            kp,
            kd,
            dt_s: 1.0 / self.control_hz,
            filter_gain: self.filter_gain(),
            amp_tau_s: self.sensors.amp_tau_s,
        };
        if (kp == 0.0 && kd == 0.0) || lp.is_stable() {
            return Ok(());
        }
        let hz = self.control_hz;
        match flight_stability::stable_kd_range(&lp) {
            Some((lo, hi)) => {
                let why = if kd == 0.0 {
                    "position feedback without damping grows"
                } else {
                    "the sampled loop grows"
                };
                // The gains as f32 (what the firmware runs) print as given.
                Err(format!(
                    "{} = {} A s/rad makes the flight PD unstable ({why}) with kp = {} A/rad at {hz} Hz: stable for kd in {lo:.4} ..= {hi:.4} A s/rad (A = {:.1} rad/s^2/A, eq 4.1 filter G = {})",
                    Dedicated::FlightKd.flag(),
                    gains.kd, gains.kp, lp.plant_gain, self.filter_gain() as f32
                ))
            }
            None => Err(format!(
                "{} = {} A/rad gives an unstable flight PD at --control-hz / control_hz = {hz} Hz for every kd up to 1000 A s/rad: raise the control rate or lower kp",
                Dedicated::FlightKp.flag(),
                gains.kp
            )),
        }
    }
}

fn check_range(name: &str, v: f64, (lo, hi): (f64, f64), unit: &'static str) -> Result<(), String> {
    let range = Range::new(lo, false, hi, unit);
    if range.allows(v) {
        Ok(())
    } else {
        Err(format!("{name} = {v} is out of range: allowed {range}"))
    }
}

/// The `[sweep]` table of a scenario file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SweepSection {
    /// `NAME=START:END:N` specs, as for `hopper-sim sweep --param`.
    pub params: Vec<String>,
    /// Metric to plot.
    pub metric: Option<String>,
}

/// A parsed scenario file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scenario {
    /// Where it came from (file name), for messages.
    pub origin: String,
    /// Free text.
    pub description: Option<String>,
    /// The settings the file gives.
    pub settings: Overrides,
    /// Its `[sweep]` table.
    pub sweep: SweepSection,
}

/// A scenario file could not be used: where (`file:line` or the file) and what.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioError {
    /// `file:line`, or the file when no line applies.
    pub location: String,
    /// What went wrong, naming the key.
    pub message: String,
}

impl std::fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.location, self.message)
    }
}

impl std::error::Error for ScenarioError {}

impl From<ParamsFileError> for ScenarioError {
    fn from(e: ParamsFileError) -> Self {
        ScenarioError {
            location: e.location,
            message: e.message,
        }
    }
}

/// Read and parse a scenario file.
pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
    let origin = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError {
        location: origin.clone(),
        message: format!("cannot read scenario file: {e}"),
    })?;
    from_toml_str(&text, &origin)
}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

/// Line of every key, by dotted path (`controller.name`), from the spanned parse.
fn key_lines(
    text: &str,
    table: &toml::de::DeTable<'_>,
    prefix: &str,
    out: &mut HashMap<String, usize>,
) {
    for (k, v) in table.iter() {
        let path = format!("{prefix}{}", k.get_ref());
        out.insert(path.clone(), line_of(text, k.span().start));
        if let toml::de::DeValue::Table(t) = v.get_ref() {
            key_lines(text, t, &format!("{path}."), out);
        }
    }
}

/// A scenario file as serde reads it: every table refuses unknown keys, and
/// the types are checked here; presets, names and ranges after, by
/// [`from_toml_str`], with the line of the key.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileToml {
    description: Option<String>,
    /// A preset name or a table read like a parameter file.
    plant: Option<toml::Value>,
    /// The same, for what the controller believes.
    model: Option<toml::Value>,
    /// A catalogue motor's name ([`crate::motors::MOTORS`]).
    motor: Option<String>,
    start_apex_m: Option<f64>,
    duration_s: Option<f64>,
    control_hz: Option<f64>,
    inject: Option<Vec<String>>,
    /// A controller name or a [`ControllerToml`] table.
    controller: Option<toml::Value>,
    sensors: Option<SensorsToml>,
    sweep: Option<SweepToml>,
    /// Firmware parameters by their table names (docs/parameters.md).
    params: Option<toml::Table>,
}

/// `[controller]`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ControllerToml {
    name: Option<String>,
    target_apex_m: Option<f64>,
    torque_nm: Option<f64>,
    energy_gain_nm_per_j: Option<f64>,
    flight_kp_a_per_rad: Option<f64>,
    flight_kd_a_s_per_rad: Option<f64>,
}

/// `[sensors]`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorsToml {
    noise: Option<bool>,
    seed: Option<u64>,
    loadcell_sigma_n: Option<f64>,
    pot_sigma_m: Option<f64>,
}

/// `[sweep]`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SweepToml {
    /// One `NAME=START:END:N` or a list of them.
    param: Option<OneOrMany>,
    metric: Option<String>,
}

/// A string or a list of strings.
#[derive(Deserialize)]
#[serde(untagged)]
enum OneOrMany {
    One(String),
    Many(Vec<String>),
}

/// The controller called `name`, or the file's error for `path`.
fn controller_named(
    r: &Reader<'_>,
    name: &str,
    path: &str,
) -> Result<ControllerKind, ScenarioError> {
    ControllerKind::from_name(name).ok_or_else(|| {
        r.err(
            path,
            format!(
                "unknown controller `{name}` in `{path}`: expected one of {CONTROLLER_NAMES:?}"
            ),
        )
    })
}

/// A serde message about the key at `path`, in this file's words: an
/// unknown key, or a value of the wrong type.
fn describe_serde(message: &str, path: &str) -> String {
    if let Some(rest) = message.strip_prefix("unknown field `") {
        let expected = rest.split_once("`, expected ").map_or("", |(_, e)| e);
        return format!("unknown key `{path}`: expected {expected}");
    }
    let (got, wanted) = match message.split_once(", expected ") {
        Some((got, wanted)) => (
            got.trim_start_matches("invalid type: ")
                .trim_start_matches("invalid value: "),
            wanted,
        ),
        // The one untagged type: `sweep.param`.
        None if message.contains("untagged enum OneOrMany") => {
            return format!("`{path}` must be a NAME=START:END:N string or a list of them")
        }
        None => return format!("`{path}`: {message}"),
    };
    let wanted = match wanted {
        "f64" => "a number",
        "u64" => "a non-negative integer",
        "a boolean" => "true or false",
        "a sequence" => "a list",
        other => other,
    };
    format!("`{path}` must be {wanted}, got {got}")
}

struct Reader<'a> {
    origin: &'a str,
    /// The line of every key, by its dotted path.
    lines: HashMap<String, usize>,
}

impl Reader<'_> {
    fn err(&self, path: &str, message: String) -> ScenarioError {
        ScenarioError {
            location: match self.lines.get(path) {
                Some(l) => format!("{}:{l}", self.origin),
                None => self.origin.to_string(),
            },
            message,
        }
    }

    /// The deepest key path on `line`, if a key is there.
    fn path_on_line(&self, line: usize) -> Option<&str> {
        self.lines
            .iter()
            .filter(|(_, l)| **l == line)
            .map(|(p, _)| p.as_str())
            .max_by_key(|p| p.len())
    }

    /// `value` at `path` if it lies in `(lo, hi)` (`lo` itself refused when
    /// `lo_exclusive`), in `unit`.
    fn ranged(
        &self,
        path: &str,
        value: Option<f64>,
        (lo, hi): (f64, f64),
        lo_exclusive: bool,
        unit: &'static str,
    ) -> Result<Option<f64>, ScenarioError> {
        let Some(v) = value else {
            return Ok(None);
        };
        let range = Range::new(lo, lo_exclusive, hi, unit);
        if !range.allows(v) {
            return Err(self.err(
                path,
                format!("`{path}` = {v} is out of range: allowed {range}"),
            ));
        }
        Ok(Some(v))
    }

    /// A parameter set: a preset name or a table read like a parameter file.
    fn params(
        &self,
        value: Option<&toml::Value>,
        key: &str,
    ) -> Result<Option<PlantSet>, ScenarioError> {
        match value {
            None => Ok(None),
            Some(toml::Value::String(name)) => match PlantSet::preset(name) {
                Some(set) => Ok(Some(set)),
                None => Err(self.err(
                    key,
                    format!(
                        "unknown preset `{key} = \"{name}\"`: expected one of {:?} or a table of parameters",
                        Params::PRESET_NAMES
                    ),
                )),
            },
            Some(toml::Value::Table(t)) => {
                let prefix = format!("{key}.");
                let line_for = |k: &str| self.lines.get(&format!("{prefix}{k}")).copied();
                let p = params_toml::params_from_table(t, self.origin, &prefix, &line_for)?;
                Ok(Some(PlantSet {
                    params: p,
                    name: self.origin.to_string(),
                    preset: params_toml::base_of(t),
                }))
            }
            Some(other) => Err(self.err(
                key,
                format!("`{key}` must be a preset name or a table of parameters, got {other}"),
            )),
        }
    }

    /// `[params]`: firmware parameters by name, each checked against the table.
    fn firmware_params(
        &self,
        table: &toml::Table,
    ) -> Result<Vec<(&'static Param, f32)>, ScenarioError> {
        let mut list = Vec::new();
        for (name, value) in table {
            let key = format!("params.{name}");
            let path = format!("params.\"{name}\"");
            let p = hopper_control::params::find(name).ok_or_else(|| {
                self.err(
                    &key,
                    format!("unknown firmware parameter `{path}` (see docs/parameters.md)"),
                )
            })?;
            let read = || match value {
                toml::Value::Float(f) => Ok(*f),
                toml::Value::Integer(i) => Ok(*i as f64),
                toml::Value::Boolean(b) => Ok(f64::from(u8::from(*b))),
                other => Err(format!("`{path}` must be a number, got {other}")),
            };
            let v = table_setting(p, read).map_err(|e| {
                let message = match e {
                    SettingError::Dedicated(d) => format!("set `{path}` with {}", d.flag()),
                    SettingError::Value(message) => message,
                    SettingError::OutOfRange(v) => {
                        let unit = crate::controller::unit_suffix(p);
                        format!(
                            "`{path}` = {v} is out of range: allowed {}{unit} ..= {}{unit}",
                            p.min, p.max
                        )
                    }
                };
                self.err(&key, message)
            })?;
            list.push((p, v));
        }
        Ok(list)
    }
}

/// Parse a scenario file's text. `origin` names it in errors and is the
/// name the plant parameters are reported under when the file gives them as
/// a table.
pub fn from_toml_str(text: &str, origin: &str) -> Result<Scenario, ScenarioError> {
    let spanned = toml::de::DeTable::parse(text).map_err(|e| ScenarioError {
        location: match e.span() {
            Some(s) => format!("{origin}:{}", line_of(text, s.start)),
            None => origin.to_string(),
        },
        message: format!("malformed TOML: {}", e.message()),
    })?;
    let mut lines = HashMap::new();
    key_lines(text, spanned.get_ref(), "", &mut lines);
    let r = Reader { origin, lines };
    let file: FileToml = toml::from_str(text).map_err(|e| {
        let line = e.span().map(|s| line_of(text, s.start));
        let path = line
            .and_then(|l| r.path_on_line(l))
            .unwrap_or("")
            .to_string();
        ScenarioError {
            location: match line {
                Some(l) => format!("{origin}:{l}"),
                None => origin.to_string(),
            },
            message: describe_serde(e.message(), &path),
        }
    })?;
    let mut s = Overrides {
        plant: r.params(file.plant.as_ref(), "plant")?,
        model: r
            .params(file.model.as_ref(), "model")?
            .map(|set| set.params),
        start_apex_m: r.ranged(
            "start_apex_m",
            file.start_apex_m,
            crate::run::START_APEX_RANGE_M,
            true,
            "m",
        )?,
        duration_s: r.ranged(
            "duration_s",
            file.duration_s,
            (0.0, crate::run::MAX_DURATION_S),
            true,
            "s",
        )?,
        control_hz: r.ranged(
            "control_hz",
            file.control_hz,
            limits::CONTROL_HZ,
            false,
            "Hz",
        )?,
        ..Overrides::default()
    };
    if let Some(name) = &file.motor {
        s.motor = Some(crate::motors::named(name).map_err(|e| r.err("motor", e))?);
    }
    if let Some(list) = &file.inject {
        s.inject = Some(
            list.iter()
                .map(|spec| Injection::parse(spec).map_err(|e| r.err("inject", e)))
                .collect::<Result<_, _>>()?,
        );
    }
    match file.controller {
        None => {}
        Some(toml::Value::String(name)) => {
            s.controller = Some(controller_named(&r, &name, "controller")?)
        }
        Some(table @ toml::Value::Table(_)) => {
            let c = ControllerToml::deserialize(table).map_err(|e| {
                // A value deserialiser has no spans: the key is in the text,
                // in the message of an unknown field, after "in" otherwise.
                let message = e.message().to_string();
                let full = e.to_string();
                let key = message
                    .strip_prefix("unknown field `")
                    .and_then(|rest| rest.split_once('`'))
                    .map(|(k, _)| k)
                    .or_else(|| {
                        full.rsplit_once("in `")
                            .and_then(|(_, k)| k.split('`').next())
                    })
                    .unwrap_or("");
                let path = format!("controller.{key}");
                let at = if r.lines.contains_key(&path) {
                    path.as_str()
                } else {
                    "controller"
                };
                r.err(at, describe_serde(&message, &path))
            })?;
            let p = "controller.";
            s.controller = match &c.name {
                Some(name) => Some(controller_named(&r, name, "controller.name")?),
                None => None,
            };
            let at = |k: &str| format!("{p}{k}");
            s.target_apex_m = r.ranged(
                &at("target_apex_m"),
                c.target_apex_m,
                limits::TARGET_APEX_M,
                false,
                "m",
            )?;
            s.torque_nm = r.ranged(
                &at("torque_nm"),
                c.torque_nm,
                limits::TORQUE_NM,
                false,
                "N m",
            )?;
            s.energy_gain_nm_per_j = r.ranged(
                &at("energy_gain_nm_per_j"),
                c.energy_gain_nm_per_j,
                limits::ENERGY_GAIN_NM_PER_J,
                false,
                "N m/J",
            )?;
            s.flight_kp_a_per_rad = r.ranged(
                &at("flight_kp_a_per_rad"),
                c.flight_kp_a_per_rad,
                limits::FLIGHT_KP_A_PER_RAD,
                false,
                "A/rad",
            )?;
            s.flight_kd_a_s_per_rad = r.ranged(
                &at("flight_kd_a_s_per_rad"),
                c.flight_kd_a_s_per_rad,
                limits::FLIGHT_KD_A_S_PER_RAD,
                false,
                "A s/rad",
            )?;
        }
        Some(other) => {
            return Err(r.err(
                "controller",
                format!("`controller` must be a controller name or a table, got {other}"),
            ))
        }
    }
    if let Some(t) = &file.sensors {
        s.noise = t.noise;
        s.seed = t.seed;
        s.loadcell_sigma_n = r.ranged(
            "sensors.loadcell_sigma_n",
            t.loadcell_sigma_n,
            limits::LOADCELL_SIGMA_N,
            false,
            "N",
        )?;
        s.pot_sigma_m = r.ranged(
            "sensors.pot_sigma_m",
            t.pot_sigma_m,
            limits::POT_SIGMA_M,
            false,
            "m",
        )?;
    }
    if let Some(t) = &file.params {
        s.firmware_params = Some(r.firmware_params(t)?);
    }
    let sweep = match file.sweep {
        None => SweepSection::default(),
        Some(t) => SweepSection {
            params: match t.param {
                None => Vec::new(),
                Some(OneOrMany::One(one)) => vec![one],
                Some(OneOrMany::Many(list)) => list,
            },
            metric: t.metric,
        },
    };
    Ok(Scenario {
        origin: origin.to_string(),
        description: file.description,
        settings: s,
        sweep,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_err(text: &str) -> ScenarioError {
        match from_toml_str(text, "s.toml") {
            Ok(s) => panic!("parsed: {s:?}"),
            Err(e) => e,
        }
    }

    #[test]
    fn full_scenario_parses() {
        let s = from_toml_str(
            "plant = { base = \"design\", spring_stiffness_n_per_m = 10000 }\nmodel = \"identified\"\nstart_apex_m = 0.1\nduration_s = 15\n[controller]\nname = \"energy-apex\"\ntarget_apex_m = 0.04\nenergy_gain_nm_per_j = 2\n[sensors]\nnoise = false\nseed = 7\n[sweep]\nparam = [\"torque=0.5:1:2\"]\n",
            "s.toml",
        )
        .unwrap();
        let o = &s.settings;
        let PlantSet {
            params: p, name, ..
        } = o.plant.clone().unwrap();
        assert_eq!(p.spring_stiffness_n_per_m, 10_000.0);
        assert_eq!(name, "s.toml");
        assert_eq!(o.model, Some(Params::identified()));
        assert_eq!(o.controller, Some(ControllerKind::EnergyApex));
        assert_eq!(o.target_apex_m, Some(0.04));
        assert_eq!(o.energy_gain_nm_per_j, Some(2.0));
        assert_eq!((o.noise, o.seed), (Some(false), Some(7)));
        assert_eq!((o.start_apex_m, o.duration_s), (Some(0.1), Some(15.0)));
        assert_eq!(s.sweep.params, vec!["torque=0.5:1:2".to_string()]);
        let set = Settings::resolve(Some(o), &Overrides::default());
        set.check().unwrap();
        assert!(set.controller_spec().unwrap().strategy_override.is_some());
    }

    #[test]
    fn firmware_parameters_by_name_parse_and_are_checked() {
        let s = from_toml_str(
            "[controller]\nname = \"energy-apex\"\n[params]\n\"energy_apex.integral_gain\" = 0.4\n\"energy_apex.allow_negative\" = true\n",
            "s.toml",
        )
        .unwrap();
        let list = s.settings.firmware_params.clone().unwrap();
        let got: Vec<(&str, f32)> = list.iter().map(|(p, v)| (p.name, *v)).collect();
        assert_eq!(
            got,
            vec![
                ("energy_apex.allow_negative", 1.0),
                ("energy_apex.integral_gain", 0.4)
            ]
        );
        let settings = Settings::resolve(Some(&s.settings), &Overrides::default());
        settings.check().unwrap();
        let e = parse_err("\n[params]\n\"energy_apex.integral_gain\" = 20\n");
        assert_eq!(e.location, "s.toml:3", "{e}");
        assert!(
            e.message.contains("out of range: allowed 0.001 ..= 9.99"),
            "{e}"
        );
        let e = parse_err("[params]\n\"flight.kp_a_per_rad\" = 5\n");
        assert!(e.message.contains("with --flight-kp"), "{e}");
        // A wrong type in [controller] names its key and line.
        let e = parse_err("[controller]\nname = \"energy\"\ntarget_apex_m = \"high\"\n");
        assert_eq!(e.location, "s.toml:3", "{e}");
        assert!(
            e.message
                .contains("`controller.target_apex_m` must be a number"),
            "{e}"
        );
        let e = parse_err("[params]\n\"no.such\" = 1\n");
        assert!(e.message.contains("unknown firmware parameter"), "{e}");
    }

    #[test]
    fn inject_list_parses_and_flags_replace_it() {
        let s = from_toml_str(
            "duration_s = 2\ninject = [\"estop@1.0\", \"nan@0.5\"]\n",
            "s.toml",
        )
        .unwrap();
        let list = s.settings.inject.clone().unwrap();
        assert_eq!(list.len(), 2);
        assert_eq!(list[1].kind, crate::inject::InjectKind::Nan);
        let settings = Settings::resolve(Some(&s.settings), &Overrides::default());
        assert_eq!(settings.controller_spec().unwrap().injections, list);
        let cli = Overrides {
            inject: Some(Vec::new()),
            ..Overrides::default()
        };
        assert!(Settings::resolve(Some(&s.settings), &cli).inject.is_empty());
        let e = parse_err("\n\ninject = [\"boom@1\"]\n");
        assert_eq!(e.location, "s.toml:3");
        assert!(e.message.contains("unknown fault kind `boom`"), "{e}");
        let e = parse_err("inject = \"estop@1\"\n");
        assert!(e.message.contains("must be a list"), "{e}");
    }

    #[test]
    fn errors_name_file_line_and_key() {
        let e = parse_err("duration_s = 1\n[controller]\nname = \"energy\"\ntagret_apex_m = 0.1\n");
        assert_eq!(e.location, "s.toml:4");
        assert!(e.message.contains("controller.tagret_apex_m"), "{e}");

        let e = parse_err("start_apex_m = 0.1\n\n[controller]\ntarget_apex_m = 3.0\n");
        assert_eq!(e.location, "s.toml:4");
        assert!(
            e.message.contains("controller.target_apex_m") && e.message.contains('3'),
            "{e}"
        );

        let e = parse_err("[plant]\nbase = \"design\"\nbody_mas_kg = 1\n");
        assert_eq!(e.location, "s.toml:3");
        assert!(e.message.contains("plant.body_mas_kg"), "{e}");

        let e = parse_err("plant = { base = \"design\", stroke_m = 9.0 }\n");
        assert_eq!(e.location, "s.toml:1");
        assert!(e.message.contains("plant.stroke_m"), "{e}");

        let e = parse_err("duration_s = \"long\"\n");
        assert_eq!(e.location, "s.toml:1");
        assert!(
            e.message.contains("duration_s") && e.message.contains("number"),
            "{e}"
        );

        let e = parse_err("\ncontroller = \"rocket\"\n");
        assert_eq!(e.location, "s.toml:2");
        assert!(e.message.contains("unknown controller `rocket`"), "{e}");

        let e = parse_err("[sensors]\nnoise = \"yes\"\n");
        assert_eq!(e.location, "s.toml:2");
        assert!(e.message.contains("sensors.noise"), "{e}");

        let e = parse_err("speed = 1\n");
        assert_eq!(e.location, "s.toml:1");
        assert!(e.message.contains("unknown key `speed`"), "{e}");

        let e = parse_err("duration_s = [1\n");
        assert!(e.location.starts_with("s.toml:"), "{e}");
        assert!(e.message.contains("malformed TOML"), "{e}");
    }

    #[test]
    fn flags_override_file_override_defaults() {
        let file = Overrides {
            controller: Some(ControllerKind::EnergyApex),
            target_apex_m: Some(0.04),
            duration_s: Some(15.0),
            seed: Some(3),
            ..Overrides::default()
        };
        let cli = Overrides {
            target_apex_m: Some(0.06),
            seed: Some(9),
            ..Overrides::default()
        };
        let s = Settings::resolve(Some(&file), &cli);
        assert_eq!(s.controller, ControllerKind::EnergyApex);
        assert_eq!(s.target_apex_m, 0.06);
        assert_eq!(s.duration_s, 15.0);
        assert_eq!(s.sensors.seed, 9);
        assert_eq!(s.start_apex_m, DEFAULT_START_APEX_M);
        assert_eq!(s.params_name, DEFAULT_PARAMS);
        let d = Settings::resolve(None, &Overrides::default());
        assert_eq!(d.controller, DEFAULT_CONTROLLER);
        assert_eq!(d.target_apex_m, DEFAULT_TARGET_APEX_M);
        assert_eq!(d.sensors, SensorConfig::DEFAULT);
        assert_eq!(d.control_hz, DEFAULT_CONTROL_HZ);
    }

    #[test]
    fn a_motor_and_named_parameters_apply_layer_by_layer() {
        use hopper_control::params as p;
        let motor = crate::motors::named("pittman-14204").ok();
        let file_r = (&p::THERMAL_RESISTANCE_OHM, 2.0_f32);
        let set_r = (&p::THERMAL_RESISTANCE_OHM, 3.0_f32);
        let last_r = |s: &Settings| {
            s.firmware_params
                .iter()
                .rev()
                .find(|(q, _)| q.name == p::THERMAL_RESISTANCE_OHM.name)
                .map(|(_, v)| *v)
        };
        let file = Overrides {
            firmware_params: Some(vec![file_r]),
            ..Overrides::default()
        };
        // The flags' motor over the file's parameters: the motor's data.
        let cli = Overrides {
            motor,
            ..Overrides::default()
        };
        assert_eq!(last_r(&Settings::resolve(Some(&file), &cli)), Some(1.01));
        // The file's motor under its own parameters: the file's value.
        let file_motor = Overrides {
            motor,
            ..file.clone()
        };
        assert_eq!(
            last_r(&Settings::resolve(Some(&file_motor), &Overrides::default())),
            Some(2.0)
        );
        // `--set` over any motor.
        let cli_set = Overrides {
            motor,
            firmware_params: Some(vec![set_r]),
            ..Overrides::default()
        };
        let s = Settings::resolve(Some(&file), &cli_set);
        assert_eq!(last_r(&s), Some(3.0));
        assert_eq!(s.params_name, "design+pittman-14204");
    }

    #[test]
    fn energy_gain_needs_an_energy_controller() {
        let s = Settings {
            energy_gain_nm_per_j: Some(1.0),
            ..Settings::resolve(None, &Overrides::default())
        };
        assert!(s.check().unwrap_err().contains("energy-apex"));
    }
}
