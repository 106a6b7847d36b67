//! Open-loop position step, thesis eq 2.49: `p(t) = l1 u(t - t1)`, with `t1`
//! the bottom of stance (maximum spring compression). Before `t1` the
//! reference is the start position `p = 0`. The reference is tracked by the
//! nut position PD [`NutPositionPd`] (Table 2.1's `k_p,f`, `k_v,f`).

use super::{
    check_finite, flight_pd::FlightPd, or_zero, track_bottom, Actuator, ControlInput, ControlLaw,
    EventInput, InvalidField, LawError, NutPositionPd, StanceInput,
};
use crate::estimator::Phase;

crate::param::config! {
    /// Configuration of the open-loop step.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct Config;
    params {
        10 STEP_OPEN_M step_m: f32 {
            "step_open.step_m", "m", Real, [0.0, 1.0], 0.01, LIVE,
            "Step height l1 of eq 2.49 (Table 2.1: 10 mm; clamped to the stroke)."
        }
    }
    nested {
        11 STEP_OPEN_KP at pd.kp_n_per_m {
            "step_open.kp_n_per_m", "N/m", Real, [0.0, 1.0e7], 8.0e4, LIVE,
            "Nut position loop gain k_p,f of eq 2.49 (Table 2.1)."
        }
        12 STEP_OPEN_KD at pd.kd_n_s_per_m {
            "step_open.kd_n_s_per_m", "N s/m", Real, [0.0, 1.0e5], 300.0, LIVE,
            "Nut velocity loop gain k_v,f of eq 2.49 (Table 2.1)."
        }
        13 STEP_OPEN_FEEDFORWARD at pd.spring_feedforward {
            "step_open.spring_feedforward", "-", Flag, [0.0, 1.0], 1.0, LIVE,
            "Add the measured spring force to the position loop."
        }
    }
    plain {
        /// Position loop tracking the reference (gains in N/m and N s/m on the nut).
        // Its gains and feed-forward are the entries above, written after.
        pub pd: NutPositionPd = NutPositionPd::default(),
    }
}

/// Position reference of eq 2.49, m: `l1` after the bottom, 0 before; clamped to `0..=stroke`.
pub fn reference_m(c: &Config, act: &Actuator, after_bottom: bool) -> f32 {
    if after_bottom {
        crate::num::clamp(c.step_m, 0.0, crate::num::max(act.stroke_m, 0.0))
    } else {
        0.0
    }
}

/// Current command, A (positive compresses the spring), clamped.
pub fn command(c: &Config, act: &Actuator, x: &StanceInput) -> Result<f32, LawError> {
    check_finite(&[c.step_m, x.nut_position_m, x.nut_velocity_mps])?;
    let p_ref = reference_m(c, act, x.after_bottom);
    c.pd.current_a(
        act,
        p_ref,
        x.nut_position_m,
        x.nut_velocity_mps,
        x.spring_force_n,
    )
}

impl Config {
    /// Checks every field, naming the first one out of range.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// The thesis's open-loop step controller: eq 2.49 in stance, the flight PD
/// in flight. State: whether this stance's bottom has passed.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepOpen {
    cfg: Config,
    act: Actuator,
    flight: FlightPd,
    after_bottom: bool,
}

impl StepOpen {
    /// Checks `cfg`.
    pub fn new(cfg: &Config, act: &Actuator, flight: FlightPd) -> Result<Self, InvalidField> {
        cfg.validate()?;
        Ok(Self {
            cfg: *cfg,
            act: *act,
            flight,
            after_bottom: false,
        })
    }
}

impl ControlLaw for StepOpen {
    fn on_event(&mut self, event: &EventInput) {
        track_bottom(&mut self.after_bottom, event);
    }

    fn current_a(&mut self, x: &ControlInput) -> f32 {
        match x.phase {
            Phase::Flight => self.flight.current_a(x.motor_angle_rad, x.motor_rate_rad_s),
            Phase::Stance => or_zero(command(&self.cfg, &self.act, &x.stance(self.after_bottom))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{close, input};
    use super::*;

    #[test]
    fn step_after_bottom_only() -> Result<(), LawError> {
        let act = Actuator::default();
        let c = Config {
            pd: NutPositionPd {
                spring_feedforward: false,
                ..NutPositionPd::default()
            },
            ..Config::default()
        };
        let mut x = input();
        assert_eq!(command(&c, &act, &x)?, 0.0);
        x.after_bottom = true;
        // Error 0.01 m * 8e4 N/m = 800 N -> tau = 800 r / 0.9 = 0.7074 N m -> 23.82 A.
        assert!(close(command(&c, &act, &x)?, 23.82, 0.02));
        // Nut past the reference: negative (pull back).
        x.nut_position_m = 0.02;
        assert!(command(&c, &act, &x)? < 0.0);
        // Large error saturates.
        let big = Config { step_m: 0.05, ..c };
        x.nut_position_m = 0.0;
        assert_eq!(command(&big, &act, &x)?, act.current_limit_a);
        // Reference clamped to the stroke.
        let huge = Config { step_m: 1.0, ..c };
        assert_eq!(reference_m(&huge, &act, true), 0.05);
        // Spring feed-forward (default): at the reference the motor holds the
        // measured 385 N: tau = 385 r / 0.9 = 0.3404 N m -> 11.46 A.
        x.nut_position_m = 0.01;
        assert!(close(command(&Config::default(), &act, &x)?, 11.46, 0.02));
        Ok(())
    }
}
