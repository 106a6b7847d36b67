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

use super::{require, Actuator, InvalidField};
use crate::pd_design::PdGains;

crate::param::config! {
    /// Configuration of the flight PD.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct Config;
    params {
        4 FLIGHT_START_M start_position_m: f32 {
            "flight.start_position_m", "m", Real, [0.0, 1.0], 0.0, LIVE,
            "Nut position the flight PD returns to (0: the upper stop; at most the stroke)."
        }
    }
    nested {
        2 FLIGHT_KP at gains.kp {
            "flight.kp_a_per_rad", "A/rad", Real, [0.0, 1.0e4], 20.3152, LIVE,
            "Flight PD position gain on the motor angle (eq 4.4; default eq 4.13; hopper-sim's design preset runs Table 2.1's 8e4 N/m on the nut, 1.8953 A/rad, with the Chapter 2 laws)."
        }
        3 FLIGHT_KD at gains.kd {
            "flight.kd_a_s_per_rad", "A s/rad", Real, [0.0, 1.0e3], 0.6077, LIVE,
            "Flight PD rate gain (eq 4.4; default eq 4.13; the design preset's Chapter 2 laws: Table 2.1's 300 N s/m, 0.0071073 A s/rad)."
        }
    }
    plain {
        /// PD gains: `kp` in A/rad, `kd` in A s/rad (both finite, >= 0). Default eq 4.13:
        /// `kp = 20.3152`, `kd = 0.6077` (= `pd_design::pd_gains(110.0, 0.707, 0.1)`).
        // Both gains are the entries above, written after.
        pub gains: PdGains = PdGains { kp: 0.0, kd: 0.0 },
    }
}

/// The flight PD on a given actuator, its configuration checked once.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FlightPd {
    kp: f32,
    kd: f32,
    theta_ref_rad: f32,
    limit_a: f32,
}

impl FlightPd {
    /// Checks `c`: finite, non-negative gains and a start position on the
    /// stroke (a bad one is refused by name: with it the nut would not be
    /// driven home in flight).
    pub fn new(c: &Config, act: &Actuator) -> Result<Self, InvalidField> {
        crate::param::validate_fields(&mut { *c }, FIELDS)?;
        require(
            c.start_position_m <= act.stroke_m,
            entries::FLIGHT_START_M.name,
        )?;
        let r = act.screw_m_per_rad;
        require(r > 0.0 && r.is_finite(), "model.screw_lead_m")?;
        Ok(FlightPd {
            kp: c.gains.kp,
            kd: c.gains.kd,
            theta_ref_rad: c.start_position_m / r,
            limit_a: act.usable_limit_a(),
        })
    }

    /// Current command, A (positive compresses the spring), clamped to the
    /// current limit. `motor_angle_rad` is `theta = p / r`,
    /// `motor_rate_rad_s` its filtered rate; a non-finite one gives 0 A.
    #[inline]
    pub fn current_a(&self, motor_angle_rad: f32, motor_rate_rad_s: f32) -> f32 {
        if !(motor_angle_rad + motor_rate_rad_s).is_finite() {
            return 0.0;
        }
        let i = self.kp * (self.theta_ref_rad - motor_angle_rad) - self.kd * motor_rate_rad_s;
        if i.is_nan() {
            return 0.0;
        }
        crate::num::clamp(i, -self.limit_a, self.limit_a)
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
    fn sign_values_and_saturation() -> Result<(), InvalidField> {
        let act = Actuator::default();
        let pd = FlightPd::new(&Config::default(), &act)?;
        assert_eq!(pd.current_a(0.0, 0.0), 0.0);
        // 1 rad below the start (nut down): pull back, -20.3152 A.
        assert!(close(pd.current_a(1.0, 0.0), -20.3152, 1e-4));
        // At the target moving up (rate -10 rad/s): -kd * rate = +6.077 A brakes it.
        assert!(close(pd.current_a(0.0, -10.0), 6.077, 1e-4));
        // Large error saturates.
        assert_eq!(pd.current_a(60.0, 0.0), -act.current_limit_a);
        assert_eq!(pd.current_a(-60.0, 0.0), act.current_limit_a);
        assert_eq!(pd.current_a(f32::NAN, 0.0), 0.0);
        assert_eq!(pd.current_a(0.0, f32::INFINITY), 0.0);
        Ok(())
    }

    #[test]
    fn bad_gains_are_refused_by_name() {
        let act = Actuator::default();
        let with = |kp: f32, kd: f32, start: f32| Config {
            gains: PdGains { kp, kd },
            start_position_m: start,
        };
        let refused = |c: Config| FlightPd::new(&c, &act).err().map(|f| f.0);
        assert_eq!(
            refused(with(f32::NAN, 0.6, 0.0)),
            Some("flight.kp_a_per_rad")
        );
        assert_eq!(refused(with(-1.0, 0.6, 0.0)), Some("flight.kp_a_per_rad"));
        assert_eq!(
            refused(with(20.0, f32::INFINITY, 0.0)),
            Some("flight.kd_a_s_per_rad")
        );
        assert_eq!(
            refused(with(20.0, 0.6, 0.06)),
            Some("flight.start_position_m")
        );
        assert_eq!(refused(with(20.0, 0.6, 0.01)), None);
    }

    proptest::proptest! {
        #[test]
        fn the_current_is_finite_and_within_the_limit(
            theta in proptest::num::f32::ANY, rate in proptest::num::f32::ANY,
            kp in 0.0f32..200.0, kd in 0.0f32..10.0, start in 0.0f32..0.05,
        ) {
            let c = Config { gains: PdGains { kp, kd }, start_position_m: start };
            let act = Actuator::default();
            let pd = FlightPd::new(&c, &act)
                .map_err(|f| proptest::test_runner::TestCaseError::fail(f.0))?;
            let i = pd.current_a(theta, rate);
            proptest::prop_assert!(i.is_finite() && i.abs() <= act.current_limit_a);
        }
    }
}
