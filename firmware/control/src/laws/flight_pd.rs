//! Flight PD: back-drive the ball screw to its start position (thesis
//! section 4.3, eq 4.4 `C = k_d s + k_p`, gains from [`crate::pd_design`]):
//!
//! ```text
//! i = k_p (theta_ref - theta) + k_d (0 - theta dot),   theta_ref = p_start / r
//! ```
//!
//! `k_p` in A/rad, `k_d` in A s/rad. The output is saturated at the current
//! limit; a PD has no integrator, so saturation causes no windup. With the
//! eq 4.13 gains the loop saturates for any error above 1.7 rad (1.3 mm of
//! nut travel), so large returns are bang-bang with derivative braking; the
//! thesis (section 4.3) reports the resulting oscillation and lowers the
//! gains along eq 4.18 (see [`crate::pd_design::kp_over_kd_at_eta_opt`]).

use super::{check_finite, Actuator, LawError};
use crate::pd_design::PdGains;

/// Configuration of the flight PD.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// PD gains: `kp` in A/rad, `kd` in A s/rad (both >= 0). Default eq 4.13:
    /// `kp = 20.3152`, `kd = 0.6077` (= `pd_design::pd_gains(110.0, 0.707, 0.1)`).
    pub gains: PdGains,
    /// Start position of the nut, m (0 = upper stop). Default 0.
    pub start_position_m: f32,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            gains: PdGains {
                kp: 20.3152,
                kd: 0.6077,
            },
            start_position_m: 0.0,
        }
    }
}

/// Current command, A (positive compresses the spring), clamped.
/// `motor_angle_rad` is `theta = p / r`, `motor_rate_rad_s` its filtered rate.
pub fn command(
    c: &Config,
    act: &Actuator,
    motor_angle_rad: f32,
    motor_rate_rad_s: f32,
) -> Result<f32, LawError> {
    check_finite(&[
        c.gains.kp,
        c.gains.kd,
        c.start_position_m,
        motor_angle_rad,
        motor_rate_rad_s,
    ])?;
    let r = act.screw_m_per_rad;
    if !(r > 0.0 && r.is_finite()) {
        return Err(LawError::NonFiniteInput);
    }
    let theta_ref = c.start_position_m / r;
    let i = c.gains.kp * (theta_ref - motor_angle_rad) - c.gains.kd * motor_rate_rad_s;
    act.clamp_current(i)
}

/// [`command`] with its constants checked and worked out once, for the
/// control step: a dozen instructions instead of re-validating the gains and
/// dividing by `r` every period. Gives exactly [`command`]'s current for
/// finite inputs, and 0 A for non-finite ones (like `or_zero(command(..))`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Prepared {
    kp: f32,
    kd: f32,
    theta_ref_rad: f32,
    limit_a: f32,
}

impl Prepared {
    /// `None` when [`command`] would refuse every input (a non-finite gain or
    /// start position, or an unusable screw ratio).
    pub fn new(c: &Config, act: &Actuator) -> Option<Self> {
        check_finite(&[c.gains.kp, c.gains.kd, c.start_position_m]).ok()?;
        let r = act.screw_m_per_rad;
        if !(r > 0.0 && r.is_finite()) {
            return None;
        }
        let limit_a = act.usable_limit_a();
        Some(Prepared {
            kp: c.gains.kp,
            kd: c.gains.kd,
            theta_ref_rad: c.start_position_m / r,
            limit_a,
        })
    }

    /// Current command, A (see [`command`]).
    #[inline]
    pub fn current_a(&self, motor_angle_rad: f32, motor_rate_rad_s: f32) -> f32 {
        if !(motor_angle_rad + motor_rate_rad_s).is_finite() {
            return 0.0;
        }
        let i = self.kp * (self.theta_ref_rad - motor_angle_rad) - self.kd * motor_rate_rad_s;
        if i.is_nan() {
            return 0.0;
        }
        i.max(-self.limit_a).min(self.limit_a)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::close;
    use super::*;
    use crate::pd_design::{pd_gains, DesignError};

    #[test]
    fn default_gains_are_eq_4_13() -> Result<(), DesignError> {
        let g = pd_gains(110.0, 0.707, 0.1)?;
        let d = Config::default().gains;
        assert!(close(g.kp, d.kp, 1e-3) && close(g.kd, d.kd, 1e-3));
        Ok(())
    }

    #[test]
    fn sign_values_and_saturation() -> Result<(), LawError> {
        let (c, act) = (Config::default(), Actuator::default());
        assert_eq!(command(&c, &act, 0.0, 0.0)?, 0.0);
        // 1 rad below the start (nut down): pull back, -20.3152 A.
        assert!(close(command(&c, &act, 1.0, 0.0)?, -20.3152, 1e-4));
        // At the target moving up (rate -10 rad/s): -kd * rate = +6.077 A brakes it.
        assert!(close(command(&c, &act, 0.0, -10.0)?, 6.077, 1e-4));
        // Large error saturates at the limit.
        assert_eq!(command(&c, &act, 60.0, 0.0)?, -act.current_limit_a);
        assert_eq!(command(&c, &act, -60.0, 0.0)?, act.current_limit_a);
        assert_eq!(
            command(&c, &act, f32::NAN, 0.0),
            Err(LawError::NonFiniteInput)
        );
        Ok(())
    }

    proptest::proptest! {
        #[test]
        fn prepared_equals_command(
            theta in -100.0f32..100.0, rate in -1000.0f32..1000.0,
            kp in 0.0f32..200.0, kd in 0.0f32..10.0, start in 0.0f32..0.05,
        ) {
            let c = Config { gains: crate::pd_design::PdGains { kp, kd }, start_position_m: start };
            let act = Actuator::default();
            let fast = Prepared::new(&c, &act).map(|p| p.current_a(theta, rate));
            proptest::prop_assert_eq!(fast, Some(super::super::or_zero(command(&c, &act, theta, rate))));
        }
    }
}
