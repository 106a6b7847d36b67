//! The whole control period in one place: raw sample in, DAC code and
//! amplifier enable out.
//!
//! [`Hopper::step`] is what the firmware's control task and the simulator
//! both call once per period:
//!
//! 1. convert the raw sample to SI ([`crate::calibration::Converter`]);
//! 2. run the phase estimator and the filtered derivatives of eq 4.1
//!    ([`crate::estimator::PhaseEstimator`]);
//! 3. estimate the energy (eq 2.44 with the eq 2.45 spring term);
//! 4. run the selected stance law, or in flight the PD back-drive (eq 4.4)
//!    (or the modified-torque window, section 4.4.3);
//! 5. let the [`Supervisor`] check the sample and the request;
//! 6. turn the approved current into a DAC code, and update the per-hop
//!    ledger and the telemetry record.
//!
//! [`crate::runner::PeriodRunner`] wraps it around the I/O: read, step,
//! write the DAC, set the enable, the watchdog decision and overruns.

#[cfg(feature = "fault-injection")]
use crate::calibration::Measurements;
use crate::calibration::{CalError, Converter, DacMap};
use crate::energy::{EnergyInput, EnergyModel};
use crate::estimator::{EstimatorError, Phase, PhaseEstimator, PhaseEvent, PhaseInput};
use crate::hal::RawSample;
use crate::laws::{ControlInput, ControlLaw, Controller, EventInput, InvalidField};
use crate::model::{ModelError, ModelParams};
use crate::supervisor::{Command, Fault, Faults, Supervisor, SupervisorInput};
use crate::telemetry::{HopLedger, HopLedgerBuilder, StepRecord};

pub use crate::laws::energy_apex::{ApexLoop, EnergyMeasure};
pub use crate::laws::Strategy;

pub use crate::config::{HopperConfig, STOP_IMPACT_SPEED_MPS};

/// Why a [`Hopper`] could not be built.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// The model is invalid.
    Model(ModelError),
    /// The calibration is invalid.
    Calibration(CalError),
    /// The estimator configuration is invalid.
    Estimator(EstimatorError),
    /// The target apex is not in `0..=1` m.
    TargetApex,
    /// A parameter is out of its entry's range, or a controller's or the
    /// flight PD's field is unusable (named).
    Law(InvalidField),
}

impl From<InvalidField> for ConfigError {
    fn from(f: InvalidField) -> Self {
        ConfigError::Law(f)
    }
}

/// What one control period produced.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepOutput {
    /// The DAC code to write (the zero-current code when faulted).
    pub dac_code: u16,
    /// The approved command.
    pub command: Command,
    /// What the laws asked for before the supervisor, A.
    pub requested_a: f32,
    /// Phase estimate after this sample.
    pub phase: Phase,
    /// The event this sample completed.
    pub event: Option<PhaseEvent>,
    /// The completed hop's ledger, at the apex that ends it.
    pub hop: Option<HopLedger>,
    /// Energy estimate, J (NaN when the sample was rejected).
    pub energy_j: f32,
    /// Latched faults after this period.
    pub faults: Faults,
    /// Compact record for the telemetry and the capture.
    pub record: StepRecord,
}

/// The control period's state: conversion, estimator, the selected
/// controller, supervisor and ledger. Not `Copy`: a copy would duplicate
/// the fault latch.
#[derive(Debug, Clone)]
pub struct Hopper {
    cfg: HopperConfig,
    converter: Converter,
    dac: DacMap,
    energy: EnergyModel,
    estimator: PhaseEstimator,
    controller: Controller,
    supervisor: Supervisor,
    /// The e-stop input, debounced: what the supervisor and arming see.
    estop: crate::debounce::Debounce,
    ledger: HopLedgerBuilder,
    /// `E_D` of the target apex, J (every energy-based law's reference).
    desired_energy_j: f32,
    /// Screw ratio `r`, m/rad: the nut's speed from the motor's rate.
    screw_m_per_rad: f32,
    steps: u32,
    /// The supervisor's input of the last step (a fault reset between
    /// periods is checked against it); `None` before the first.
    last_input: Option<SupervisorInput>,
    /// Corruption applied to each converted sample (simulated faults only).
    #[cfg(feature = "fault-injection")]
    injected: MeasurementOverride,
}

/// Values that replace the converter's output before the estimator sees it:
/// simulated sensor faults the converter cannot produce with a valid
/// calibration (NaN, infinity). `None` leaves a field as converted.
#[cfg(feature = "fault-injection")]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MeasurementOverride {
    /// Replaces [`Measurements::spring_force_n`], N.
    pub spring_force_n: Option<f32>,
    /// Replaces [`Measurements::leg_compression_m`], m.
    pub leg_compression_m: Option<f32>,
    /// Replaces [`Measurements::nut_position_m`], m.
    pub nut_position_m: Option<f32>,
}

#[cfg(feature = "fault-injection")]
impl MeasurementOverride {
    /// By value, not through `&mut`: the sample then stays in registers. With
    /// a `&mut` the converted sample was stored field by field (some fields
    /// in pieces, as the converter's `Result` lays it out) and read back with
    /// wider loads, a store-to-load forwarding stall of about a sixth of the
    /// host's control step.
    #[inline(always)]
    fn apply(&self, m: Measurements) -> Measurements {
        Measurements {
            spring_force_n: self.spring_force_n.unwrap_or(m.spring_force_n),
            leg_compression_m: self.leg_compression_m.unwrap_or(m.leg_compression_m),
            nut_position_m: self.nut_position_m.unwrap_or(m.nut_position_m),
            ..m
        }
    }
}

fn cal_fault(e: CalError) -> Fault {
    match e {
        CalError::NonFinite(_) => Fault::SensorNonFinite,
        _ => Fault::SensorRange,
    }
}

impl Hopper {
    /// Validates `cfg` and builds the controller (in flight, no fault).
    pub fn new(cfg: HopperConfig) -> Result<Self, ConfigError> {
        cfg.model.validate().map_err(ConfigError::Model)?;
        let converter = Converter::new(cfg.calibration).map_err(ConfigError::Calibration)?;
        // The estimator's contact evidence (load-cell force in excess of
        // `k (delta0 + p)`) is a cross-check of two sensors through the spring,
        // like the supervisor's: it uses the spring as calibrated (the
        // supervisor's rate and preload), not the control model, which may be
        // wrong by design (model-error studies) without hiding a liftoff.
        let sensed = ModelParams {
            spring_stiffness_n_per_m: cfg.supervisor.spring_rate_n_per_m,
            preload_m: cfg.supervisor.spring_preload_m,
            ..cfg.model
        };
        let estimator =
            PhaseEstimator::new(cfg.estimator, &sensed).map_err(ConfigError::Estimator)?;
        let desired_energy_j = Self::desired_for(&cfg.model, cfg.target_apex_m)?;
        let controller = Controller::new(&cfg.strategy, &cfg.model, &cfg.flight)?;
        // Every parameter against its entry's range, the parts without a
        // range check of their own (estimator, calibration, supervisor,
        // bring-up) included; after the parts' own checks, which name
        // what they find in their own terms.
        crate::params::validate(&cfg)?;
        Ok(Self {
            controller,
            cfg,
            converter,
            dac: DacMap::new(&cfg.calibration, cfg.model.usable_current_limit_a()),
            energy: EnergyModel::new(&cfg.model).map_err(|_| {
                ConfigError::Model(ModelError::OutOfRange(
                    crate::model::ModelField::SpringStiffness,
                ))
            })?,
            estimator,
            supervisor: Supervisor::new(cfg.supervisor, cfg.model.usable_current_limit_a())?,
            estop: crate::debounce::Debounce::new(cfg.estop)?,
            ledger: HopLedgerBuilder::new(),
            desired_energy_j,
            screw_m_per_rad: cfg.model.screw_m_per_rad(),
            steps: 0,
            last_input: None,
            #[cfg(feature = "fault-injection")]
            injected: MeasurementOverride::default(),
        })
    }

    /// The supervisor's input of the last step that converted a sample
    /// (what a fault reset between periods is checked against).
    pub fn last_input(&self) -> Option<&SupervisorInput> {
        self.last_input.as_ref()
    }

    /// Takes over from `old` after a reconfiguration: its latched faults
    /// (a new configuration never clears a latch), the encoders' origin
    /// ([`Converter::continue_from`]), its step count (the records' step
    /// numbers go on) and its last supervisor input.
    pub fn continue_from(&mut self, old: &Hopper) {
        self.converter.continue_from(&old.converter);
        self.supervisor.continue_thermal(&old.supervisor);
        // The debounce state, with the new configuration's times.
        self.estop.continue_from(&old.estop);
        let latched = old.supervisor.faults();
        for &f in Fault::ALL {
            if latched.contains(f) {
                self.supervisor.report(f);
            }
        }
        self.steps = old.steps;
        self.last_input = old.last_input;
    }

    /// Simulated faults: from the next period on, `o` replaces fields of
    /// each converted sample before the estimator and the supervisor see it
    /// (`MeasurementOverride::default()` stops it).
    #[cfg(feature = "fault-injection")]
    pub fn set_measurement_override(&mut self, o: MeasurementOverride) {
        self.injected = o;
    }

    fn desired_for(model: &ModelParams, apex_m: f32) -> Result<f32, ConfigError> {
        if crate::params::TARGET_APEX_M.check(apex_m).is_err() {
            return Err(ConfigError::TargetApex);
        }
        model
            .desired_energy_j(apex_m)
            .map_err(|_| ConfigError::TargetApex)
    }

    /// The configuration in use.
    pub fn config(&self) -> &HopperConfig {
        &self.cfg
    }

    /// Changes the apex target `H_D` (m, `0..=1`); the apex loop's offset is kept.
    pub fn set_target_apex(&mut self, apex_m: f32) -> Result<(), ConfigError> {
        self.desired_energy_j = Self::desired_for(&self.cfg.model, apex_m)?;
        self.cfg.target_apex_m = apex_m;
        Ok(())
    }

    /// `E_D` for the target apex, J (eq 2.43 in this crate's coordinates).
    pub fn desired_energy_j(&self) -> f32 {
        self.desired_energy_j
    }

    /// The apex loop's current correction of `E_D`, J (0 for other strategies).
    pub fn apex_offset_j(&self) -> f32 {
        self.controller.apex_offset_j()
    }

    /// The selected controller and its state.
    pub fn controller(&self) -> &Controller {
        &self.controller
    }

    /// The supervisor (faults, configuration).
    pub fn supervisor(&self) -> &Supervisor {
        &self.supervisor
    }

    /// The supervisor, mutably: for the period runner (overruns, resets
    /// through `PeriodRunner::reset_faults`, which the feed policy must hear
    /// of) and this crate's tests, not for applications.
    pub(crate) fn supervisor_mut(&mut self) -> &mut Supervisor {
        &mut self.supervisor
    }

    /// The motor took `applied_a` (what the amplifier was told, 0 when
    /// disabled) for `dt_s`: the thermal estimate heats with it (an
    /// overtemperature latches), and the open hop's ledger books its copper
    /// loss at the winding's estimated resistance, so both count the same
    /// heat.
    pub(crate) fn heat(&mut self, applied_a: f32, dt_s: f32) {
        let r_ohm = self.supervisor.thermal().winding_resistance_ohm();
        self.ledger.heat(applied_a * applied_a * r_ohm * dt_s);
        self.supervisor.heat(applied_a, dt_s);
    }

    /// The e-stop, debounced ([`crate::debounce`]).
    pub fn estop_pressed(&self) -> bool {
        self.estop.pressed()
    }

    /// The phase estimate.
    pub fn phase(&self) -> Phase {
        self.estimator.phase()
    }

    /// Nut velocity from the filtered motor rate (eq 4.1), m/s.
    pub fn nut_velocity_mps(&self) -> f32 {
        self.estimator.velocities().motor_rad_s * self.cfg.model.screw_m_per_rad()
    }

    /// The phase estimator (its counters: withdrawn touchdowns, rejected samples).
    pub fn estimator(&self) -> &PhaseEstimator {
        &self.estimator
    }

    /// Moves the encoders' origin ([`Converter::shift_origin`]): the
    /// period runner's homing and height zero, followed by a rebuild (the
    /// velocity filters must not see the step).
    pub(crate) fn shift_origin(&mut self, nut_m: f32, height_m: f32) {
        self.converter.shift_origin(nut_m, height_m);
    }

    /// One control period of `dt_s` seconds. `raw` is `None` when the sensors
    /// could not be read (latches [`Fault::SensorRange`]).
    #[inline]
    pub fn step(&mut self, raw: Option<&RawSample>, dt_s: f32) -> StepOutput {
        self.step_with(raw, dt_s, None)
    }

    /// [`Self::step`], with a motor-driving bring-up routine
    /// ([`crate::bringup`]) asking for the current instead of the
    /// controller while it runs; the supervisor checks it the same way.
    /// Inlined into the period runner, its one caller on the target (out of
    /// line the 100-byte output was returned through memory: 60
    /// instructions a period more in QEMU).
    #[inline(always)]
    pub fn step_with(
        &mut self,
        raw: Option<&RawSample>,
        dt_s: f32,
        bringup: Option<&mut crate::bringup::Calibrator>,
    ) -> StepOutput {
        self.steps = self.steps.wrapping_add(1);
        let estop_pressed = match raw {
            Some(r) => self.estop.update(r.estop_pressed, dt_s),
            None => self.estop.pressed(),
        };
        let m = match raw.map(|r| self.converter.convert(r)) {
            Some(Ok(m)) => m,
            Some(Err(e)) => return self.safe_output(cal_fault(e)),
            None => return self.safe_output(Fault::SensorRange),
        };
        // Simulator builds only: the converter's output corrupted as a
        // broken sensor path would (a NaN reaches the estimator, and the
        // supervisor must catch it in this period).
        #[cfg(feature = "fault-injection")]
        let m = self.injected.apply(m);
        let event = self.estimator.update(
            &PhaseInput {
                body_height_m: m.body_height_m,
                motor_angle_rad: m.motor_angle_rad,
                spring_force_n: m.spring_force_n,
                leg_compression_m: m.leg_compression_m,
            },
            dt_s,
        );
        let v = self.estimator.velocities();
        let phase = self.estimator.phase();
        let nut_velocity_mps = v.motor_rad_s * self.screw_m_per_rad;
        let energy_j = self
            .energy
            .total_j(&EnergyInput {
                body_height_m: m.body_height_m,
                body_velocity_mps: v.body_mps,
                motor_rate_rad_s: v.motor_rad_s,
                nut_position_m: m.nut_position_m,
                spring_force_n: m.spring_force_n,
                phase,
            })
            .unwrap_or(f32::NAN);
        // Events come a few times per hop (every ~700th period): keep their
        // bookkeeping out of line.
        let hop = match event {
            Some(e) => self.on_event(e, energy_j),
            None => None,
        };
        let requested_a = match bringup {
            Some(cal) if cal.driving() => cal.drive(&crate::bringup::DriveInput {
                motor_angle_rad: m.motor_angle_rad,
                motor_rate_rad_s: v.motor_rad_s,
                spring_force_n: m.spring_force_n,
                leg_compression_m: m.leg_compression_m,
                body_height_m: m.body_height_m,
                dt_s,
            }),
            _ => self.controller.current_a(&ControlInput {
                phase,
                body_height_m: m.body_height_m,
                toe_height_m: m.body_height_m - self.cfg.model.leg_length_m,
                body_velocity_mps: v.body_mps,
                motor_angle_rad: m.motor_angle_rad,
                motor_rate_rad_s: v.motor_rad_s,
                nut_position_m: m.nut_position_m,
                nut_velocity_mps,
                spring_force_n: m.spring_force_n,
                leg_compression_m: m.leg_compression_m,
                energy_j,
                desired_energy_j: self.desired_energy_j,
                target_apex_m: self.cfg.target_apex_m,
                flight_peak_toe_m: self.estimator.flight_peak_toe_m(),
                last_apex_m: self.estimator.last_apex_m(),
                dt_s,
            }),
        };
        let sup_in = SupervisorInput {
            // Debounced ([`crate::debounce`]), not the raw input.
            estop_pressed,
            ..SupervisorInput::from_measurements(&m, nut_velocity_mps, v.motor_rad_s, v.body_mps)
        };
        let mut command = self.supervisor.check(&sup_in, requested_a, dt_s);
        self.last_input = Some(sup_in);
        if !energy_j.is_finite() {
            // A non-finite input latched this period already; a finite one
            // that overflowed the energy is a bad sensor value too.
            self.supervisor.report(Fault::SensorNonFinite);
            command = Command::SAFE;
        }
        let dac_code = self.dac.code(command.current_a);
        let cal = self.converter.calibration();
        self.ledger.step(
            dt_s,
            command.current_a,
            cal.torque_nm(command.current_a),
            v.motor_rad_s,
            m.nut_position_m,
        );
        let faults = self.supervisor.faults();
        StepOutput {
            dac_code,
            command,
            requested_a,
            phase,
            event,
            hop,
            energy_j,
            faults,
            record: StepRecord {
                step: self.steps,
                phase: phase as u8,
                armed: false,
                faults: faults.0,
                dac_code,
                body_height_m: m.body_height_m,
                nut_position_m: m.nut_position_m,
                spring_force_n: m.spring_force_n,
                energy_j,
                command_a: command.current_a,
            },
        }
    }

    /// The zero-current DAC code.
    pub fn zero_code(&self) -> u16 {
        self.dac.code(0.0)
    }

    fn safe_output(&mut self, fault: Fault) -> StepOutput {
        // No usable measurement this period: a fault reset must wait for one.
        self.last_input = None;
        self.supervisor.report(fault);
        let dac_code = self.dac.code(0.0);
        let faults = self.supervisor.faults();
        let phase = self.estimator.phase();
        StepOutput {
            dac_code,
            command: Command::SAFE,
            requested_a: 0.0,
            phase,
            event: None,
            hop: None,
            energy_j: f32::NAN,
            faults,
            record: StepRecord {
                step: self.steps,
                phase: phase as u8,
                armed: false,
                faults: faults.0,
                dac_code,
                body_height_m: f32::NAN,
                nut_position_m: f32::NAN,
                spring_force_n: f32::NAN,
                energy_j: f32::NAN,
                command_a: 0.0,
            },
        }
    }

    /// Ledger and controller bookkeeping for an estimator event.
    #[inline(never)]
    #[cold]
    fn on_event(&mut self, event: PhaseEvent, energy_j: f32) -> Option<HopLedger> {
        let hop = match event {
            PhaseEvent::Touchdown => {
                self.ledger.touchdown(energy_j);
                None
            }
            PhaseEvent::Liftoff => {
                self.ledger.liftoff(energy_j);
                None
            }
            PhaseEvent::Bottom => None,
            PhaseEvent::Apex { toe_height_m } => self.ledger.apex(toe_height_m),
        };
        // `E_D` of the measured apex, for the per-hop loops, only at an apex
        // that completes a hop.
        let hop_apex_energy_j = match (event, &hop) {
            (PhaseEvent::Apex { toe_height_m }, Some(_)) => self
                .cfg
                .model
                .desired_energy_j(toe_height_m.clamp(0.0, 1.0))
                .ok(),
            _ => None,
        };
        self.controller.on_event(&EventInput {
            event,
            hop_apex_energy_j,
            desired_energy_j: self.desired_energy_j,
            faulted: self.supervisor.is_faulted(),
        });
        hop
    }

    /// The shaped law's torque level, fraction of the current limit (0 for
    /// other strategies).
    pub fn shaped_level(&self) -> f32 {
        self.controller.shaped_level()
    }
}

#[cfg(test)]
mod tests {
    use super::Strategy;
    use super::*;
    use crate::laws::{modified_torque, StanceLaw};
    use proptest::prelude::{
        any, prop_assert, prop_assert_eq, prop_oneof, proptest, Just, ProptestConfig,
    };
    use proptest::strategy::Strategy as _;

    fn hopper(strategy: Strategy) -> Hopper {
        let cfg = HopperConfig {
            strategy,
            ..HopperConfig::default()
        };
        Hopper::new(cfg).unwrap_or_else(|e| panic!("{e:?}"))
    }

    #[test]
    fn passive_commands_zero_with_the_amplifier_enabled() {
        let mut h = hopper(Strategy::Passive);
        let raw = crate::proptest_support::rest_sample(&h.config().calibration);
        for _ in 0..10 {
            let out = h.step(Some(&raw), 1e-4);
            assert_eq!(out.command.current_a, 0.0);
            assert!(out.command.amp_enable);
            assert_eq!(out.dac_code, 2048);
            assert!(out.faults.is_empty());
        }
    }

    #[test]
    fn flight_pd_pulls_a_displaced_nut_home() {
        let mut h = hopper(Strategy::default());
        let mut raw = crate::proptest_support::rest_sample(&h.config().calibration);
        h.step(Some(&raw), 1e-4);
        // Ease the nut 400 counts down (1 mm) at 0.05 m/s (63 rad/s: slow
        // enough to halt within a period without looking like a frozen
        // encoder), then hold: the PD asks for current upwards (< 0).
        let mut out = h.step(Some(&raw), 1e-4);
        for k in 1..=250 {
            raw.motor_counts = (2 * k).min(400);
            out = h.step(Some(&raw), 1e-4);
        }
        assert!(out.command.current_a < -10.0, "{out:?}");
        assert!(out.dac_code < 2048);
    }

    #[test]
    fn a_fault_is_safe_in_the_same_period_and_stays_latched() {
        let mut h = hopper(Strategy::default());
        let mut raw = crate::proptest_support::rest_sample(&h.config().calibration);
        h.step(Some(&raw), 1e-4);
        raw.estop_pressed = true;
        // One period pressed is a glitch (`estop.press_s` = 0.2 ms); the
        // period that completes the press is already safe.
        let out = h.step(Some(&raw), 1e-4);
        assert!(out.faults.is_empty(), "{out:?}");
        let out = h.step(Some(&raw), 1e-4);
        assert_eq!(out.command, Command::SAFE);
        assert_eq!(out.dac_code, 2048);
        assert!(out.faults.contains(Fault::Estop));
        raw.estop_pressed = false;
        let out = h.step(Some(&raw), 1e-4);
        assert_eq!(out.command, Command::SAFE, "latched after release");
    }

    #[test]
    fn unreadable_or_non_finite_sensors_trip() {
        let mut h = hopper(Strategy::default());
        let out = h.step(None, 1e-4);
        assert!(out.faults.contains(Fault::SensorRange));
        assert_eq!(out.command, Command::SAFE);

        // A calibration that would overflow f32 on a real code (a converted
        // value of inf) is refused before it runs, by its entry's name.
        let mut cfg = HopperConfig::default();
        cfg.calibration.loadcell_gain_n_per_code = f32::MAX;
        assert_eq!(
            Hopper::new(cfg).err(),
            Some(ConfigError::Law(InvalidField(
                "calibration.loadcell_gain_n_per_code"
            )))
        );
    }

    #[test]
    fn overrun_reported_by_the_application_makes_the_next_period_safe() {
        let mut h = hopper(Strategy::default());
        let raw = crate::proptest_support::rest_sample(&h.config().calibration);
        assert!(h.step(Some(&raw), 1e-4).command.amp_enable);
        h.supervisor_mut().report_overrun();
        let out = h.step(Some(&raw), 1e-4);
        assert_eq!(out.command, Command::SAFE);
        assert!(out.faults.contains(Fault::Overrun));
    }

    #[test]
    fn bad_configuration_is_refused() {
        let cfg = HopperConfig {
            target_apex_m: -0.1,
            ..HopperConfig::default()
        };
        assert_eq!(Hopper::new(cfg).err(), Some(ConfigError::TargetApex));
        let cfg = HopperConfig {
            strategy: Strategy::EnergyApex(ApexLoop {
                gain: 0.0,
                ..ApexLoop::default()
            }),
            ..HopperConfig::default()
        };
        assert_eq!(
            Hopper::new(cfg).err(),
            Some(ConfigError::Law(InvalidField("energy_apex.integral_gain")))
        );
        // Bad flight gains used to run with no nut return (0 A in flight).
        let mut cfg = HopperConfig::default();
        cfg.flight.gains.kd = f32::NAN;
        assert_eq!(
            Hopper::new(cfg).err(),
            Some(ConfigError::Law(InvalidField("flight.kd_a_s_per_rad")))
        );
        let mut h = hopper(Strategy::default());
        assert!(h.set_target_apex(f32::NAN).is_err());
        assert!(h.set_target_apex(0.1).is_ok());
        // (M + m_s) g (l0 + H) + m_u g H + k delta0^2 / 2 = 64.426 + 0.589 + 0
        // (no preload).
        assert!(
            (h.desired_energy_j() - 65.016).abs() < 0.01,
            "{}",
            h.desired_energy_j()
        );
    }

    fn any_raw() -> impl proptest::strategy::Strategy<Value = RawSample> {
        (
            any::<u16>(),
            any::<u16>(),
            0u16..4096,
            0u16..4096,
            any::<bool>(),
            any::<bool>(),
        )
            .prop_map(|(m, z, lc, pot, estop, amp)| RawSample {
                motor_counts: u32::from(m),
                height_counts: u32::from(z),
                loadcell_code: lc,
                pot_code: pot,
                estop_pressed: estop,
                amp_fault: amp,
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        /// Any raw stream: the command stays within the limit, the DAC code
        /// in range, and a latched fault stays latched with a zero command.
        #[test]
        fn any_sensor_stream_gives_a_bounded_command(
            stream in proptest::collection::vec(proptest::option::weighted(0.98, any_raw()), 1..60),
            law in 0usize..3,
            dt in prop_oneof![Just(1e-4f32), 1e-6f32..1e-2, Just(0.0f32), Just(f32::NAN)],
        ) {
            let strategy = match law {
                0 => Strategy::Passive,
                1 => Strategy::Thesis(StanceLaw::ModifiedTorque(modified_torque::Config::default())),
                _ => Strategy::default(),
            };
            let mut h = hopper(strategy);
            let limit = h.supervisor().current_limit_a();
            let mut latched = false;
            for raw in &stream {
                let out = h.step(raw.as_ref(), dt);
                prop_assert!(out.command.current_a.is_finite());
                prop_assert!(out.command.current_a.abs() <= limit);
                prop_assert!(out.dac_code <= 4095);
                if latched {
                    prop_assert_eq!(out.command, Command::SAFE);
                    prop_assert_eq!(out.dac_code, 2048);
                }
                latched |= !out.faults.is_empty();
            }
        }
    }

    /// Properties over random parameter sets, gains, targets and
    /// sensor streams: 10 000 cases each by default
    /// ([`crate::proptest_support::cases`]).
    mod properties {
        use super::super::*;
        use crate::hal::{HopperIo, IoError};
        use crate::laws::{
            energy, modified_torque, open_torque, step_closed, step_open, velocity, InvalidField,
            NutPositionPd, StanceLaw,
        };
        use crate::pd_design::PdGains;
        use crate::runner::{NoCounter, PeriodRunner, Timing};
        use crate::supervisor::SupervisorInput;
        use proptest::prelude::{any, prop_assert, prop_assert_eq, prop_oneof, Just};
        use proptest::strategy::Strategy as Gen;
        use proptest::test_runner::TestCaseError;

        /// A valid model around the thesis hardware: every field varied over
        /// a range a real build of this robot could plausibly have.
        fn any_model() -> impl Gen<Value = ModelParams> {
            (
                (1.0f32..50.0, 1e-3f32..5.0, 1e-3f32..2.0, 1e-5f32..1e-3),
                (1e-3f32..0.02, 1e3f32..1e5, 0.3f32..1.5, 0.0f32..0.02),
                (0.01f32..0.1, 0.3f32..=1.0, 1.0f32..20.0),
                (0.1f32..5.0, 0.005f32..0.2, 1.0f32..100.0),
            )
                .prop_map(
                    |((m, mu, ms, j), (lead, k, l0, d0), (stroke, eta, g), (tl, kt, il))| {
                        ModelParams {
                            body_mass_kg: m,
                            unsprung_mass_kg: mu,
                            nut_mass_kg: ms,
                            rotor_inertia_kg_m2: j,
                            screw_lead_m: lead,
                            spring_stiffness_n_per_m: k,
                            leg_length_m: l0,
                            preload_m: d0,
                            stroke_m: stroke,
                            efficiency: eta,
                            gravity_mps2: g,
                            torque_limit_nm: tl,
                            torque_constant_nm_per_a: kt,
                            current_limit_a: il,
                        }
                    },
                )
        }

        /// A gain of any size, and now and then of any sign or NaN or
        /// infinite: the bound on the command must not depend on the laws
        /// being sane, and a configuration they refuse must be refused by
        /// name ([`built`]).
        fn any_gain(typical: f32) -> impl Gen<Value = f32> {
            prop_oneof![
                6 => 0.0f32..(10.0 * typical),
                2 => 0.0f32..(1e4 * typical),
                1 => any::<f32>(),
            ]
        }

        /// The hopper for `cfg`, or `None` when a law field is refused by
        /// name (any other refusal fails the case: the generated models and
        /// calibrations are valid).
        fn built(cfg: HopperConfig) -> Result<Option<Hopper>, TestCaseError> {
            match Hopper::new(cfg) {
                Ok(h) => Ok(Some(h)),
                Err(ConfigError::Law(InvalidField(name))) if !name.is_empty() => Ok(None),
                Err(e) => Err(fail(e)),
            }
        }

        /// Every strategy: passive, each thesis law, the apex loop.
        fn any_strategy() -> impl Gen<Value = Strategy> {
            let apex = (
                any_gain(3.0),
                any::<bool>(),
                any::<bool>(),
                (
                    0.0f32..2.0,
                    1e-3f32..9.99,
                    0.0f32..60.0,
                    -10.0f32..=0.0,
                    0.0f32..=1.0,
                ),
            )
                .prop_map(|(ke, neg, body, (kp, ki, max, min, spin))| {
                    Strategy::EnergyApex(ApexLoop {
                        law: energy::Config {
                            gain_nm_per_j: ke,
                            allow_negative: neg,
                        },
                        measure: if body {
                            EnergyMeasure::Body
                        } else {
                            EnergyMeasure::Total
                        },
                        proportional: kp,
                        gain: ki,
                        max_offset_j: max,
                        min_offset_j: min,
                        spin_up_fraction: spin,
                    })
                });
            let pd = || {
                (any_gain(8e4), any_gain(300.0), any::<bool>()).prop_map(|(kp, kd, ff)| {
                    NutPositionPd {
                        kp_n_per_m: kp,
                        kd_n_s_per_m: kd,
                        spring_feedforward: ff,
                    }
                })
            };
            prop_oneof![
                Just(Strategy::Passive),
                (any_gain(0.01), pd()).prop_map(|(step_m, pd)| Strategy::Thesis(
                    StanceLaw::StepOpen(step_open::Config { step_m, pd })
                )),
                (any_gain(2e-3), pd()).prop_map(|(kp_m_per_j, pd)| Strategy::Thesis(
                    StanceLaw::StepClosed(step_closed::Config {
                        gain: step_closed::Gain::Fixed { kp_m_per_j },
                        pd,
                    })
                )),
                any_gain(1.0).prop_map(|torque_nm| Strategy::Thesis(StanceLaw::OpenTorque(
                    open_torque::Config { torque_nm }
                ))),
                (any_gain(0.2), any::<bool>()).prop_map(|(g, neg)| Strategy::Thesis(
                    StanceLaw::Energy(energy::Config {
                        gain_nm_per_j: g,
                        allow_negative: neg,
                    })
                )),
                (any_gain(0.03), any_gain(5000.0), any::<bool>()).prop_map(|(g, l, ff)| {
                    Strategy::Thesis(StanceLaw::Velocity(velocity::Config {
                        gain_mps_per_j: g,
                        loop_gain_n_s_per_m: l,
                        spring_feedforward: ff,
                    }))
                }),
                (any_gain(1.0), 0.0f32..=1.0).prop_map(|(t, f)| Strategy::Thesis(
                    StanceLaw::ModifiedTorque(modified_torque::Config {
                        torque_nm: t,
                        apex_fraction: f,
                    })
                )),
                apex,
            ]
        }

        /// The configuration of one case.
        #[derive(Debug, Clone)]
        struct Setup {
            cfg: HopperConfig,
        }

        fn any_setup() -> impl Gen<Value = Setup> {
            (
                any_model(),
                any_strategy(),
                (any_gain(20.3152), any_gain(0.6077), 0.0f32..0.05),
                0.0f32..=1.0,
                prop_oneof![3 => Just(1.0f32), 1 => 0.05f32..=1.0],
            )
                .prop_map(|(model, strategy, (kp, kd, start), target, scale)| {
                    let mut cfg = HopperConfig::for_model(model);
                    cfg.strategy = strategy;
                    cfg.flight = crate::laws::flight_pd::Config {
                        gains: PdGains { kp, kd },
                        start_position_m: start,
                    };
                    cfg.target_apex_m = target;
                    // A supervisor limit below the model's: the command must
                    // respect the configured limit, not the hardware's.
                    cfg.model.current_limit_a *= scale;
                    Setup { cfg }
                })
        }

        /// One period's input: a step of a plausible, internally consistent
        /// sensor walk (load cell, potentiometer and motor encoder agree
        /// through the spring, plus noise), an arbitrary raw sample, or a
        /// failed read.
        #[derive(Debug, Clone, Copy)]
        enum Item {
            /// Motor counts, compression in pot codes, height counts, and
            /// load-cell / pot noise in codes.
            Walk(i32, i32, i32, i32, i32, bool),
            Raw(RawSample),
            Missing,
        }

        fn any_item() -> impl Gen<Value = Item> {
            prop_oneof![
                40 => (-48i32..48, -12i32..12, -24i32..24, -6i32..6, -3i32..3, proptest::bool::weighted(0.002))
                    .prop_map(|(m, c, z, nl, np, e)| Item::Walk(m, c, z, nl, np, e)),
                1 => super::any_raw().prop_map(Item::Raw),
                1 => Just(Item::Missing),
            ]
        }

        /// Turns items into raw samples, keeping the walk's state.
        struct Walker {
            motor: u32,
            height: u32,
            compression_codes: i32,
        }

        impl Walker {
            fn new() -> Self {
                Walker {
                    motor: 0,
                    height: 0,
                    compression_codes: 0,
                }
            }

            fn sample(&mut self, cfg: &HopperConfig, item: Item) -> Option<RawSample> {
                let cal = &cfg.calibration;
                match item {
                    Item::Missing => None,
                    Item::Raw(r) => Some(r),
                    Item::Walk(dm, dc, dz, nl, np, estop) => {
                        self.motor = self.motor.wrapping_add_signed(dm);
                        self.height = self.height.wrapping_add_signed(dz);
                        self.compression_codes = (self.compression_codes + dc).clamp(0, 3000);
                        // Counters are `motor_counter_bits` wide: the nut
                        // position the converter sees is the sign-extended
                        // accumulation, which this walk keeps small.
                        let p_m = f32::from(self.motor as u16 as i16) * cal.nut_m_per_count();
                        let x_m = self.compression_codes as f32 * cal.pot_gain_m_per_code;
                        let m = &cfg.model;
                        let force_n =
                            m.spring_stiffness_n_per_m * (m.preload_m + p_m.max(0.0) + x_m);
                        let code = |offset: f32, value: f32, noise: i32| {
                            (offset + value + noise as f32).round().clamp(0.0, 4095.0) as u16
                        };
                        Some(RawSample {
                            motor_counts: self.motor & 0xFFFF,
                            height_counts: self.height & 0xFFFF,
                            loadcell_code: code(
                                cal.loadcell_offset_code,
                                force_n / cal.loadcell_gain_n_per_code,
                                nl,
                            ),
                            pot_code: code(cal.pot_offset_code, self.compression_codes as f32, np),
                            estop_pressed: estop,
                            amp_fault: false,
                        })
                    }
                }
            }
        }

        fn any_dt() -> impl Gen<Value = f32> {
            prop_oneof![8 => Just(1e-4f32), 1 => 1e-6f32..1e-2, 1 => Just(0.0f32), 1 => Just(f32::NAN)]
        }

        fn fail(e: impl core::fmt::Debug) -> TestCaseError {
            TestCaseError::fail(std::format!("{e:?}"))
        }

        extern crate std;

        /// Property 1: whatever the sensors, strategy, gains, target and
        /// (valid) model, the approved command is finite and within the
        /// configured current range, the DAC code is the code of a current
        /// in that range, and a disabled amplifier gets 0 A.
        #[test]
        fn command_never_leaves_the_configured_current_range() {
            let strategy = (
                any_setup(),
                proptest::collection::vec(any_item(), 1..40),
                any_dt(),
            );
            let result = crate::proptest_support::run(
                "command_never_leaves_the_configured_current_range",
                strategy,
                |(setup, items, dt)| {
                    let cfg = setup.cfg;
                    let Some(mut h) = built(cfg)? else {
                        return Ok(());
                    };
                    let limit = cfg.model.usable_current_limit_a();
                    prop_assert!(limit > 0.0);
                    let (lo, hi) = {
                        let a = DacMap::new(&cfg.calibration, limit).code(-limit);
                        let b = DacMap::new(&cfg.calibration, limit).code(limit);
                        (a.min(b), a.max(b))
                    };
                    let mut walk = Walker::new();
                    for item in items {
                        let raw = walk.sample(&cfg, item);
                        let out = h.step(raw.as_ref(), dt);
                        let i = out.command.current_a;
                        prop_assert!(i.is_finite(), "{:?}", out);
                        prop_assert!(i.abs() <= limit, "{} A beyond {} A", i, limit);
                        prop_assert!((lo..=hi).contains(&out.dac_code), "{:?}", out);
                        if !out.command.amp_enable {
                            prop_assert_eq!(i, 0.0);
                        }
                    }
                    Ok(())
                },
            );
            result.unwrap_or_else(|e| panic!("{e}"));
        }

        /// What the application does between periods.
        #[derive(Debug, Clone, Copy)]
        enum Action {
            Step(Item),
            /// `run_period` on an I/O whose DAC write fails.
            StepDacFails(Item),
            Overrun,
            Reset,
        }

        fn any_action() -> impl Gen<Value = Action> {
            prop_oneof![
                30 => any_item().prop_map(Action::Step),
                1 => any_item().prop_map(Action::StepDacFails),
                1 => Just(Action::Overrun),
                2 => Just(Action::Reset),
            ]
        }

        /// The sample (or a failed read), and a DAC that fails on request.
        struct TestIo(Option<RawSample>, bool);
        impl HopperIo for TestIo {
            type Error = ();
            fn read(&mut self) -> Result<RawSample, IoError<()>> {
                self.0.ok_or(IoError::Sensor)
            }
            fn write_dac(&mut self, _code: u16) -> Result<(), IoError<()>> {
                if self.1 {
                    Err(IoError::Dac)
                } else {
                    Ok(())
                }
            }
            fn set_amp_enabled(&mut self, _on: bool) -> Result<(), IoError<()>> {
                Ok(())
            }
        }

        /// Property 2 (control step): a latched fault stays latched, with
        /// 0 A, the zero code and the amplifier disabled, through any later
        /// samples, overruns and I/O errors, until a reset succeeds; and only
        /// a successful reset clears it.
        #[test]
        fn hopper_fault_stays_latched_until_reset() {
            let strategy = (any_setup(), proptest::collection::vec(any_action(), 1..40));
            let result = crate::proptest_support::run(
                "hopper_fault_stays_latched_until_reset",
                strategy,
                |(setup, actions)| {
                    let cfg = setup.cfg;
                    if built(cfg)?.is_none() {
                        return Ok(());
                    }
                    let mut r = PeriodRunner::new(cfg, Timing::default()).map_err(fail)?;
                    let zero =
                        DacMap::new(&cfg.calibration, cfg.model.usable_current_limit_a()).code(0.0);
                    let m = &cfg.model;
                    // A clean sample at rest for the reset: nut on its stop,
                    // leg extended, spring at preload.
                    let rest = SupervisorInput {
                        body_height_m: m.leg_length_m,
                        spring_force_n: m.spring_stiffness_n_per_m * m.preload_m,
                        ..SupervisorInput::default()
                    };
                    let mut walk = Walker::new();
                    for action in actions {
                        let before = r.hopper().supervisor().faults();
                        let out = match action {
                            Action::Overrun => {
                                r.report_overrun();
                                prop_assert!(r
                                    .hopper()
                                    .supervisor()
                                    .faults()
                                    .contains(Fault::Overrun));
                                continue;
                            }
                            Action::Reset => {
                                let ok = r.reset_faults(&rest).is_ok();
                                let after = r.hopper().supervisor().faults();
                                if ok {
                                    prop_assert!(after.is_empty());
                                } else {
                                    // A refused reset clears nothing.
                                    prop_assert_eq!(after.0 & before.0, before.0);
                                }
                                continue;
                            }
                            Action::Step(item) => {
                                let mut io = TestIo(walk.sample(&cfg, item), false);
                                let p = r.run_period(&mut io, &mut NoCounter);
                                // A fault-free period and a safely faulted
                                // one both keep the watchdog fed.
                                prop_assert!(p.feed_watchdog);
                                p.out
                            }
                            Action::StepDacFails(item) => {
                                let mut io = TestIo(walk.sample(&cfg, item), true);
                                let out = r.run_period(&mut io, &mut NoCounter).out;
                                prop_assert!(out.faults.contains(Fault::DacError));
                                out
                            }
                        };
                        // Faults only accumulate between resets.
                        prop_assert_eq!(out.faults.0 & before.0, before.0);
                        prop_assert_eq!(out.faults, r.hopper().supervisor().faults());
                        if !out.faults.is_empty() {
                            prop_assert_eq!(out.command, Command::SAFE);
                            prop_assert_eq!(out.dac_code, zero);
                        }
                    }
                    Ok(())
                },
            );
            result.unwrap_or_else(|e| panic!("{e}"));
        }
    }
}
