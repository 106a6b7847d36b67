//! Controllers the simulator can run against the plant.
//!
//! Every named controller is the firmware's own control crate
//! ([`hopper_control::hopper::Hopper`]) behind the simulated hardware
//! ([`crate::sim_io::SimHal`]): the plant is sampled through the sensor models,
//! the crate computes a DAC code and the amplifier enable, and the plant is
//! driven with the amplifier's current over the period.

use crate::inject::{
    InjectKind, Injection, ENCODER_JUMP_COUNTS, NOISE_BURST_DURATION_S, NOISE_BURST_SIGMA_CODES,
};
use crate::params::Params;
use crate::plant::Plant;
use crate::sim_io::{firmware_config, model_params, SensorConfig, SimHal};
use hopper_control::arming::ArmEvent;
use hopper_control::estimator::PhaseEvent;
use hopper_control::hopper::{Hopper, MeasurementOverride, StepOutput, Strategy};
use hopper_control::laws::{flight_pd, modified_torque, open_torque, ControllerKind, StanceLaw};
use hopper_control::params::{self, Param, ParamError};
use hopper_control::pd_design::{self, PdGains};
use hopper_control::runner::{NoCounter, PeriodRunner, Timing};
use hopper_control::telemetry::FaultCapture;
use hopper_robot_link::{ControlLoop, Unlinked};

/// Records in a run's firmware capture: the run's trajectory is the
/// simulator's own, so the port's capture is a short one.
const RUN_CAPTURE_LEN: usize = 16;
use hopper_control::supervisor::Fault;
use hopper_control::telemetry::HopLedger;
use hopper_control::thermal::ThermalConfig;
use serde::Serialize;

/// What drives the simulated plant (the firmware behind the simulated
/// hardware, [`FirmwareController`], or an ideal law such as [`Passive`]):
/// computes the amplifier current once per control period. Not to be
/// confused with [`hopper_control::laws::Controller`], the firmware's
/// dispatch over its control laws.
pub trait PlantDriver {
    /// Short name, as accepted by `hopper-sim run --controller`.
    fn name(&self) -> &'static str;
    /// Current the motor carries over the coming period, A.
    fn current_command_a(&mut self, plant: &Plant) -> f64;
    /// The apex the controller regulates to, m, if it has one.
    fn target_apex_m(&self) -> Option<f64> {
        None
    }
    /// Faults latched so far, in order, with the time they latched.
    fn faults(&self) -> Vec<FaultRecord> {
        Vec::new()
    }
    /// Largest |current| commanded to the amplifier (DAC and enable) from
    /// the period the first fault latched on, A; `None` without a fault.
    fn max_abs_current_after_fault_a(&self) -> Option<f64> {
        None
    }
    /// The firmware's per-hop ledgers so far.
    fn hop_ledgers(&self) -> Vec<HopLedger> {
        Vec::new()
    }
    /// Events the firmware's phase estimator reported, if it has one.
    fn estimator_events(&self) -> Option<EstimatorEvents> {
        None
    }
    /// When the phase estimator reported each touchdown and liftoff: the
    /// start of the period whose command first followed it, s.
    fn contact_times(&self) -> Option<ContactTimes> {
        None
    }
    /// Why the firmware refused the run's arm request, if it did (then the
    /// run is disarmed throughout: 0 A, amplifier off).
    fn arm_refusal(&self) -> Option<&'static str> {
        None
    }
    /// The firmware's winding temperature estimate, if it has one.
    fn thermal(&self) -> Option<ThermalSummary> {
        None
    }
    /// The firmware's winding temperature estimate now, C, if it has one.
    fn winding_c(&self) -> Option<f64> {
        None
    }
    /// The winding's resistance at the firmware's temperature estimate
    /// now, ohm, if it has one (the run books the copper loss with it).
    fn winding_resistance_ohm(&self) -> Option<f64> {
        None
    }
    /// Why the run cannot go on (a hardware-in-the-loop line that lost a
    /// frame), if it cannot: the run stops with this error.
    fn failure(&self) -> Option<String> {
        None
    }
    /// What a hardware-in-the-loop run measured of its exchange, if this
    /// is one.
    fn hil(&mut self) -> Option<crate::hil::HilReport> {
        None
    }
    /// The firmware's parameters by name (NaN: not in its configuration),
    /// for a recording; empty without firmware on this host.
    fn parameters(&self) -> Vec<(&'static str, f32)> {
        Vec::new()
    }
}

/// Times of the phase estimator's touchdown and liftoff events, s.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ContactTimes {
    /// Touchdowns.
    pub touchdowns_s: Vec<f64>,
    /// Liftoffs (a withdrawn touchdown's liftoff included).
    pub liftoffs_s: Vec<f64>,
}

/// How many of each event the firmware's phase estimator reported.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct EstimatorEvents {
    /// Touchdowns.
    pub touchdowns: usize,
    /// Liftoffs.
    pub liftoffs: usize,
    /// Flight apexes.
    pub apexes: usize,
    /// Touchdowns predicted from the height encoder that load cell and
    /// potentiometer did not confirm (each withdrawn with a liftoff).
    pub withdrawn_touchdowns: u32,
}

/// The firmware's estimate of the motor's winding temperature over a run
/// (`hopper_control::thermal`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ThermalSummary {
    /// Hottest winding temperature estimated, C.
    pub peak_winding_c: f64,
    /// Winding temperature at the end, C.
    pub final_winding_c: f64,
    /// When the current limit first fell below the amplifier's (the
    /// derating band), s; null if never (always null with the protection
    /// off).
    pub first_derated_s: Option<f64>,
    /// Whether the protection derated and faulted (`thermal.protect`); off,
    /// the run is the thesis's motor without a thermal limit.
    pub protect: bool,
    /// Whose thermal data the estimate used: `stand-in` (the defaults, a
    /// catalogue motor's: the thesis gives none for its motor) or
    /// `configured` (a `thermal.*` parameter was set).
    pub motor_data: &'static str,
    /// Winding temperature where derating starts, C.
    pub derate_winding_c: f64,
    /// Winding temperature that latches the overtemperature fault, C.
    pub trip_winding_c: f64,
    /// When the winding first reached the derating temperature, s (with
    /// the protection off too: when it would have derated); null if never.
    pub reached_derate_s: Option<f64>,
    /// When the winding first reached the trip temperature, s (with the
    /// protection off too: when it would have tripped); null if never.
    pub reached_trip_s: Option<f64>,
    /// The current limit at the end of the run, A: the amplifier's, times
    /// the derating (0 once tripped is not shown here: see `faults`).
    pub final_current_limit_a: f64,
    /// The amplifier's current limit, A.
    pub amplifier_limit_a: f64,
    /// How long the motor hopped before its winding reached the derating
    /// temperature, s (`reached_derate_s`, with the protection on or
    /// off); null if it never did.
    pub endurance_s: Option<f64>,
    /// The winding temperature the run was heading for, C: where the
    /// motor would settle under the mean square current of the last 5 hops
    /// (`steady_hop`), if the apex was steady; null when it was not, or
    /// when there is no such temperature (above about 11.4 A RMS with the
    /// stand-in's data the heat outgrows what the motor sheds).
    pub steady_winding_c: Option<f64>,
    /// Whether the run was hopping steadily (a steady apex) with a
    /// current whose steady temperature is below the derating one: it
    /// could hop on indefinitely.
    pub indefinite: bool,
    /// The motor's thermal data (for the resistance and the steady
    /// temperature).
    #[serde(skip)]
    pub config: ThermalConfig,
}

impl ThermalSummary {
    /// The winding's resistance at the last estimate, ohm.
    pub fn winding_resistance_ohm(&self) -> f64 {
        f64::from(self.config.resistance_at_ohm(self.final_winding_c as f32))
    }

    /// Fills `steady_winding_c` and `indefinite` from the steady hops'
    /// RMS current (`None`: not hopping steadily).
    pub fn heading_for(&mut self, steady_rms_a: Option<f64>) {
        let i2 = steady_rms_a.map(|a| (a * a) as f32);
        self.steady_winding_c = i2
            .and_then(|i2| self.config.steady_winding_c(i2))
            .map(f64::from);
        self.indefinite = self
            .steady_winding_c
            .is_some_and(|t| t < self.derate_winding_c);
    }

    /// One period's estimate at `t_s`: the winding at `winding_c`, the
    /// current limit in force `limit_a`, `derated` below the amplifier's.
    pub fn observe(&mut self, t_s: f64, winding_c: f64, limit_a: f64, derated: bool) {
        self.peak_winding_c = self.peak_winding_c.max(winding_c);
        self.final_winding_c = winding_c;
        if derated && self.first_derated_s.is_none() {
            self.first_derated_s = Some(t_s);
        }
        if winding_c >= self.derate_winding_c && self.reached_derate_s.is_none() {
            self.reached_derate_s = Some(t_s);
            self.endurance_s = Some(t_s);
        }
        if winding_c >= self.trip_winding_c && self.reached_trip_s.is_none() {
            self.reached_trip_s = Some(t_s);
        }
        self.final_current_limit_a = limit_a;
    }

    /// A motor at the ambient temperature under `supervisor`'s protection.
    pub fn at_start(supervisor: &hopper_control::supervisor::Supervisor) -> Self {
        let t = *supervisor.thermal().config();
        let limit_a = f64::from(supervisor.current_limit_a());
        // `protect` off runs the same motor's data.
        let stand_in = ThermalConfig { protect: true, ..t }
            == ThermalConfig {
                protect: true,
                ..ThermalConfig::default()
            };
        ThermalSummary {
            peak_winding_c: f64::from(t.ambient_c),
            final_winding_c: f64::from(t.ambient_c),
            first_derated_s: None,
            protect: t.protect,
            motor_data: if stand_in { "stand-in" } else { "configured" },
            derate_winding_c: f64::from(t.derate_winding_c),
            trip_winding_c: f64::from(t.trip_winding_c),
            reached_derate_s: None,
            reached_trip_s: None,
            final_current_limit_a: limit_a,
            amplifier_limit_a: limit_a,
            endurance_s: None,
            steady_winding_c: None,
            indefinite: false,
            config: t,
        }
    }
}

/// The run summary's thermal line: which motor's data, the protection's
/// state, the peak winding temperature, when it derated (or would have)
/// and tripped (or would have), and the current limit at the end.
pub fn heat_line(t: &ThermalSummary) -> String {
    let data = match t.motor_data {
        "stand-in" => "stand-in motor data (maxon RE 40; the thesis gives none)",
        _ => "configured thermal.* data",
    };
    let derating = |v: Option<f64>, verb: &str| {
        v.map_or("no derating".to_string(), |s| format!("{verb} {s:.2} s"))
    };
    if t.protect {
        let end = match t.reached_trip_s {
            // The fault latched: the supervisor commands 0 A from then on.
            Some(s) => format!("tripped at {s:.2} s (overtemperature: 0 A since)"),
            None => format!(
                "no trip; limit at end {:.1} of {:.1} A",
                t.final_current_limit_a, t.amplifier_limit_a
            ),
        };
        format!(
            "{data}: winding peak {:.0} C; {}, {end}",
            t.peak_winding_c,
            derating(t.first_derated_s, "derating from"),
        )
    } else {
        let trip = t
            .reached_trip_s
            .map_or("no trip".to_string(), |s| format!("would trip at {s:.2} s"));
        format!(
            "{data}, protection OFF (thermal.protect=0: no thermal limit, as the thesis modelled): winding peak {:.0} C; {}, {trip}",
            t.peak_winding_c,
            derating(t.reached_derate_s, "would derate at"),
        )
    }
}

/// A latched fault.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FaultRecord {
    /// Kebab-case name ([`Fault::name`]).
    pub name: &'static str,
    /// Simulated time of the period that latched it, s.
    pub time_s: f64,
}

/// Controller names `hopper-sim run --controller` accepts: the firmware's
/// own list ([`hopper_control::laws::ControllerKind`]).
pub use hopper_control::params::CONTROLLER_NAMES;

/// What to build: a controller name and its settings.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerSpec {
    /// One of [`CONTROLLER_NAMES`].
    pub name: String,
    /// Apex target `H_D`, m.
    pub target_apex_m: f64,
    /// Torque for `open-torque` and `modified-torque`, N m (None: law default, 1 N m).
    pub torque_nm: Option<f64>,
    /// Sensor noise and amplifier lag.
    pub sensors: SensorConfig,
    /// The parameters the controller believes (None: the plant's).
    pub model: Option<Params>,
    /// A strategy with non-default gains, used instead of the name's default
    /// (the name still names the run).
    pub strategy_override: Option<Strategy>,
    /// Flight PD gains instead of the preset's (below) or the firmware's
    /// default (eq 4.13).
    pub flight_override: Option<flight_pd::Config>,
    /// The preset the plant came from (a parameter file's `base`), whose
    /// machine brings its own controller defaults: the `design` preset's
    /// flight law is Table 2.1's ([`Params::preset_flight_gains`]). `None`:
    /// the firmware's defaults.
    pub preset: Option<&'static str>,
    /// Faults to inject (`hopper-sim run --inject`).
    pub injections: Vec<Injection>,
    /// Firmware parameters set by name ([`hopper_control::params`]),
    /// applied last, in order; the configuration is validated again when
    /// the controller is built.
    pub params: Vec<(&'static Param, f32)>,
}

impl ControllerSpec {
    /// `name` with the defaults: 0.05 m target, law torque, default noise.
    pub fn new(name: &str) -> Self {
        ControllerSpec {
            name: name.to_string(),
            target_apex_m: 0.05,
            torque_nm: None,
            sensors: SensorConfig::DEFAULT,
            model: None,
            strategy_override: None,
            flight_override: None,
            preset: None,
            injections: Vec::new(),
            params: Vec::new(),
        }
    }

    /// The control-crate strategy for this name.
    pub fn strategy(&self) -> Result<Strategy, String> {
        if let Some(s) = self.strategy_override {
            return Ok(s);
        }
        let kind = self.kind()?;
        let torque = |default: f32| self.torque_nm.map_or(default, |t| t as f32);
        Ok(match kind.default_strategy() {
            Strategy::Thesis(StanceLaw::OpenTorque(c)) => {
                Strategy::Thesis(StanceLaw::OpenTorque(open_torque::Config {
                    torque_nm: torque(c.torque_nm),
                }))
            }
            Strategy::Thesis(StanceLaw::ModifiedTorque(c)) => {
                Strategy::Thesis(StanceLaw::ModifiedTorque(modified_torque::Config {
                    torque_nm: torque(c.torque_nm),
                    ..c
                }))
            }
            other => other,
        })
    }

    /// The flight PD gains this spec's preset brings on a machine the
    /// controller believes has `believed` parameters: for the Chapter 2
    /// laws ([`ControllerKind::is_chapter_2_law`]) the preset's gains on the
    /// nut converted to the motor ([`pd_design::gains_from_nut`]); the
    /// firmware's default (eq 4.13) for the other laws or when the preset
    /// brings none. (With Table 2.1's lightly damped flight law, damping
    /// ratio 0.026, energy-apex no longer regulates from 0.25 m or to 0.04 m.)
    pub fn default_flight_gains(&self, believed: &Params) -> Result<PdGains, String> {
        // The preset's flight law goes with the laws it was simulated with.
        let gains = match self.kind()?.is_chapter_2_law() {
            true => self.preset.and_then(Params::preset_flight_gains),
            false => None,
        };
        match gains {
            Some(g) => pd_design::gains_from_nut(
                g.kp_n_per_m as f32,
                g.kd_ns_per_m as f32,
                &model_params(believed),
            )
            .map_err(|e| format!("the preset's flight gains on this machine: {e:?}")),
            None => Ok(flight_pd::Config::default().gains),
        }
    }

    /// The controller this spec names.
    pub fn kind(&self) -> Result<ControllerKind, String> {
        ControllerKind::from_name(&self.name).ok_or_else(|| {
            format!(
                "unknown controller `{}`: expected one of {CONTROLLER_NAMES:?}",
                self.name
            )
        })
    }

    /// The firmware's period runner and the sensor models for a plant with
    /// `plant_params` whose body starts at rest `start_apex_m` above the
    /// ground, at control period `dt_s`, disarmed as at boot.
    /// `untethered`: whether arming needs no link (the default of the
    /// `arming.untethered` parameter; `--set` overrides it).
    pub fn runner(
        &self,
        plant_params: &Params,
        start_apex_m: f64,
        dt_s: f64,
        untethered: bool,
    ) -> Result<(PeriodRunner, SimHal), String> {
        if let Some(t) = self.torque_nm {
            if !(t.is_finite() && t.abs() <= 10.0) {
                return Err(format!(
                    "--torque {t} N m is out of range: allowed -10 ..= 10 N m"
                ));
            }
        }
        if !(self.target_apex_m.is_finite() && (0.0..=1.0).contains(&self.target_apex_m)) {
            return Err(format!(
                "--target-apex {} m is out of range: allowed 0 ..= 1 m",
                self.target_apex_m
            ));
        }
        let believed = self.model.as_ref().unwrap_or(plant_params);
        let mut cfg = firmware_config(
            plant_params,
            believed,
            self.strategy()?,
            self.target_apex_m,
            start_apex_m,
        );
        cfg.flight.gains = self.default_flight_gains(believed)?;
        cfg.arming.untethered = untethered;
        if let Some(f) = self.flight_override {
            cfg.flight = f;
        }
        for (p, v) in &self.params {
            params::set(&mut cfg, p.name, *v)
                .map_err(|e| describe_param_error(p, *v, e, &self.name))?;
        }
        let timing = Timing {
            period_s: dt_s as f32,
            ..Timing::default()
        };
        let runner = PeriodRunner::new(cfg, timing)
            .map_err(|e| format!("controller configuration: {e:?}"))?;
        Ok((runner, SimHal::new(&cfg.calibration, &self.sensors)))
    }

    /// Builds the controller for a plant with `plant_params` whose body starts
    /// at rest `start_apex_m` above the ground, at control period `dt_s`.
    pub fn build(
        &self,
        plant_params: &Params,
        start_apex_m: f64,
        dt_s: f64,
    ) -> Result<FirmwareController, String> {
        // The simulator has no link: a run is the operator's explicit arm
        // command (below), untethered (`--set arming.untethered=0` leaves
        // it disarmed: "link-down").
        let (mut runner, hal) = self.runner(plant_params, start_apex_m, dt_s, true)?;
        // Disarmed at boot like the board; armed at the first period if
        // the robot is at rest with the nut home (a release from rest is).
        runner.arming_mut().request_arm();
        let cfg = *runner.hopper().config();
        // The name of what actually runs (a strategy override names its own).
        let name = cfg.strategy.kind().name();
        let thermal = ThermalSummary::at_start(runner.hopper().supervisor());
        Ok(FirmwareController {
            name,
            firmware: ControlLoop::new(runner),
            capture: FaultCapture::new(),
            hal,
            dt_s,
            target_apex_m: (name != "passive").then_some(self.target_apex_m),
            faults: Vec::new(),
            hops: Vec::new(),
            last: None,
            events: EstimatorEvents::default(),
            contact_times: ContactTimes::default(),
            arm_refusal: None,
            thermal,
            injections: self
                .injections
                .iter()
                .map(|&i| (i, InjectState::Pending))
                .collect(),
            max_abs_current_after_fault_a: None,
        })
    }
}

impl ControllerSpec {
    /// The host's end of a hardware-in-the-loop run on `connection` (a
    /// robot image's link): this spec's firmware configuration is set on the
    /// robot by the parameters' names and the robot armed, with the plant
    /// held at its start (`plant_params`, `start_apex_m`). The injections
    /// that act on the sensor and amplifier models work as in a host run;
    /// those inside the firmware or on its DAC
    /// ([`FIRMWARE_SIDE_INJECTIONS`]) are refused.
    pub fn build_hil(
        &self,
        plant_params: &Params,
        start_apex_m: f64,
        dt_s: f64,
        connection: crate::hil::Connection,
    ) -> Result<crate::hil::HilDriver, String> {
        if let Some(i) = self
            .injections
            .iter()
            .find(|i| FIRMWARE_SIDE_INJECTIONS.contains(&i.kind))
        {
            return Err(format!(
                "--inject {}: it acts inside the firmware or on its DAC, which are the robot's in a HIL run (the sensor-side kinds work)",
                i.kind.name()
            ));
        }
        let (runner, hal) = self.runner(plant_params, start_apex_m, dt_s, true)?;
        let cfg = *runner.hopper().config();
        let name = cfg.strategy.kind().name();
        let plant = Plant::new(*plant_params, start_apex_m).map_err(|e| e.to_string())?;
        crate::hil::HilDriver::connect(
            connection,
            &cfg,
            hal,
            &plant,
            dt_s,
            (name != "passive").then_some(self.target_apex_m),
            ThermalSummary::at_start(runner.hopper().supervisor()),
        )
        .map(|d| {
            d.with_injections(
                self.injections
                    .iter()
                    .map(|&i| (i, InjectState::Pending))
                    .collect(),
            )
        })
    }
}

/// The controller firmware parameter `p` applies to, for an error message:
/// the registry's owner ([`params::owner`]).
pub fn owner_of(p: &Param) -> String {
    match params::owner(p).and_then(|o| CONTROLLER_NAMES.get(o.controller)) {
        Some(name) => format!("the {name} controller"),
        None => "another controller".to_string(),
    }
}

/// ` UNIT` for a message, or nothing for dimensionless numbers, flags and
/// choices.
pub fn unit_suffix(p: &Param) -> String {
    match p.unit {
        "1" | "-" => String::new(),
        u => format!(" {u}"),
    }
}

/// One clear sentence for a parameter `controller` refused.
pub fn describe_param_error(p: &Param, value: f32, e: ParamError, controller: &str) -> String {
    let unit = unit_suffix(p);
    match e {
        ParamError::Unknown => format!("unknown firmware parameter `{}`", p.name),
        ParamError::OutOfRange(_) => format!(
            "parameter `{}` = {value}{unit} is out of range: allowed {}{unit} ..= {}{unit}",
            p.name, p.min, p.max
        ),
        ParamError::NotSelected(_) => format!(
            "parameter `{}` applies to {}, not to the `{controller}` controller",
            p.name,
            owner_of(p)
        ),
    }
}

/// The control crate on the simulated hardware.
pub struct FirmwareController {
    name: &'static str,
    /// The firmware's control loop (the same one the board and QEMU run),
    /// with no link.
    firmware: ControlLoop,
    /// The port's capture (a run's trajectory is the simulator's record:
    /// the firmware's capture is kept short).
    capture: FaultCapture<RUN_CAPTURE_LEN>,
    /// The sensor, DAC and amplifier models (public for fault injection).
    pub hal: SimHal,
    dt_s: f64,
    target_apex_m: Option<f64>,
    faults: Vec<FaultRecord>,
    hops: Vec<HopLedger>,
    last: Option<StepOutput>,
    events: EstimatorEvents,
    contact_times: ContactTimes,
    arm_refusal: Option<&'static str>,
    thermal: ThermalSummary,
    injections: Vec<(Injection, InjectState)>,
    max_abs_current_after_fault_a: Option<f64>,
}

/// Where an injection is in its life.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum InjectState {
    /// Its time has not come.
    Pending,
    /// Applied, and ends later (a noise burst).
    Active,
    /// Applied for good (or over).
    Done,
}

impl FirmwareController {
    /// The control crate's state.
    pub fn hopper(&self) -> &Hopper {
        self.firmware.runner.hopper()
    }

    /// The control crate's state, mutably (reset, target changes).
    pub fn hopper_mut(&mut self) -> &mut Hopper {
        self.firmware.runner.hopper_mut()
    }

    /// The last period's output.
    pub fn last_output(&self) -> Option<&StepOutput> {
        self.last.as_ref()
    }

    /// Applies the injections due in the period starting at `plant.time_s()`
    /// ([`apply_due_injections`]); the firmware-side ones to the runner.
    fn apply_injections(&mut self, plant: &Plant) {
        let firmware = &mut self.firmware;
        apply_due_injections(
            &mut self.injections,
            &mut self.hal,
            plant,
            self.dt_s,
            &mut |kind| match kind {
                InjectKind::Nan => {
                    firmware
                        .runner
                        .hopper_mut()
                        .set_measurement_override(MeasurementOverride {
                            spring_force_n: Some(f32::NAN),
                            ..MeasurementOverride::default()
                        })
                }
                // The RTIC app finds the overrun at the start of the next
                // period and reports it before stepping: do the same.
                InjectKind::Overrun => firmware.runner.report_overrun(),
                _ => {}
            },
        );
    }
}

/// The injections that act inside the firmware (`nan`, `overrun`) or on
/// its DAC (`dac-error`), not on the sensor models: a hardware-in-the-loop
/// run cannot take them (the firmware and the DAC are the robot's).
pub const FIRMWARE_SIDE_INJECTIONS: [InjectKind; 3] =
    [InjectKind::Nan, InjectKind::Overrun, InjectKind::DacError];

/// Applies the injections due in the period starting at `plant.time_s()`
/// to the sensor and amplifier models in `hal`, and hands the ones that act
/// inside the firmware to `firmware`. An injection at `t` is due in the
/// first period that starts no earlier than half a period before `t` (the
/// plant's clock is a sum of periods, so `t` itself may be missed by a
/// rounding error).
pub(crate) fn apply_due_injections(
    injections: &mut [(Injection, InjectState)],
    hal: &mut SimHal,
    plant: &Plant,
    dt_s: f64,
    firmware: &mut dyn FnMut(InjectKind),
) {
    let now_s = plant.time_s() + 0.5 * dt_s;
    for (inj, state) in injections {
        match *state {
            InjectState::Pending if now_s >= inj.time_s => {}
            InjectState::Active if now_s >= inj.time_s + NOISE_BURST_DURATION_S => {
                hal.faults.adc_burst_sigma_codes = 0;
                *state = InjectState::Done;
                continue;
            }
            _ => continue,
        }
        *state = InjectState::Done;
        let full_scale = hal.adc_full_scale();
        let f = &mut hal.faults;
        match inj.kind {
            InjectKind::EncoderJump => {
                f.motor_counts_offset = f.motor_counts_offset.wrapping_add(ENCODER_JUMP_COUNTS);
            }
            InjectKind::EncoderFrozen => hal.freeze_motor_encoder(plant),
            InjectKind::LoadcellStuck => hal.freeze_loadcell(plant),
            InjectKind::LoadcellSaturated => f.loadcell_code = Some(full_scale),
            InjectKind::PotOpen => f.pot_code = Some(0),
            InjectKind::NoiseBurst => {
                f.adc_burst_sigma_codes = NOISE_BURST_SIGMA_CODES;
                *state = InjectState::Active;
            }
            InjectKind::Estop => f.estop = true,
            InjectKind::AmpFault => f.amp_fault = true,
            InjectKind::DacError => f.dac_error = true,
            InjectKind::Nan | InjectKind::Overrun => firmware(inj.kind),
        }
    }
}

impl PlantDriver for FirmwareController {
    fn name(&self) -> &'static str {
        self.name
    }

    fn current_command_a(&mut self, plant: &Plant) -> f64 {
        // Before the injections: an overrun is reported into the supervisor
        // there, and must count as latched in this period.
        let before = self.firmware.runner.hopper().supervisor().faults();
        if !self.injections.is_empty() {
            self.apply_injections(plant);
        }
        let out = {
            let mut io = self.hal.io(plant);
            let period = self.firmware.period(
                &mut io,
                &mut NoCounter,
                &mut &mut self.capture,
                &mut Unlinked::default(),
            );
            if let Some(ArmEvent::Refused(r)) = period.arm_event {
                self.arm_refusal.get_or_insert(r.name());
            }
            period.out
        };
        // The host keeps every deadline: the plant takes no time.
        self.firmware.runner.end_period(false);
        let supervisor = self.firmware.runner.hopper().supervisor();
        let motor = supervisor.thermal();
        self.thermal.observe(
            plant.time_s(),
            f64::from(motor.winding_c()),
            f64::from(supervisor.current_limit_a() * motor.limit_scale()),
            motor.limit_scale() < 1.0,
        );
        let new = out.faults.0 & !before.0;
        if new != 0 {
            for f in Fault::ALL {
                if new & f.bit() != 0 {
                    self.faults.push(FaultRecord {
                        name: f.name(),
                        time_s: plant.time_s(),
                    });
                }
            }
        }
        if let Some(h) = out.hop {
            self.hops.push(h);
        }
        match out.event {
            Some(PhaseEvent::Touchdown) => {
                self.events.touchdowns += 1;
                self.contact_times.touchdowns_s.push(plant.time_s());
            }
            Some(PhaseEvent::Liftoff) => {
                self.events.liftoffs += 1;
                self.contact_times.liftoffs_s.push(plant.time_s());
            }
            Some(PhaseEvent::Apex { .. }) => self.events.apexes += 1,
            _ => {}
        }
        self.last = Some(out);
        if !self.faults.is_empty() {
            let i = self.hal.commanded_current_a().abs();
            let max = self.max_abs_current_after_fault_a.get_or_insert(0.0);
            *max = max.max(i);
        }
        self.hal.mean_current_a(self.dt_s)
    }

    fn target_apex_m(&self) -> Option<f64> {
        self.target_apex_m
    }

    fn faults(&self) -> Vec<FaultRecord> {
        self.faults.clone()
    }

    fn max_abs_current_after_fault_a(&self) -> Option<f64> {
        self.max_abs_current_after_fault_a
    }

    fn hop_ledgers(&self) -> Vec<HopLedger> {
        self.hops.clone()
    }

    fn parameters(&self) -> Vec<(&'static str, f32)> {
        let mut cfg = *self.firmware.runner.hopper().config();
        hopper_control::params::TABLE
            .iter()
            .map(|p| {
                (
                    p.name,
                    hopper_control::params::read(&mut cfg, p).unwrap_or(f32::NAN),
                )
            })
            .collect()
    }

    fn estimator_events(&self) -> Option<EstimatorEvents> {
        Some(EstimatorEvents {
            withdrawn_touchdowns: self
                .firmware
                .runner
                .hopper()
                .estimator()
                .withdrawn_touchdowns(),
            ..self.events
        })
    }

    fn contact_times(&self) -> Option<ContactTimes> {
        Some(self.contact_times.clone())
    }

    fn thermal(&self) -> Option<ThermalSummary> {
        Some(self.thermal)
    }

    fn winding_c(&self) -> Option<f64> {
        Some(self.thermal.final_winding_c)
    }

    fn winding_resistance_ohm(&self) -> Option<f64> {
        Some(self.thermal.winding_resistance_ohm())
    }

    fn arm_refusal(&self) -> Option<&'static str> {
        self.arm_refusal
    }
}

/// Passive hopping on the ideal plant, without sensors or firmware: 0 A
/// every period (thesis section 4.4.1). The spring preload holds the nut on
/// its upper stop, so the leg acts as a fixed spring. For plant-level tests;
/// `--controller passive` runs the firmware's passive strategy instead.
#[derive(Clone, Copy, Debug, Default)]
pub struct Passive;

impl PlantDriver for Passive {
    fn name(&self) -> &'static str {
        "passive"
    }
    fn current_command_a(&mut self, _plant: &Plant) -> f64 {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(protect: bool, derated: Option<f64>, trip: Option<f64>) -> ThermalSummary {
        ThermalSummary {
            peak_winding_c: 150.4,
            final_winding_c: 149.0,
            first_derated_s: derated.filter(|_| protect),
            protect,
            motor_data: "stand-in",
            derate_winding_c: 135.0,
            trip_winding_c: 150.0,
            reached_derate_s: derated,
            reached_trip_s: trip,
            final_current_limit_a: 17.1,
            amplifier_limit_a: 33.67,
            ..ThermalSummary::default()
        }
    }

    /// The heat line names the motor's data and says when the limit
    /// derated and the fault tripped, or with the protection off when they
    /// would have; a trip shows no current limit (the supervisor drives 0 A).
    #[test]
    fn the_heat_line_says_what_the_protection_did_or_would_have_done() {
        let on = heat_line(&summary(true, Some(11.71), None));
        assert!(on.starts_with("stand-in motor data (maxon RE 40"), "{on}");
        assert!(
            on.ends_with(
                "winding peak 150 C; derating from 11.71 s, no trip; limit at end 17.1 of 33.7 A"
            ),
            "{on}"
        );
        let tripped = heat_line(&summary(true, Some(11.26), Some(14.8)));
        assert!(
            tripped.ends_with(
                "derating from 11.26 s, tripped at 14.80 s (overtemperature: 0 A since)"
            ),
            "{tripped}"
        );
        let off = heat_line(&summary(false, Some(11.71), Some(13.44)));
        assert!(off.contains("protection OFF"), "{off}");
        assert!(
            off.ends_with("would derate at 11.71 s, would trip at 13.44 s"),
            "{off}"
        );
        let cool = heat_line(&summary(false, None, None));
        assert!(cool.ends_with("no derating, no trip"), "{cool}");
        let mine = heat_line(&ThermalSummary {
            motor_data: "configured",
            ..summary(true, None, None)
        });
        assert!(mine.starts_with("configured thermal.* data"), "{mine}");
    }
}
