//! Energy-feedback torque, thesis eq 2.52: `tau = -K_e (E - E_D)`.
//!
//! `K_e` in N m/J; Table 2.1's 0.2 means a 5 J deficit asks for the full
//! 1 N m. A surplus gives negative torque (the motor pulls the nut up and
//! removes energy), as in the thesis; set `allow_negative = false` to only add.
//!
//! [`Energy`] is the thesis's controller (this law in stance, the
//! flight PD in flight); [`Law`] is the stance law itself, which
//! [`super::energy_apex`] also runs.

use super::{
    flight_pd::FlightPd, require, Actuator, ControlInput, ControlLaw, EventInput, InvalidField,
};
use crate::estimator::Phase;

crate::param::config! {
    /// Configuration of the energy-feedback torque law.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct Config;
    params {
        5 ENERGY_GAIN gain_nm_per_j: f32 {
            "energy.gain_nm_per_j", "N m/J", Real, [0.0, 100.0], 0.2, LIVE,
            "K_e of eq 2.52 (Table 2.1: 0.2)."
        }
        6 ENERGY_ALLOW_NEGATIVE allow_negative: bool {
            "energy.allow_negative", "-", Flag, [0.0, 1.0], 1.0, LIVE,
            "Eq 2.52 may command negative torque on an energy surplus."
        }
    }
}

impl Config {
    /// Checks every field against its `energy.*` entry, naming the first
    /// one out of range (energy-apex checks its own copy against its
    /// `energy_apex.*` entries).
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// Eq 2.52 on a given actuator, its configuration checked once.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Law {
    gain_nm_per_j: f32,
    allow_negative: bool,
    torque_constant_nm_per_a: f32,
    limit_a: f32,
}

impl Law {
    /// The law of `c`, which the controller that runs it has checked
    /// against its own entries ([`Config::validate`], or energy-apex's
    /// `ApexLoop::validate`); refused for an unusable actuator.
    pub fn new(c: &Config, act: &Actuator) -> Result<Self, InvalidField> {
        let kt = act.torque_constant_nm_per_a;
        require(kt > 0.0 && kt.is_finite(), "model.torque_constant_nm_per_a")?;
        Ok(Law {
            gain_nm_per_j: c.gain_nm_per_j,
            allow_negative: c.allow_negative,
            torque_constant_nm_per_a: kt,
            limit_a: act.usable_limit_a(),
        })
    }

    /// Torque of eq 2.52, N m (unclamped; not finite for a non-finite energy,
    /// or 0 when only positive torque is allowed).
    #[inline]
    pub fn torque_nm(&self, energy_j: f32, desired_energy_j: f32) -> f32 {
        let tau = -self.gain_nm_per_j * (energy_j - desired_energy_j);
        if self.allow_negative {
            tau
        } else {
            crate::num::max(tau, 0.0)
        }
    }

    /// Current command, A (positive compresses the spring), clamped to the
    /// current limit; 0 A for a non-finite energy.
    #[inline]
    pub fn current_a(&self, energy_j: f32, desired_energy_j: f32) -> f32 {
        // The add-only limit drops a NaN, so a NaN or infinite energy gives
        // a torque of 0, NaN or +-inf here, and the test below turns any of
        // them into 0 A.
        let tau = self.torque_nm(energy_j, desired_energy_j);
        if !tau.is_finite() {
            return 0.0;
        }
        crate::num::clamp(
            tau / self.torque_constant_nm_per_a,
            -self.limit_a,
            self.limit_a,
        )
    }
}

/// The thesis's energy-feedback controller: eq 2.52 in stance, the flight PD
/// in flight. No state of its own.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Energy {
    law: Law,
    flight: FlightPd,
}

impl Energy {
    /// Checks `c`.
    pub fn new(c: &Config, act: &Actuator, flight: FlightPd) -> Result<Self, InvalidField> {
        c.validate()?;
        Ok(Self {
            law: Law::new(c, act)?,
            flight,
        })
    }
}

impl ControlLaw for Energy {
    fn on_event(&mut self, _event: &EventInput) {}

    #[inline]
    fn current_a(&mut self, x: &ControlInput) -> f32 {
        match x.phase {
            Phase::Flight => self.flight.current_a(x.motor_angle_rad, x.motor_rate_rad_s),
            Phase::Stance => self.law.current_a(x.energy_j, x.desired_energy_j),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::close;
    use super::*;

    #[test]
    fn eq_2_52_values_sign_and_saturation() -> Result<(), InvalidField> {
        let act = Actuator::default();
        let law = Law::new(&Config::default(), &act)?;
        // 2 J short -> 0.4 N m -> 13.47 A.
        assert!(close(law.torque_nm(68.0, 70.0), 0.4, 1e-5));
        assert!(close(law.current_a(68.0, 70.0), 13.468, 1e-2));
        // Surplus -> -0.2 N m.
        assert!(close(law.current_a(71.0, 70.0), -6.734, 1e-2));
        let add_only = Law::new(
            &Config {
                allow_negative: false,
                ..Config::default()
            },
            &act,
        )?;
        assert_eq!(add_only.current_a(71.0, 70.0), 0.0);
        // 20 J short -> 4 N m -> saturates.
        assert_eq!(law.current_a(50.0, 70.0), act.current_limit_a);
        assert_eq!(law.current_a(f32::INFINITY, 70.0), 0.0);
        assert_eq!(law.current_a(f32::NAN, 70.0), 0.0);
        Ok(())
    }

    #[test]
    fn a_bad_gain_is_refused_by_name() {
        let act = Actuator::default();
        for k in [f32::NAN, -0.1, f32::INFINITY, 101.0] {
            let c = Config {
                gain_nm_per_j: k,
                ..Config::default()
            };
            let flight = FlightPd::new(&super::super::flight_pd::Config::default(), &act)
                .unwrap_or_else(|e| panic!("{e:?}"));
            assert_eq!(
                Energy::new(&c, &act, flight).err(),
                Some(InvalidField("energy.gain_nm_per_j"))
            );
        }
    }

    proptest::proptest! {
        #[test]
        fn the_current_is_finite_and_within_the_limit(
            e in proptest::num::f32::ANY, ed in 0.0f32..200.0, k in 0.0f32..10.0,
            neg in proptest::bool::ANY,
        ) {
            let act = Actuator::default();
            let law = Law::new(&Config { gain_nm_per_j: k, allow_negative: neg }, &act)
                .map_err(|f| proptest::test_runner::TestCaseError::fail(f.0))?;
            let i = law.current_a(e, ed);
            proptest::prop_assert!(i.is_finite() && i.abs() <= act.current_limit_a);
            proptest::prop_assert!(neg || i >= 0.0);
        }
    }
}
