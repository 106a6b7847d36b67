//! Energy-feedback torque, thesis eq 2.52: `tau = -K_e (E - E_D)`.
//!
//! `K_e` in N m/J; Table 2.1's 0.2 means a 5 J deficit asks for the full
//! 1 N m. A surplus gives negative torque (the motor pulls the nut up and
//! removes energy), as in the thesis; set `allow_negative = false` to only add.

use super::{check_finite, Actuator, LawError, StanceInput};

/// Configuration of the energy-feedback torque law.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// `K_e`, N m/J (>= 0). Default 0.2 (Table 2.1).
    pub gain_nm_per_j: f32,
    /// Whether an energy surplus may command negative torque. Default true.
    pub allow_negative: bool,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            gain_nm_per_j: 0.2,
            allow_negative: true,
        }
    }
}

/// Torque of eq 2.52, N m (unclamped).
pub fn torque_nm(c: &Config, energy_j: f32, desired_energy_j: f32) -> Result<f32, LawError> {
    check_finite(&[c.gain_nm_per_j, energy_j, desired_energy_j])?;
    let tau = -c.gain_nm_per_j * (energy_j - desired_energy_j);
    check_finite(&[tau])?;
    Ok(if c.allow_negative { tau } else { tau.max(0.0) })
}

/// Current command, A (positive compresses the spring), clamped.
pub fn command(c: &Config, act: &Actuator, x: &StanceInput) -> Result<f32, LawError> {
    act.torque_to_current(torque_nm(c, x.energy_j, x.desired_energy_j)?)
}

/// [`command`] with its constants checked once, for the control step.
/// Gives exactly [`command`]'s current for finite energies, and 0 A for
/// non-finite ones (like `or_zero(command(..))`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Prepared {
    gain_nm_per_j: f32,
    allow_negative: bool,
    torque_constant_nm_per_a: f32,
    limit_a: f32,
}

impl Prepared {
    /// `None` when [`command`] would refuse every input (non-finite gain,
    /// unusable torque constant).
    pub fn new(c: &Config, act: &Actuator) -> Option<Self> {
        let kt = act.torque_constant_nm_per_a;
        if !(c.gain_nm_per_j.is_finite() && kt > 0.0 && kt.is_finite()) {
            return None;
        }
        let limit_a = act.usable_limit_a();
        Some(Prepared {
            gain_nm_per_j: c.gain_nm_per_j,
            allow_negative: c.allow_negative,
            torque_constant_nm_per_a: kt,
            limit_a,
        })
    }

    /// Current command, A (see [`command`]).
    #[inline]
    pub fn current_a(&self, energy_j: f32, desired_energy_j: f32) -> f32 {
        let tau = -self.gain_nm_per_j * (energy_j - desired_energy_j);
        if !tau.is_finite() {
            return 0.0;
        }
        let tau = if self.allow_negative {
            tau
        } else {
            tau.max(0.0)
        };
        (tau / self.torque_constant_nm_per_a)
            .max(-self.limit_a)
            .min(self.limit_a)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{close, input};
    use super::*;

    #[test]
    fn eq_2_52_values_sign_and_saturation() -> Result<(), LawError> {
        let (c, act) = (Config::default(), Actuator::default());
        let mut x = input();
        x.energy_j = 68.0; // 2 J short -> 0.4 N m -> 13.47 A
        assert!(close(torque_nm(&c, 68.0, 70.0)?, 0.4, 1e-5));
        assert!(close(command(&c, &act, &x)?, 13.468, 1e-2));
        x.energy_j = 71.0; // surplus -> -0.2 N m
        assert!(close(command(&c, &act, &x)?, -6.734, 1e-2));
        let add_only = Config {
            allow_negative: false,
            ..c
        };
        assert_eq!(command(&add_only, &act, &x)?, 0.0);
        x.energy_j = 50.0; // 20 J short -> 4 N m -> saturates
        assert_eq!(command(&c, &act, &x)?, act.current_limit_a);
        x.energy_j = f32::INFINITY;
        assert_eq!(command(&c, &act, &x), Err(LawError::NonFiniteInput));
        Ok(())
    }

    proptest::proptest! {
        #[test]
        fn prepared_equals_command(
            e in 0.0f32..200.0, ed in 0.0f32..200.0, k in 0.0f32..10.0, neg in proptest::bool::ANY,
        ) {
            let c = Config { gain_nm_per_j: k, allow_negative: neg };
            let act = Actuator::default();
            let mut x = input();
            x.energy_j = e;
            x.desired_energy_j = ed;
            let fast = Prepared::new(&c, &act).map(|p| p.current_a(e, ed));
            proptest::prop_assert_eq!(fast, Some(super::super::or_zero(command(&c, &act, &x))));
        }
    }
}
