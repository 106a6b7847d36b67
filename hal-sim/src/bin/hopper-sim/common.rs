//! The settings of one run that `run`, `sweep` and `serve` share: the flags
//! over a scenario file over the defaults.

use anyhow::Result;
use clap::Args;
use hal_sim::inject::Injection;
use hal_sim::params_toml;
use hal_sim::scenario::{self, Overrides, Scenario, Settings};
use hopper_control::laws::ControllerKind;
use std::path::PathBuf;

/// The settings of one run, shared by `run` and `sweep`. Each is an
/// `Option` so that a scenario file's value survives when the flag is not
/// given; the defaults live in `hal_sim::scenario` and apply when neither
/// sets a value.
#[derive(Args)]
pub(crate) struct BaseArgs {
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
    /// A robot file (`hopper-sim params show design` writes one): the
    /// machine's constants, its calibration and the plant's own fields.
    /// The plant and the firmware both take it, unless --params gives the
    /// plant or --model-params what the controller believes; --set
    /// overrides its entries.
    #[arg(long, value_name = "FILE.toml")]
    robot: Option<PathBuf>,
    /// What the controller believes, separately from the plant (`--params`):
    /// a preset or a TOML file [default: the plant's parameters]. Try model
    /// error, e.g. a file with `base = "design"` and
    /// `spring_stiffness_n_per_m = 13200`.
    #[arg(long, value_name = "PRESET|PATH.toml")]
    model_params: Option<String>,
    /// A catalogue motor on the plant, its electrical and thermal data
    /// together: design (the preset's; thermal data the stand-in's, the
    /// RE 40's), re40 (maxon RE 40, 24 V), pittman-14204 (Pittman
    /// 14204S006; docs/endurance.md says which figures are the sheet's).
    /// The amplifier's current limit stays; the firmware believes the new
    /// motor unless --model-params says otherwise.
    #[arg(long, value_parser = parse_motor, value_name = "NAME")]
    motor: Option<&'static hal_sim::motors::CatalogueMotor>,
    /// Controller: one of the firmware's laws, the list from its registry.
    #[arg(long, value_parser = parse_controller, help = controller_help())]
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
    /// 1.8953 A/rad with the design motor; another motor's torque constant
    /// converts them).
    #[arg(long, allow_negative_numbers = true)]
    flight_kp: Option<f64>,
    /// Flight PD derivative gain, A s/rad (default: eq 4.13, 0.6077; the
    /// Chapter 2 laws on the design preset: Table 2.1's 300 N s/m on the
    /// nut, 0.0071073 A s/rad with the design motor).
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
    pub(crate) start_apex: Option<f64>,
    /// Simulated time, s [default: 5].
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) duration: Option<f64>,
    /// Control rate, Hz [default: 10000].
    #[arg(long)]
    control_hz: Option<f64>,
    /// Inject a fault, KIND@TIME (s); repeatable. KIND: encoder-jump,
    /// encoder-frozen, loadcell-stuck, loadcell-saturated, pot-open, nan,
    /// noise-burst, estop, amp-fault, dac-error, overrun (docs/safety.md).
    /// Replaces the scenario file's `inject` list.
    #[arg(long = "inject", value_name = "KIND@TIME")]
    pub(crate) inject: Vec<String>,
    /// Set a firmware parameter by its name in the parameter table
    /// (docs/parameters.md), e.g. `--set shaped.switch_fraction=0.5`;
    /// repeatable, applied after every other setting.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
}

/// `--motor NAME`: a catalogue motor.
fn parse_motor(
    name: &str,
) -> std::result::Result<&'static hal_sim::motors::CatalogueMotor, String> {
    hal_sim::motors::named(name)
}

/// `--controller NAME`: one of the firmware's controllers, by name.
/// `--controller`'s help: the laws the firmware registers, by name.
fn controller_help() -> String {
    format!(
        "Controller: {} (energy-apex: the apex-regulating energy law; shaped: docs/beat-the-thesis.md). Each is the firmware's control crate on the simulated sensors [default: passive]",
        hal_sim::controller::CONTROLLER_NAMES.join(", ")
    )
}

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
        let robot = match &self.robot {
            Some(path) => {
                let origin = path.display().to_string();
                let robot = hopper_robot_file::load(path).map_err(anyhow::Error::msg)?;
                let plant =
                    params_toml::plant_from_robot(&robot, &origin).map_err(anyhow::Error::msg)?;
                Some((robot, plant))
            }
            None => None,
        };
        Ok(Overrides {
            robot,
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
            motor: self.motor,
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
    pub(crate) fn scenario(&self) -> Result<Option<Scenario>> {
        self.scenario
            .as_deref()
            .map(scenario::load)
            .transpose()
            .map_err(anyhow::Error::msg)
    }
}

/// Flags over the scenario's settings over the defaults.
pub(crate) fn resolve(file: Option<&Scenario>, base: &BaseArgs) -> Result<Settings> {
    let cli = base.overrides()?;
    Ok(Settings::resolve(file.map(|s| &s.settings), &cli))
}
