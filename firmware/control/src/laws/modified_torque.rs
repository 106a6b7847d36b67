//! Modified torque control (thesis section 4.4.3): the full motor torque in
//! stance, and already in flight on the way down from the moment the toe
//! falls below a fraction (the thesis's 40 %) of the last apex height, so the
//! motor is up to speed at touchdown. Outside that window the flight PD
//! ([`super::flight_pd`]) drives the nut back.

use super::{
    check_finite, flight_pd::FlightPd, or_zero, Actuator, ControlInput, ControlLaw, EventInput,
    InvalidField, LawError,
};
use crate::estimator::Phase;

crate::param::config! {
    /// Configuration of the modified torque law.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct Config;
    params {
        /// Positive compresses the spring. The default is full torque.
        8 MODIFIED_TORQUE_NM torque_nm: f32 {
            "modified_torque.torque_nm", "N m", Real, [-10.0, 10.0], 1.0, LIVE,
            "Modified-torque law's torque in stance and late descent (section 4.4.3)."
        }
        /// The fraction is of the toe height at the last apex.
        9 MODIFIED_TORQUE_APEX_FRACTION apex_fraction: f32 {
            "modified_torque.apex_fraction", "1", Real, [0.0, 1.0], 0.4, LIVE,
            "Fraction of the last apex below which the descent starts the torque (section 4.4.3: 40 %)."
        }
    }
}

/// Whether the law is active in flight: descending (`body_velocity_mps < 0`)
/// with the toe (m) below `apex_fraction * last_apex_m`. False without an
/// apex, with a non-positive apex, or with any non-finite input.
pub fn flight_active(
    c: &Config,
    toe_height_m: f32,
    body_velocity_mps: f32,
    last_apex_m: Option<f32>,
) -> bool {
    let Some(apex) = last_apex_m else {
        return false;
    };
    if check_finite(&[c.apex_fraction, toe_height_m, body_velocity_mps, apex]).is_err() {
        return false;
    }
    descent_window(c.apex_fraction, toe_height_m, body_velocity_mps, apex)
}

/// The pre-touchdown window both this law and [`super::shaped`] use:
/// descending, with the toe (m) below `fraction` of a positive last apex
/// `apex_m`. False for any NaN input (every comparison fails).
#[inline]
pub fn descent_window(
    fraction: f32,
    toe_height_m: f32,
    body_velocity_mps: f32,
    apex_m: f32,
) -> bool {
    apex_m > 0.0 && body_velocity_mps < 0.0 && toe_height_m < fraction * apex_m
}

/// Current command while active (stance, or flight when
/// [`flight_active`]), A: the constant-torque law's `tau / k_m`, clamped.
pub fn command(c: &Config, act: &Actuator) -> Result<f32, LawError> {
    super::open_torque::command(
        &super::open_torque::Config {
            torque_nm: c.torque_nm,
        },
        act,
    )
}

impl Config {
    /// Checks every field, naming the first one out of range.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// The thesis's modified-torque controller: full torque in stance and in the
/// late descent, the flight PD in the rest of the flight. No state of its
/// own (the last apex comes from the estimator).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ModifiedTorque {
    cfg: Config,
    active_a: f32,
    flight: FlightPd,
}

impl ModifiedTorque {
    /// Checks `cfg`.
    pub fn new(cfg: &Config, act: &Actuator, flight: FlightPd) -> Result<Self, InvalidField> {
        cfg.validate()?;
        Ok(Self {
            cfg: *cfg,
            active_a: or_zero(command(cfg, act)),
            flight,
        })
    }
}

impl ControlLaw for ModifiedTorque {
    fn on_event(&mut self, _event: &EventInput) {}

    fn current_a(&mut self, x: &ControlInput) -> f32 {
        match x.phase {
            Phase::Flight => {
                if flight_active(
                    &self.cfg,
                    x.toe_height_m,
                    x.body_velocity_mps,
                    x.last_apex_m,
                ) {
                    self.active_a
                } else {
                    self.flight.current_a(x.motor_angle_rad, x.motor_rate_rad_s)
                }
            }
            Phase::Stance => self.active_a,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::close;
    use super::*;

    #[test]
    fn window_and_command() -> Result<(), LawError> {
        let c = Config::default();
        let act = Actuator::default();
        assert!(close(command(&c, &act)?, 33.67, 1e-2));
        // Apex 0.1 m: threshold 0.04 m.
        assert!(flight_active(&c, 0.039, -1.0, Some(0.1)));
        assert!(!flight_active(&c, 0.041, -1.0, Some(0.1)));
        // Rising through the window: not active.
        assert!(!flight_active(&c, 0.02, 1.0, Some(0.1)));
        assert!(!flight_active(&c, 0.02, -1.0, None));
        assert!(!flight_active(&c, f32::NAN, -1.0, Some(0.1)));
        let over = Config {
            torque_nm: 2.0,
            ..c
        };
        assert_eq!(command(&over, &act)?, act.current_limit_a);
        Ok(())
    }
}
