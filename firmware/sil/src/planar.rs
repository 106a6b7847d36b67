//! The planar machine in the loop: Appendix A's runner with its hip
//! actuated ([`hopper_plant::planar_general`]) and a planar controller of
//! the control crate, one period at a time. `hopper-sim planar run
//! --controller raibert` and the QEMU planar image both run this, so the
//! golden check compares the same computation on two instruction sets.
//!
//! The controller reads what a boom-mounted machine's sensors measure
//! ([`PlanarSensors`]: the plant's state quantised to each encoder's and
//! the potentiometer's resolution) through the control crate's planar
//! estimator, and its command holds over the period.

use hopper_control::planar::estimator::{PlanarEstimator, PlanarEstimatorConfig, PlanarReadings};
use hopper_control::planar::guard::{Guard, GuardConfig, PlanarFault};
use hopper_control::planar::raibert::{Raibert, RaibertConfig};
use hopper_control::planar::{HipDrive, PlanarCommand, PlanarEstimate};
use hopper_control::thermal::{MotorThermal, ThermalConfig};
use hopper_plant::planar::{ApexState, PlanarError, PlanarEvent, PlanarState};
use hopper_plant::planar_general::{Actuation, GeneralParams, GeneralRunner};

/// The plant's integration step and the controller's period, s (the
/// firmware's 10 kHz).
pub const DT_S: f64 = 1e-4;

/// A planar machine: Appendix A's runner, its hip's drive and its
/// sensors (what a robot file describes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarMachine {
    /// The runner.
    pub params: GeneralParams,
    /// The hip's drive: torque per ampere and the amplifier's limit.
    pub hip: HipDrive,
    /// The hip motor's winding resistance, ohm.
    pub hip_winding_ohm: f64,
    /// The sensors.
    pub sensors: PlanarSensors,
}

impl PlanarMachine {
    /// Table 2.2's machine with its hip actuated
    /// ([`GeneralParams::actuated_table_2_2`]), the leg's motor through
    /// the design's gearhead at the hip ([`HipDrive::design`], the leg
    /// motor's winding), on a boom ([`PlanarSensors::boom`]).
    pub fn design() -> Self {
        PlanarMachine {
            params: GeneralParams::actuated_table_2_2(),
            hip: HipDrive::design(),
            hip_winding_ohm: hopper_plant::params::Params::design().winding_resistance_ohm,
            sensors: PlanarSensors::boom(),
        }
    }

    /// Every part within its ranges; else the first field that is not.
    pub fn validate(&self) -> Result<(), PlanarError> {
        self.params.validate()?;
        self.hip
            .validate()
            .map_err(|e| PlanarError::OutOfRange(e.0))?;
        if !(self.hip_winding_ohm.is_finite() && self.hip_winding_ohm > 0.0) {
            return Err(PlanarError::NotPositive("hip_winding_ohm"));
        }
        self.sensors.validate()
    }
}

/// The sensors of a planar hopper on a boom, by their resolution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarSensors {
    /// The hip's forward position, m a count; 0: the machine has no
    /// forward encoder, and the estimator takes the speed from the leg's
    /// kinematics in stance.
    pub boom_x_m: f64,
    /// The hip's height, m a count.
    pub boom_z_m: f64,
    /// The body's pitch, rad a count.
    pub pitch_rad: f64,
    /// The hip's angle (the leg against the body), rad a count.
    pub hip_rad: f64,
    /// The leg's length, m a step of the potentiometer's converter.
    pub leg_m: f64,
}

impl PlanarSensors {
    /// A 1.5 m boom with 20,000-line encoders read in quadrature (80,000
    /// counts a turn: 118 um at the hip), 16,384-line encoders on the
    /// pitch and the hip (65,536 counts: 96 urad), and the leg's
    /// potentiometer read by a 12-bit converter over 0.1 m (24 um).
    pub const fn boom() -> Self {
        const TURN: f64 = 2.0 * core::f64::consts::PI;
        PlanarSensors {
            boom_x_m: TURN * 1.5 / 80_000.0,
            boom_z_m: TURN * 1.5 / 80_000.0,
            pitch_rad: TURN / 65_536.0,
            hip_rad: TURN / 65_536.0,
            leg_m: 0.1 / 4096.0,
        }
    }

    /// Every resolution finite and positive; else the first that is not.
    pub fn validate(&self) -> Result<(), PlanarError> {
        if !(self.boom_x_m.is_finite() && self.boom_x_m >= 0.0) {
            return Err(PlanarError::OutOfRange("boom_x_m"));
        }
        for (name, v) in [
            ("boom_z_m", self.boom_z_m),
            ("pitch_rad", self.pitch_rad),
            ("hip_rad", self.hip_rad),
            ("leg_m", self.leg_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(PlanarError::NotPositive(name));
            }
        }
        Ok(())
    }

    /// What they read of `st`.
    pub fn read(&self, st: &PlanarState) -> PlanarReadings {
        // (No encoder, step 0: it reads 0.)
        let q = |v: f64, step: f64| {
            if step > 0.0 {
                (libm::round(v / step) * step) as f32
            } else {
                0.0
            }
        };
        PlanarReadings {
            boom_x_m: q(st.x_m, self.boom_x_m),
            boom_z_m: q(st.z_m, self.boom_z_m),
            pitch_rad: q(st.phi_rad, self.pitch_rad),
            hip_angle_rad: q(st.theta_rad - st.phi_rad, self.hip_rad),
            leg_length_m: q(st.leg_length_m, self.leg_m),
        }
    }
}

/// The plant and the controller.
#[derive(Clone, Copy, Debug)]
pub struct PlanarLoop {
    plant: GeneralRunner,
    /// The controller.
    pub controller: Raibert,
    /// The pitch, leg-angle and fall limits over its command.
    guard: Guard,
    /// The sensors.
    sensors: PlanarSensors,
    /// The estimator.
    estimator: PlanarEstimator,
    /// The hip's drive: torque to current, within the amplifier's limit.
    hip: HipDrive,
    /// The hip motor's winding temperature, as the firmware estimates it
    /// (the leg motor's model and data: derated, then off, when hot).
    hip_thermal: MotorThermal,
    /// The hip's copper loss so far, by the plant's winding, J.
    hip_copper_loss_j: f64,
    /// The hip motor's winding resistance, ohm.
    hip_winding_ohm: f64,
    /// The largest hip current so far, A.
    hip_peak_current_a: f32,
    /// The hip current commanded this period, A.
    hip_current_a: f32,
}

impl PlanarLoop {
    /// The design machine ([`PlanarMachine::design`]) at an apex with the
    /// toe `cfg.target_apex_m` up, moving at `speed_mps`, run by Raibert's
    /// controller with `cfg`.
    pub fn new(cfg: RaibertConfig, speed_mps: f64) -> Result<Self, PlanarError> {
        Self::of(&PlanarMachine::design(), cfg, speed_mps)
    }

    /// The machine `m` at an apex with the toe `cfg.target_apex_m` up,
    /// moving at `speed_mps`, run by Raibert's controller with `cfg` (its
    /// leg's length and the estimator's taken from the machine's, its
    /// torque limit at most the hip drive's).
    pub fn of(m: &PlanarMachine, cfg: RaibertConfig, speed_mps: f64) -> Result<Self, PlanarError> {
        m.validate()?;
        cfg.validate().map_err(|e| PlanarError::OutOfRange(e.0))?;
        let p = m.params;
        let cfg = RaibertConfig {
            leg_length_m: p.leg_length_m as f32,
            max_hip_torque_nm: cfg.max_hip_torque_nm.min(m.hip.torque_limit_nm()),
            ..cfg
        };
        let controller = Raibert::new(cfg).map_err(|e| PlanarError::OutOfRange(e.0))?;
        let guard =
            Guard::new(GuardConfig::table_2_2()).map_err(|e| PlanarError::OutOfRange(e.0))?;
        let start = ApexState {
            z_m: p.leg_length_m + f64::from(cfg.target_apex_m),
            x_dot_mps: speed_mps,
            phi_rad: 0.0,
            theta_rad: 0.0,
            phi_dot_rad_s: 0.0,
            theta_dot_rad_s: 0.0,
        };
        let estimator = PlanarEstimator::new(PlanarEstimatorConfig {
            leg_length_m: p.leg_length_m as f32,
            speed_from_leg: m.sensors.boom_x_m == 0.0,
            ..PlanarEstimatorConfig::table_2_2()
        })
        .map_err(|e| PlanarError::OutOfRange(e.0))?;
        let hip_thermal = MotorThermal::new(ThermalConfig::default())
            .map_err(|e| PlanarError::OutOfRange(e.0))?;
        Ok(PlanarLoop {
            plant: GeneralRunner::from_apex(p, &start)?,
            controller,
            guard,
            sensors: m.sensors,
            estimator,
            hip: m.hip,
            hip_thermal,
            hip_copper_loss_j: 0.0,
            hip_winding_ohm: m.hip_winding_ohm,
            hip_peak_current_a: 0.0,
            hip_current_a: 0.0,
        })
    }

    /// The plant's state.
    pub fn state(&self) -> PlanarState {
        self.plant.state()
    }

    /// The machine's parameters.
    pub fn params(&self) -> &GeneralParams {
        self.plant.params()
    }

    /// What the sensors read of the plant this period.
    pub fn sense(&self) -> PlanarReadings {
        self.sensors.read(&self.plant.state())
    }

    /// The estimator's period: the estimate from this period's readings.
    pub fn estimate_from(&mut self, r: &PlanarReadings) -> PlanarEstimate {
        self.estimator.update(r, DT_S as f32)
    }

    /// What the controller reads this period: the sensors' readings of
    /// the plant, through the estimator.
    pub fn estimate(&mut self) -> PlanarEstimate {
        let r = self.sense();
        self.estimate_from(&r)
    }

    /// The controller's period: its command for `est` at the commanded
    /// speed, through the guard (zero on both actuators once a limit
    /// latched), the hip's torque as the current its amplifier is told to
    /// drive gives it (within the current limit, derated when the winding
    /// is hot).
    pub fn control(&mut self, est: &PlanarEstimate, speed_command_mps: f64) -> PlanarCommand {
        let cmd = self
            .controller
            .step(est, speed_command_mps as f32, DT_S as f32);
        // A winding at its trip temperature stops the machine, as the leg
        // motor's stops the vertical hopper.
        if self.hip_thermal.tripped() {
            self.guard.latch(PlanarFault::HipOvertemperature);
        }
        let cmd = self.guard.filter(est, cmd);
        let current_a = self
            .hip
            .current_a(cmd.hip_torque_nm, self.hip_thermal.limit_scale());
        self.hip_thermal.add(current_a, DT_S as f32);
        self.hip_current_a = current_a;
        PlanarCommand {
            hip_torque_nm: current_a * self.hip.torque_per_amp_nm_per_a,
            ..cmd
        }
    }

    /// The hip motor's winding temperature as the firmware estimates it, C.
    pub fn hip_winding_c(&self) -> f32 {
        self.hip_thermal.winding_c()
    }

    /// The hip's copper loss so far, J.
    pub fn hip_copper_loss_j(&self) -> f64 {
        self.hip_copper_loss_j
    }

    /// The hip current commanded this period, A.
    pub fn hip_current_a(&self) -> f32 {
        self.hip_current_a
    }

    /// The largest hip current so far, A.
    pub fn hip_peak_current_a(&self) -> f32 {
        self.hip_peak_current_a
    }

    /// What the guard latched, if anything.
    pub fn fault(&self) -> Option<PlanarFault> {
        self.guard.fault()
    }

    /// Applies `cmd` (and a push on the body of `push_n`) and integrates
    /// the plant over the period, its transitions to `on_event`.
    pub fn advance(
        &mut self,
        cmd: PlanarCommand,
        push_n: f64,
        on_event: &mut impl FnMut(PlanarEvent),
    ) {
        // The hip's amplifier drives the current the torque was made of,
        // within its own limit; its winding turns it to heat.
        // (The plant's amplifier limits it as the firmware does: the same
        // drive, at the full limit.)
        let per_amp = f64::from(self.hip.torque_per_amp_nm_per_a);
        let current_a = f64::from(self.hip.current_a(cmd.hip_torque_nm, 1.0));
        self.hip_peak_current_a = self.hip_peak_current_a.max(libm::fabs(current_a) as f32);
        self.hip_copper_loss_j += current_a * current_a * self.hip_winding_ohm * DT_S;
        self.plant.set_actuation(Actuation {
            hip_torque_nm: current_a * per_amp,
            leg_thrust_n: f64::from(cmd.leg_thrust_n),
            push_n,
        });
        self.plant.step(DT_S, on_event);
    }
}
