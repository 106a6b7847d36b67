//! Open-loop constant torque (thesis section 2.1.3.4, Figures 2.8-2.9 and
//! section 4.4.2): a fixed motor torque for the whole stance.

use super::{
    flight_pd::FlightPd, or_zero, Actuator, ControlInput, ControlLaw, EventInput, InvalidField,
    LawError,
};
use crate::estimator::Phase;

crate::param::config! {
    /// Configuration of the constant-torque law.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct Config;
    params {
        // The open-torque law's parameter keeps its `constant_torque.` name:
        // parameter names are a contract (scenario files, the link,
        // docs/parameters.md) kept from before the law was renamed.
        /// Positive compresses the spring.
        7 CONSTANT_TORQUE_NM torque_nm: f32 {
            "constant_torque.torque_nm", "N m", Real, [-10.0, 10.0], 1.0, LIVE,
            "Open-loop stance torque (section 2.1.3.4; Table 2.1: 1 N m)."
        }
    }
}

/// Current command `tau / k_m`, A, clamped (a non-finite torque is refused
/// by [`Actuator::torque_to_current`]).
pub fn command(c: &Config, act: &Actuator) -> Result<f32, LawError> {
    act.torque_to_current(c.torque_nm)
}

impl Config {
    /// Checks every field, naming the first one out of range.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// The thesis's open-loop constant-torque controller: a fixed torque in
/// stance, the flight PD in flight. No state of its own.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OpenTorque {
    stance_a: f32,
    flight: FlightPd,
}

impl OpenTorque {
    /// Checks `cfg`.
    pub fn new(cfg: &Config, act: &Actuator, flight: FlightPd) -> Result<Self, InvalidField> {
        cfg.validate()?;
        Ok(Self {
            stance_a: or_zero(command(cfg, act)),
            flight,
        })
    }
}

impl ControlLaw for OpenTorque {
    fn on_event(&mut self, _event: &EventInput) {}

    fn current_a(&mut self, x: &ControlInput) -> f32 {
        match x.phase {
            Phase::Flight => self.flight.current_a(x.motor_angle_rad, x.motor_rate_rad_s),
            Phase::Stance => self.stance_a,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::close;
    use super::*;

    #[test]
    fn torque_to_current_and_saturation() -> Result<(), LawError> {
        let act = Actuator::default();
        assert!(close(command(&Config::default(), &act)?, 33.67, 1e-2));
        let half = Config { torque_nm: 0.5 };
        assert!(close(command(&half, &act)?, 16.835, 1e-2));
        let over = Config { torque_nm: 3.0 };
        assert_eq!(command(&over, &act)?, act.current_limit_a);
        let neg = Config { torque_nm: -3.0 };
        assert_eq!(command(&neg, &act)?, -act.current_limit_a);
        let bad = Config {
            torque_nm: f32::NAN,
        };
        assert_eq!(command(&bad, &act), Err(LawError::NonFiniteInput));
        Ok(())
    }
}
