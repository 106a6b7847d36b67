//! What a planar machine needs beyond the vertical supervisor's checks:
//! the body's pitch and the leg's angle within their limits, and a fall
//! detected (the hip below a height the machine only reaches lying on the
//! ground). Any of them, or a measurement that is not finite, latches and
//! zeroes both actuators' commands (the hip's and the leg's) from that
//! period on, until a reset on a machine back within its limits.

use super::{PlanarCommand, PlanarEstimate};
use crate::param::{require, InvalidField};

/// The limits, SI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GuardConfig {
    /// The largest |pitch| allowed, rad.
    pub max_pitch_rad: f32,
    /// The largest |leg angle| from the vertical allowed, rad.
    pub max_leg_angle_rad: f32,
    /// The hip below this height is a fall, m.
    pub min_hip_height_m: f32,
}

impl GuardConfig {
    /// Limits for the thesis's planar runner (a 0.65 m leg): 30 degrees of
    /// pitch, 35 degrees of leg angle, the hip below half the leg.
    pub const fn table_2_2() -> Self {
        GuardConfig {
            max_pitch_rad: 0.52,
            max_leg_angle_rad: 0.61,
            min_hip_height_m: 0.325,
        }
    }

    /// Every limit finite and positive; else the first that is not.
    pub fn validate(&self) -> Result<(), InvalidField> {
        let pos = |v: f32| v.is_finite() && v > 0.0;
        require(
            pos(self.max_pitch_rad) && self.max_pitch_rad < 1.6,
            "max_pitch_rad",
        )?;
        require(
            pos(self.max_leg_angle_rad) && self.max_leg_angle_rad < 1.6,
            "max_leg_angle_rad",
        )?;
        require(pos(self.min_hip_height_m), "min_hip_height_m")
    }
}

/// Why the guard stopped the machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlanarFault {
    /// A measurement was not finite.
    NonFinite,
    /// The body pitched beyond its limit.
    Pitch,
    /// The leg swung beyond its limit.
    LegAngle,
    /// The hip fell below its height.
    Fall,
    /// The hip motor's winding reached its trip temperature (the leg
    /// motor's thermal model, run on the hip's current).
    HipOvertemperature,
    /// The leg motor's winding reached its trip temperature (a leg driven
    /// through its ball screw).
    LegOvertemperature,
}

/// The guard (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Guard {
    cfg: GuardConfig,
    latched: Option<PlanarFault>,
}

impl Guard {
    /// A guard with `cfg`, checked.
    pub fn new(cfg: GuardConfig) -> Result<Self, InvalidField> {
        cfg.validate()?;
        Ok(Guard { cfg, latched: None })
    }

    /// What `est` violates, if anything (the first in the order of
    /// [`PlanarFault`]).
    pub fn violation(&self, est: &PlanarEstimate) -> Option<PlanarFault> {
        let c = &self.cfg;
        if !est.is_finite() {
            Some(PlanarFault::NonFinite)
        } else if est.phi_rad.abs() > c.max_pitch_rad {
            Some(PlanarFault::Pitch)
        } else if est.theta_rad.abs() > c.max_leg_angle_rad {
            Some(PlanarFault::LegAngle)
        } else if est.z_m < c.min_hip_height_m {
            Some(PlanarFault::Fall)
        } else {
            None
        }
    }

    /// The period's command: `cmd`, or zero on both actuators once a
    /// violation latched (this period's included).
    pub fn filter(&mut self, est: &PlanarEstimate, cmd: PlanarCommand) -> PlanarCommand {
        if self.latched.is_none() {
            self.latched = self.violation(est);
        }
        if self.latched.is_some() {
            PlanarCommand::default()
        } else {
            cmd
        }
    }

    /// Latches `fault`, found outside the guard's own checks (the hip
    /// winding's trip), unless another latched first.
    pub fn latch(&mut self, fault: PlanarFault) {
        if self.latched.is_none() {
            self.latched = Some(fault);
        }
    }

    /// What latched, if anything.
    pub fn fault(&self) -> Option<PlanarFault> {
        self.latched
    }

    /// Clears the latch if `est` is within every limit; else the
    /// violation that remains, and nothing is cleared.
    pub fn reset(&mut self, est: &PlanarEstimate) -> Result<(), PlanarFault> {
        match self.violation(est) {
            Some(v) => Err(v),
            None => {
                self.latched = None;
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn upright() -> PlanarEstimate {
        PlanarEstimate {
            z_m: 0.7,
            ..Default::default()
        }
    }

    const PUSH: PlanarCommand = PlanarCommand {
        hip_torque_nm: 10.0,
        leg_thrust_n: 200.0,
        leg_current_a: 5.0,
    };

    #[test]
    fn a_fault_found_elsewhere_latches_and_zeroes_both() {
        let mut g = Guard::new(GuardConfig::table_2_2()).unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(g.filter(&upright(), PUSH), PUSH);
        g.latch(PlanarFault::HipOvertemperature);
        // The first latched stays: a later one does not replace it.
        g.latch(PlanarFault::Fall);
        assert_eq!(g.fault(), Some(PlanarFault::HipOvertemperature));
        assert_eq!(g.filter(&upright(), PUSH), PlanarCommand::default());
    }

    #[test]
    fn each_limit_latches_and_zeroes_both_actuators_until_reset() {
        let cases = [
            (
                PlanarEstimate {
                    phi_rad: 0.6,
                    ..upright()
                },
                PlanarFault::Pitch,
            ),
            (
                PlanarEstimate {
                    theta_rad: -0.7,
                    ..upright()
                },
                PlanarFault::LegAngle,
            ),
            (
                PlanarEstimate {
                    z_m: 0.2,
                    ..upright()
                },
                PlanarFault::Fall,
            ),
            (
                PlanarEstimate {
                    x_dot_mps: f32::NAN,
                    ..upright()
                },
                PlanarFault::NonFinite,
            ),
        ];
        for (bad, why) in cases {
            let mut g = Guard::new(GuardConfig::table_2_2()).unwrap_or_else(|e| panic!("{e:?}"));
            assert_eq!(g.filter(&upright(), PUSH), PUSH);
            assert_eq!(g.filter(&bad, PUSH), PlanarCommand::default());
            // Back within its limits, still stopped until a reset.
            assert_eq!(g.filter(&upright(), PUSH), PlanarCommand::default());
            assert_eq!(g.fault(), Some(why));
            assert_eq!(g.reset(&bad), Err(why));
            assert_eq!(g.reset(&upright()), Ok(()));
            assert_eq!(g.filter(&upright(), PUSH), PUSH);
        }
    }

    #[test]
    fn a_bad_limit_is_refused_by_name() {
        let mut c = GuardConfig::table_2_2();
        c.min_hip_height_m = -1.0;
        assert_eq!(Guard::new(c).err(), Some(InvalidField("min_hip_height_m")));
    }

    proptest! {
        /// Whatever it reads, it passes the command only within every
        /// limit, and zero otherwise.
        #[test]
        fn the_command_passes_only_within_the_limits(
            phi in -2.0f32..2.0, theta in -2.0f32..2.0, z in 0.0f32..1.5,
        ) {
            let mut g = Guard::new(GuardConfig::table_2_2()).unwrap_or_else(|e| panic!("{e:?}"));
            let est = PlanarEstimate { phi_rad: phi, theta_rad: theta, z_m: z, ..Default::default() };
            let c = g.filter(&est, PUSH);
            let within = phi.abs() <= 0.52 && theta.abs() <= 0.61 && z >= 0.325;
            prop_assert_eq!(c == PUSH, within);
        }
    }
}
