//! The planar machine's control period, as the firmware runs it: this
//! period's readings through the estimator, Raibert's controller and
//! what drives the leg, both windings' heat, the guard over the command,
//! and the currents both amplifiers are told to drive. The host's
//! simulator, the QEMU planar image and a board all run this one type.

use super::estimator::{PlanarEstimator, PlanarEstimatorConfig, PlanarReadings};
use super::guard::{Guard, GuardConfig, PlanarFault};
use super::raibert::{Raibert, RaibertConfig};
use super::thrust::ScrewThrust;
use super::{limited_current_a, HipDrive, PlanarCommand, PlanarEstimate};
use crate::laws::Strategy;
use crate::model::ModelParams;
use crate::param::InvalidField;
use crate::thermal::{MotorThermal, ThermalConfig};

/// What drives a planar machine's leg in its period.
pub trait LegDrive: Clone + core::fmt::Debug {
    /// Whether the leg is driven through its ball screw by a motor (the
    /// period keeps the readings and counts the motor's heat), or by the
    /// controller's force along it.
    const SCREW: bool;

    /// The leg motor's current this period for `est` and the readings
    /// `r`, A (0 for a leg driven by force); `faulted` when the guard has
    /// latched.
    fn leg_current_a(
        &mut self,
        est: &PlanarEstimate,
        r: &PlanarReadings,
        faulted: bool,
        dt_s: f32,
    ) -> f32;

    /// Where the leg's nut stands by the readings `r`, m below its upper
    /// stop (0 for a leg driven by force: it has no nut).
    fn nut_position_m(&self, _r: &PlanarReadings) -> f32 {
        0.0
    }

    /// The nut's speed as the leg's drive last estimated it, m/s (0 for a
    /// leg driven by force).
    fn nut_velocity_mps(&self) -> f32 {
        0.0
    }

    /// The last hop's apex, the toe's height, m, as the leg's law took it
    /// (`None` before the first, and for a leg driven by force).
    fn last_apex_m(&self) -> Option<f32> {
        None
    }
}

/// The leg driven by the controller's force along it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ForceLeg;

impl LegDrive for ForceLeg {
    const SCREW: bool = false;

    #[inline(always)]
    fn leg_current_a(&mut self, _: &PlanarEstimate, _: &PlanarReadings, _: bool, _: f32) -> f32 {
        0.0
    }
}

impl LegDrive for ScrewThrust {
    const SCREW: bool = true;

    fn leg_current_a(
        &mut self,
        est: &PlanarEstimate,
        r: &PlanarReadings,
        faulted: bool,
        dt_s: f32,
    ) -> f32 {
        self.current_a(est, r.leg_length_m, r.leg_motor_rad, faulted, dt_s)
    }

    fn nut_position_m(&self, r: &PlanarReadings) -> f32 {
        self.nut_position_m(r.leg_motor_rad)
    }

    fn nut_velocity_mps(&self) -> f32 {
        self.nut_velocity_mps()
    }

    fn last_apex_m(&self) -> Option<f32> {
        self.last_apex_m()
    }
}

/// The planar machine's controller over a period, its leg driven as `L`
/// says. In this order, the period's fields first: the Cortex-M4's
/// floating-point loads and stores reach 1,020 bytes from a base.
#[derive(Clone, Debug)]
#[repr(C)]
pub struct PlanarPeriod<L: LegDrive = ForceLeg> {
    /// The controller.
    controller: Raibert,
    /// The pitch, leg-angle and fall limits over its command.
    guard: Guard,
    /// The estimator.
    estimator: PlanarEstimator,
    /// The hip's drive: torque to current, within the amplifier's limit.
    hip: HipDrive,
    /// The hip motor's winding temperature, as the firmware estimates it
    /// (the leg motor's model and data: derated, then off, when hot).
    hip_thermal: MotorThermal,
    /// The leg motor's, when the leg is driven through its screw (the same
    /// model and data: derated, then off, when hot).
    leg_thermal: MotorThermal,
    /// The hip current commanded this period, A.
    hip_current_a: f32,
    /// The leg motor's amplifier limit, A.
    leg_current_limit_a: f32,
    /// This period's readings (kept for the leg's screw).
    readings: PlanarReadings,
    /// What drives the leg.
    leg: L,
    /// Each winding reached its trip temperature since the last reset:
    /// it must cool below its derating temperature before one.
    hip_tripped: bool,
    leg_tripped: bool,
}

impl PlanarPeriod {
    /// Raibert's controller with `cfg` on a machine whose leg is
    /// `leg_length_m` long and whose hip is driven by `hip` (the
    /// controller's torque limit at most the drive's), its speed measured
    /// by a boom's forward encoder or, with `speed_from_leg`, from the
    /// leg's kinematics in stance; the leg by the controller's force. A
    /// field out of range is refused by name.
    pub fn new(
        cfg: RaibertConfig,
        leg_length_m: f32,
        hip: HipDrive,
        speed_from_leg: bool,
    ) -> Result<Self, InvalidField> {
        hip.validate()?;
        cfg.validate()?;
        let cfg = RaibertConfig {
            leg_length_m,
            max_hip_torque_nm: cfg.max_hip_torque_nm.min(hip.torque_limit_nm()),
            ..cfg
        };
        let controller = Raibert::new(cfg)?;
        let guard = Guard::new(GuardConfig::table_2_2())?;
        let estimator = PlanarEstimator::new(PlanarEstimatorConfig {
            leg_length_m,
            speed_from_leg,
            ..PlanarEstimatorConfig::table_2_2()
        })?;
        let hip_thermal = MotorThermal::new(ThermalConfig::default())?;
        Ok(PlanarPeriod {
            controller,
            guard,
            estimator,
            hip,
            hip_thermal,
            leg_thermal: hip_thermal,
            hip_current_a: 0.0,
            leg_current_limit_a: 0.0,
            readings: PlanarReadings::default(),
            leg: ForceLeg,
            hip_tripped: false,
            leg_tripped: false,
        })
    }

    /// The leg driven as on the vertical hopper: its motor turns the ball
    /// screw of the leg `model` describes, run by the vertical law
    /// `strategy` holding the controller's apex target (the controller's
    /// own thrust unused).
    pub fn with_screw(
        self,
        strategy: &Strategy,
        model: &ModelParams,
    ) -> Result<PlanarPeriod<ScrewThrust>, InvalidField> {
        let target = self.controller.config().target_apex_m;
        let gain = self.estimator.config().rate_filter_gain;
        let leg = ScrewThrust::new(strategy, model, target, gain)?;
        Ok(PlanarPeriod {
            controller: self.controller,
            guard: self.guard,
            estimator: self.estimator,
            hip: self.hip,
            hip_thermal: self.hip_thermal,
            leg_thermal: self.leg_thermal,
            hip_current_a: self.hip_current_a,
            leg_current_limit_a: model.current_limit_a,
            readings: self.readings,
            leg,
            hip_tripped: self.hip_tripped,
            leg_tripped: self.leg_tripped,
        })
    }
}

impl<L: LegDrive> PlanarPeriod<L> {
    /// The estimate from this period's readings `r`, `dt_s` after the
    /// last.
    pub fn estimate_from(&mut self, r: &PlanarReadings, dt_s: f32) -> PlanarEstimate {
        if L::SCREW {
            self.readings = *r;
        }
        self.estimator.update(r, dt_s)
    }

    /// The command for `est` at the commanded speed, through the guard
    /// (zero on both actuators once a limit latched): the hip's torque as
    /// the current its amplifier is told to drive gives it (within the
    /// current limit, derated when the winding is hot), the leg motor's
    /// current likewise.
    #[inline(always)]
    pub fn control(
        &mut self,
        est: &PlanarEstimate,
        speed_command_mps: f32,
        dt_s: f32,
    ) -> PlanarCommand {
        self.control_armed(est, speed_command_mps, dt_s, true)
    }

    /// [`control`](Self::control) with both amplifiers enabled only if
    /// `armed`: disarmed, both are told 0 (the guard still watches, and
    /// the windings' heat counts the current they drive, none), and the
    /// leg's law learns nothing from the hops.
    pub fn control_armed(
        &mut self,
        est: &PlanarEstimate,
        speed_command_mps: f32,
        dt_s: f32,
        armed: bool,
    ) -> PlanarCommand {
        let mut cmd = self.controller.step(est, speed_command_mps, dt_s);
        if L::SCREW {
            // The leg motor's encoder is read here, not by the estimator:
            // a reading that is not a number stops the machine; so does
            // its winding at the trip temperature.
            if !self.readings.leg_motor_rad.is_finite() {
                self.guard.latch(PlanarFault::NonFinite);
            }
            if self.leg_thermal.tripped() {
                self.leg_tripped = true;
                self.guard.latch(PlanarFault::LegOvertemperature);
            }
            let faulted = self.guard.fault().is_some() || !armed;
            cmd.leg_current_a = self.leg.leg_current_a(est, &self.readings, faulted, dt_s);
            cmd.leg_thrust_n = 0.0;
        }
        // A winding at its trip temperature stops the machine, as the leg
        // motor's stops the vertical hopper.
        if self.hip_thermal.tripped() {
            self.hip_tripped = true;
            self.guard.latch(PlanarFault::HipOvertemperature);
        }
        let cmd = self.guard.filter(est, cmd);
        let cmd = if armed { cmd } else { PlanarCommand::default() };
        let current_a = self
            .hip
            .current_a(cmd.hip_torque_nm, self.hip_thermal.limit_scale());
        self.hip_thermal.add(current_a, dt_s);
        self.hip_current_a = current_a;
        let leg_current_a = if L::SCREW {
            // Within the amplifier's limit, derated when the winding is
            // hot (the vertical hopper's leg motor's model).
            let i = limited_current_a(
                cmd.leg_current_a,
                self.leg_current_limit_a,
                self.leg_thermal.limit_scale(),
            );
            self.leg_thermal.add(i, dt_s);
            i
        } else {
            0.0
        };
        PlanarCommand {
            hip_torque_nm: current_a * self.hip.torque_per_amp_nm_per_a,
            leg_current_a,
            ..cmd
        }
    }

    /// The controller.
    pub fn controller(&self) -> &Raibert {
        &self.controller
    }

    /// What drives the leg.
    pub fn leg(&self) -> &L {
        &self.leg
    }

    /// The hip's drive.
    pub fn hip(&self) -> &HipDrive {
        &self.hip
    }

    /// The hip current commanded this period, A.
    pub fn hip_current_a(&self) -> f32 {
        self.hip_current_a
    }

    /// The hip motor's winding temperature as the firmware estimates it, C.
    pub fn hip_winding_c(&self) -> f32 {
        self.hip_thermal.winding_c()
    }

    /// The leg motor's winding temperature as the firmware estimates it,
    /// C (a leg driven through its screw).
    pub fn leg_winding_c(&self) -> f32 {
        self.leg_thermal.winding_c()
    }

    /// What the guard latched, if anything.
    pub fn fault(&self) -> Option<PlanarFault> {
        self.guard.fault()
    }

    /// The hotter motor's thermal estimate (the hip's, or the leg's when
    /// the leg is driven through its screw and its winding is hotter).
    pub fn hotter_winding(&self) -> &MotorThermal {
        if L::SCREW && self.leg_thermal.winding_c() > self.hip_thermal.winding_c() {
            &self.leg_thermal
        } else {
            &self.hip_thermal
        }
    }

    /// Clears what the guard latched, if `est` is within every limit and
    /// every winding that tripped since the last reset has cooled below
    /// its derating temperature; else what remains, and nothing is
    /// cleared.
    pub fn reset_fault(&mut self, est: &PlanarEstimate) -> Result<(), PlanarFault> {
        // A winding's trip clears once it has cooled below the derating
        // temperature, as the vertical hopper's does, whichever fault the
        // guard holds.
        if self.hip_tripped && !self.hip_thermal.cool() {
            return Err(PlanarFault::HipOvertemperature);
        }
        if self.leg_tripped && !self.leg_thermal.cool() {
            return Err(PlanarFault::LegOvertemperature);
        }
        // The leg motor's encoder, which the estimator does not read.
        if L::SCREW && !self.readings.leg_motor_rad.is_finite() {
            return Err(PlanarFault::NonFinite);
        }
        self.guard.reset(est)?;
        self.hip_tripped = false;
        self.leg_tripped = false;
        Ok(())
    }

    /// Where the leg's nut stands by this period's readings, m below its
    /// upper stop (0 for a leg driven by force).
    pub fn nut_position_m(&self) -> f32 {
        self.leg.nut_position_m(&self.readings)
    }

    /// The leg's nut's speed as last estimated, m/s (0 for a leg driven
    /// by force).
    pub fn nut_velocity_mps(&self) -> f32 {
        self.leg.nut_velocity_mps()
    }

    /// The last hop's apex, the toe's height, m, as the leg's law took it
    /// (`None` before the first, and for a leg driven by force).
    pub fn last_apex_m(&self) -> Option<f32> {
        self.leg.last_apex_m()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laws::ControllerKind;

    const DT_S: f32 = 1e-4;

    fn period() -> PlanarPeriod<ScrewThrust> {
        PlanarPeriod::new(
            RaibertConfig::table_2_2(),
            super::super::TABLE_2_2_LEG_LENGTH_M,
            HipDrive::design(),
            false,
        )
        .and_then(|p| {
            p.with_screw(
                &ScrewThrust::planar_strategy(ControllerKind::EnergyApex),
                &super::super::thrust::tests::model(),
            )
        })
        .unwrap_or_else(|e| panic!("{e:?}"))
    }

    /// Standing upright on the toe, the leg at rest on its spring.
    fn standing() -> PlanarReadings {
        PlanarReadings {
            boom_x_m: 0.0,
            boom_z_m: 0.6,
            pitch_rad: 0.0,
            hip_angle_rad: 0.0,
            leg_length_m: 0.6,
            leg_motor_rad: 0.0,
        }
    }

    /// A machine set up with a drive that cannot be is refused by the
    /// field's name, before anything runs.
    #[test]
    fn a_bad_hip_drive_is_refused_by_name() {
        let hip = HipDrive {
            torque_per_amp_nm_per_a: f32::NAN,
            ..HipDrive::design()
        };
        let r = PlanarPeriod::new(RaibertConfig::table_2_2(), 0.65, hip, false);
        assert_eq!(r.err(), Some(InvalidField("torque_per_amp_nm_per_a")));
    }

    /// The leg motor's encoder read as not a number: the guard latches and
    /// both amplifiers are told 0 A from that period on, whatever the
    /// readings after it.
    #[test]
    fn a_leg_motor_reading_that_is_not_a_number_stops_both_motors() {
        let mut p = period();
        for _ in 0..100 {
            let est = p.estimate_from(&standing(), DT_S);
            p.control(&est, 0.0, DT_S);
        }
        assert_eq!(p.fault(), None);
        let bad = PlanarReadings {
            leg_motor_rad: f32::NAN,
            ..standing()
        };
        let est = p.estimate_from(&bad, DT_S);
        let cmd = p.control(&est, 0.0, DT_S);
        assert_eq!(p.fault(), Some(PlanarFault::NonFinite));
        assert_eq!((cmd.hip_torque_nm, cmd.leg_current_a), (0.0, 0.0));
        let est = p.estimate_from(&standing(), DT_S);
        let cmd = p.control(&est, 0.5, DT_S);
        assert_eq!((cmd.hip_torque_nm, cmd.leg_current_a), (0.0, 0.0));
        assert_eq!(p.hip_current_a(), 0.0);
    }

    proptest::proptest! {
        /// Any readings and command, finite or not, period after period:
        /// both currents finite and within their amplifiers' limits.
        #[test]
        fn the_currents_stay_within_the_limits(
            seq in proptest::collection::vec(
                (
                    proptest::prop_oneof![-2.0f32..2.0, proptest::prelude::Just(f32::NAN)],
                    0.3f32..1.2,
                    -1.0f32..1.0,
                    -1.0f32..1.0,
                    proptest::prop_oneof![0.4f32..0.7, proptest::prelude::Just(f32::INFINITY)],
                    -100.0f32..100.0,
                    proptest::prop_oneof![-3.0f32..3.0, proptest::prelude::Just(f32::NAN)],
                ),
                1..200,
            )
        ) {
            let mut p = period();
            let hip_limit = HipDrive::design().current_limit_a;
            let leg_limit = super::super::thrust::tests::model().current_limit_a;
            for (x, z, pitch, hip, leg, motor, speed) in seq {
                let r = PlanarReadings {
                    boom_x_m: x,
                    boom_z_m: z,
                    pitch_rad: pitch,
                    hip_angle_rad: hip,
                    leg_length_m: leg,
                    leg_motor_rad: motor,
                };
                let est = p.estimate_from(&r, DT_S);
                let cmd = p.control(&est, speed, DT_S);
                let hip_a = cmd.hip_torque_nm / HipDrive::design().torque_per_amp_nm_per_a;
                proptest::prop_assert!(hip_a.is_finite() && hip_a.abs() <= hip_limit * (1.0 + 1e-6));
                proptest::prop_assert!(cmd.leg_current_a.is_finite() && cmd.leg_current_a.abs() <= leg_limit);
            }
        }
    }
}
