//! `{{name}}`: a constant motor torque in stance, the flight PD in flight.
//!
//! Written by `cargo xtask new-law {{name}}` from the project's template
//! (`xtask/templates/law.rs`); docs/laws.md is the guide. Change the two
//! places marked STANCE and FLIGHT (and the parameters) to make it your law:
//! everything else (its name on the command line and the link, its
//! parameters in the table and docs/parameters.md, its place among the
//! controllers) follows from this file and its line in `laws!`
//! (`firmware/control/src/laws/mod.rs`).
//!
//! What it receives every period is a [`ControlInput`] (the phase, the
//! filtered rates of eq 4.1, the energy of eq 2.44 and `E_D` of eq 2.43, the
//! apex target), and at each estimator event (touchdown, bottom, liftoff,
//! apex) an [`EventInput`] first. What it returns is a current in A,
//! positive pushing the nut down; the supervisor clamps it, and the period
//! runner commands 0 A whenever a fault is latched or the robot is
//! disarmed. It runs in the control interrupt: bounded work, no loops over
//! data, no allocation, no panics.

use super::{
    flight_pd::FlightPd, or_zero, Actuator, ControlInput, ControlLaw, EventInput, InvalidField,
};
use crate::estimator::Phase;
use crate::model::ModelParams;

crate::param::config! {
    /// The law's settings: each line one runtime parameter (its number on
    /// the link, name, unit, kind, range, default, whether it may change
    /// while the motor runs, and what it is).
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct Config;
    params {
        /// Positive compresses the spring.
        {{number}} {{MODULE}}_THRUST_NM thrust_nm: f32 {
            "{{module}}.thrust_nm", "N m", Real, [-10.0, 10.0], 1.0, LIVE,
            "Motor torque through the whole stance (the template's law: thesis section 2.1.3.4)."
        }
    }
}

impl Config {
    /// Checks every field against its range, naming the first one out of range.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// The law's state, built once from its configuration (outside the control
/// interrupt: a parameter change builds a new one).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Law {
    /// The stance current, A (`thrust / k_m`, clamped to the usable limit).
    stance_a: f32,
    /// The flight back-drive (eq 4.4 with eq 4.13's gains by default).
    flight: FlightPd,
}

impl Law {
    /// Checks `cfg` and precomputes what the period needs.
    pub fn new(
        cfg: &Config,
        act: &Actuator,
        _model: &ModelParams,
        flight: FlightPd,
    ) -> Result<Self, InvalidField> {
        cfg.validate()?;
        Ok(Self {
            stance_a: or_zero(act.torque_to_current(cfg.thrust_nm)),
            flight,
        })
    }
}

impl ControlLaw for Law {
    fn on_event(&mut self, _event: &EventInput) {}

    fn current_a(&mut self, x: &ControlInput) -> f32 {
        match x.phase {
            // FLIGHT: bring the nut back to its start for the next touchdown.
            Phase::Flight => self.flight.current_a(x.motor_angle_rad, x.motor_rate_rad_s),
            // STANCE: the thrust.
            Phase::Stance => self.stance_a,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thrust_in_stance_and_a_bad_value_refused() {
        let act = Actuator::default();
        let model = ModelParams::default();
        let flight = FlightPd::new(&super::super::flight_pd::Config::default(), &act)
            .unwrap_or_else(|e| panic!("{e:?}"));
        let law = Law::new(&Config::default(), &act, &model, flight.clone())
            .unwrap_or_else(|e| panic!("{e:?}"));
        // 1 N m over 0.0297 N m/A, at the usable limit.
        assert!((law.stance_a - 33.67).abs() < 0.01, "{}", law.stance_a);
        let bad = Config {
            thrust_nm: f32::NAN,
        };
        assert!(Law::new(&bad, &act, &model, flight).is_err());
    }
}
