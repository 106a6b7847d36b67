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
}
