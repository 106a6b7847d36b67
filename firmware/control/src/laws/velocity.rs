//! Actuator velocity control, thesis eq 2.53: `pd_ref = -K_v (E - E_D)`,
//! tracked by a velocity loop to torque.
//!
//! Units: `K_v` in m/(s J). Table 2.1's `K_v = 30` cannot be m/(s J): a 5 J
//! deficit would ask for 150 m/s of nut speed, while the motor's no-load
//! speed (24 V / 0.0297 V s/rad = 808 rad/s) is only 0.64 m/s of nut speed,
//! so the law would be bang-bang at any error above 0.02 J. Read as
//! **30 mm/(s J) = 0.03 m/(s J)**, a 5 J deficit asks for 0.15 m/s, i.e.
//! about 15 mm of stroke in a 100 ms stance against ~500 N of spring force,
//! about 7 J: the right order to make up the losses. The default is that
//! reading.
//!
//! Velocity loop (this crate's choice; the thesis does not give one):
//! `F = F_s + k_vel (pd_ref - pd)` on the nut, with the measured spring force
//! `F_s` as feed-forward (the force the nut must hold to move at all), then
//! `tau = F r / eta`.

use super::{
    check_finite, flight_pd::FlightPd, or_zero, Actuator, ControlInput, ControlLaw, EventInput,
    InvalidField, LawError, StanceInput,
};
use crate::estimator::Phase;

crate::param::config! {
    /// Configuration of the velocity law.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct Config;
    params {
        20 VELOCITY_GAIN gain_mps_per_j: f32 {
            "velocity.gain_mps_per_j", "m/(s J)", Real, [0.0, 10.0], 0.03, LIVE,
            "K_v of eq 2.53 (Table 2.1's 30 read as mm/(s J))."
        }
        /// `k_vel`: force on the nut per m/s of velocity error. At the default a 0.1 m/s
        /// error gives 500 N (0.44 N m).
        21 VELOCITY_LOOP_GAIN loop_gain_n_s_per_m: f32 {
            "velocity.loop_gain_n_s_per_m", "N s/m", Real, [0.0, 1.0e6], 5000.0, LIVE,
            "Velocity loop gain from nut speed error to force."
        }
        22 VELOCITY_FEEDFORWARD spring_feedforward: bool {
            "velocity.spring_feedforward", "-", Flag, [0.0, 1.0], 1.0, LIVE,
            "Add the measured spring force to the velocity loop."
        }
    }
}

/// Velocity reference of eq 2.53, m/s.
pub fn velocity_reference_mps(
    c: &Config,
    energy_j: f32,
    desired_energy_j: f32,
) -> Result<f32, LawError> {
    check_finite(&[c.gain_mps_per_j, energy_j, desired_energy_j])?;
    let v = -c.gain_mps_per_j * (energy_j - desired_energy_j);
    check_finite(&[v])?;
    Ok(v)
}

/// Current command, A (positive compresses the spring), clamped.
pub fn command(c: &Config, act: &Actuator, x: &StanceInput) -> Result<f32, LawError> {
    check_finite(&[c.loop_gain_n_s_per_m, x.nut_velocity_mps, x.spring_force_n])?;
    let v_ref = velocity_reference_mps(c, x.energy_j, x.desired_energy_j)?;
    let ff = if c.spring_feedforward {
        crate::num::max(x.spring_force_n, 0.0)
    } else {
        0.0
    };
    let force_n = ff + c.loop_gain_n_s_per_m * (v_ref - x.nut_velocity_mps);
    act.nut_force_to_current(force_n)
}

impl Config {
    /// Checks every field, naming the first one out of range.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// The thesis's actuator-velocity controller: eq 2.53 in stance, the flight
/// PD in flight. No state of its own.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Velocity {
    cfg: Config,
    act: Actuator,
    flight: FlightPd,
}

impl Velocity {
    /// Checks `cfg`.
    pub fn new(cfg: &Config, act: &Actuator, flight: FlightPd) -> Result<Self, InvalidField> {
        cfg.validate()?;
        Ok(Self {
            cfg: *cfg,
            act: *act,
            flight,
        })
    }
}

impl ControlLaw for Velocity {
    fn on_event(&mut self, _event: &EventInput) {}

    fn current_a(&mut self, x: &ControlInput) -> f32 {
        match x.phase {
            Phase::Flight => self.flight.current_a(x.motor_angle_rad, x.motor_rate_rad_s),
            Phase::Stance => or_zero(command(&self.cfg, &self.act, &x.stance(false))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{close, input};
    use super::*;

    #[test]
    fn eq_2_53_values_sign_and_saturation() -> Result<(), LawError> {
        let act = Actuator::default();
        let c = Config {
            spring_feedforward: false,
            ..Config::default()
        };
        // 5 J short -> 0.15 m/s; at pd = 0: 750 N -> 0.6631 N m -> 22.33 A.
        assert!(close(velocity_reference_mps(&c, 65.0, 70.0)?, 0.15, 1e-6));
        let mut x = input();
        x.energy_j = 65.0;
        assert!(close(command(&c, &act, &x)?, 22.33, 0.02));
        // Already at the reference speed: zero (no feed-forward).
        x.nut_velocity_mps = 0.15;
        assert!(close(command(&c, &act, &x)?, 0.0, 1e-3));
        // Surplus: negative.
        x.energy_j = 75.0;
        x.nut_velocity_mps = 0.0;
        assert!(command(&c, &act, &x)? < 0.0);
        // With feed-forward the spring force is held: 385 N -> 11.46 A at zero error.
        let ff = Config::default();
        x.energy_j = 70.0;
        assert!(close(command(&ff, &act, &x)?, 11.46, 0.02));
        // Saturation.
        x.energy_j = 0.0;
        assert_eq!(command(&ff, &act, &x)?, act.current_limit_a);
        Ok(())
    }
}
