//! Closed-loop position step, thesis eqs 2.50-2.51:
//! `p(t) = k_p (E_D - E(t1)) u(t - t1)`, the step height latched at the bottom
//! of stance `t1` and tracked by the nut position PD [`NutPositionPd`].
//!
//! Units: `k_p` in m/J. Table 2.1's `k_p = 0.2` is read as **0.2 cm/J =
//! 2e-3 m/J** (a 5 J deficit gives a 10 mm step, Table 2.1's `l1`); in m/J it
//! would ask for 1 m of stroke per 5 J.
//!
//! Eq 2.51 as printed, `k_p = (E_D - E) / (K (z(t1) - z(t_td)))`, has units
//! of m (and a negative sign, `z(t1) < z(t_td)`), so with eq 2.50 the step
//! would be `(E_D - E)^2 / (K dz)`. The dimensionally consistent reading of its
//! derivation from eq 2.48 (`dp = dE / F_s`, with the spring force at the
//! bottom approximated by `K (z(t_td) - z(t1))`) is
//! `k_p = 1 / (K (z(t_td) - z(t1)))` in m/J, i.e. `p = (E_D - E) / F_s(t1)`.
//! That is what [`Gain::Normalised`] implements; with the design spring and
//! 50 mm compression it gives 1.8e-3 m/J, close to the 2e-3 m/J reading of
//! the thesis's 0.2.

use super::{
    check_finite, flight_pd::FlightPd, or_zero, track_bottom, Actuator, ControlInput, ControlLaw,
    EventInput, InvalidField, LawError, NutPositionPd, StanceInput,
};
use crate::estimator::{Phase, PhaseEvent};

/// How `k_p` of eq 2.50 is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Gain {
    /// A fixed `k_p`, m/J (>= 0). Thesis: 0.2 cm/J = 2e-3 m/J.
    Fixed {
        /// `k_p`, m/J.
        kp_m_per_j: f32,
    },
    /// Eq 2.51 read dimensionally: `k_p = 1 / (K (z(t_td) - z(t1)))`, m/J,
    /// with the leg compression at `t1`; compressions under
    /// `min_compression_m` (m, > 0) are raised to it to bound `k_p`.
    Normalised {
        /// Floor on the compression used, m. Default 0.005.
        min_compression_m: f32,
    },
}

impl crate::param::Choice for Gain {
    fn index(&self) -> usize {
        match self {
            Gain::Fixed { .. } => 0,
            Gain::Normalised { .. } => 1,
        }
    }

    /// The other gain starts from its entry's default; the same one keeps
    /// its value.
    fn choose(&mut self, index: usize) {
        if self.index() == index {
            return;
        }
        *self = if index == 0 {
            Gain::Fixed {
                kp_m_per_j: entries::STEP_CLOSED_KP_M_PER_J.default,
            }
        } else {
            Gain::Normalised {
                min_compression_m: entries::STEP_CLOSED_MIN_COMPRESSION_M.default,
            }
        };
    }
}

/// Names of [`entries::STEP_CLOSED_GAIN`]'s choices.
const STEP_CLOSED_GAINS: [&str; 2] = ["fixed", "normalised"];

crate::param::config! {
    /// Configuration of the closed-loop step.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct Config;
    nested {
        17 STEP_CLOSED_KP at pd.kp_n_per_m {
            "step_closed.kp_n_per_m", "N/m", Real, [0.0, 1.0e7], 8.0e4, LIVE,
            "Nut position loop gain of eq 2.50 (Table 2.1)."
        }
        18 STEP_CLOSED_KD at pd.kd_n_s_per_m {
            "step_closed.kd_n_s_per_m", "N s/m", Real, [0.0, 1.0e5], 300.0, LIVE,
            "Nut velocity loop gain of eq 2.50 (Table 2.1)."
        }
        19 STEP_CLOSED_FEEDFORWARD at pd.spring_feedforward {
            "step_closed.spring_feedforward", "-", Flag, [0.0, 1.0], 1.0, LIVE,
            "Add the measured spring force to the position loop."
        }
    }
    custom {
        14 STEP_CLOSED_GAIN |s| Some(Slot::Choice(&mut s.gain)), {
            "step_closed.gain", "-", Kind::Choice(&STEP_CLOSED_GAINS), [0.0, 1.0], 0.0, LIVE,
            "k_p of eq 2.50: fixed (step_closed.kp_m_per_j) or eq 2.51 normalised by the compression."
        }
        15 STEP_CLOSED_KP_M_PER_J |s| match &mut s.gain {
            Gain::Fixed { kp_m_per_j } => Some(R(kp_m_per_j)),
            Gain::Normalised { .. } => None,
        }, {
            "step_closed.kp_m_per_j", "m/J", Real, [0.0, 1.0], 2.0e-3, LIVE,
            "Fixed k_p of eq 2.50 (Table 2.1's 0.2 read as cm/J)."
        }
        16 STEP_CLOSED_MIN_COMPRESSION_M |s| match &mut s.gain {
            Gain::Normalised { min_compression_m } => Some(R(min_compression_m)),
            Gain::Fixed { .. } => None,
        }, {
            "step_closed.min_compression_m", "m", Real, [1.0e-4, 1.0], 0.005, LIVE,
            "Floor on the compression in eq 2.51's normalised gain."
        }
    }
    plain {
        /// Gain choice. Default `Fixed { kp_m_per_j: 2e-3 }` (Table 2.1's 0.2 in cm/J).
        pub gain: Gain = if entries::STEP_CLOSED_GAIN.default == 0.0 {
                Gain::Fixed {
                    kp_m_per_j: entries::STEP_CLOSED_KP_M_PER_J.default,
                }
            } else {
                Gain::Normalised {
                    min_compression_m: entries::STEP_CLOSED_MIN_COMPRESSION_M.default,
                }
            },
        /// Position loop tracking the reference (gains in N/m and N s/m on the nut).
        // Its gains and feed-forward are the entries above, written after.
        pub pd: NutPositionPd = NutPositionPd::default(),
    }
}

/// `k_p` in m/J for a leg compression at `t1` (m), per [`Gain`].
pub fn gain_m_per_j(c: &Config, act: &Actuator, compression_m: f32) -> Result<f32, LawError> {
    match c.gain {
        Gain::Fixed { kp_m_per_j } => {
            check_finite(&[kp_m_per_j])?;
            Ok(crate::num::max(kp_m_per_j, 0.0))
        }
        Gain::Normalised { min_compression_m } => {
            check_finite(&[min_compression_m, compression_m])?;
            let dz = crate::num::max(crate::num::max(compression_m, min_compression_m), 1e-4);
            let k = act.spring_stiffness_n_per_m;
            if !(k > 0.0 && k.is_finite()) {
                return Err(LawError::NonFiniteInput);
            }
            Ok(1.0 / (k * dz))
        }
    }
}

/// Step height of eq 2.50, m: `k_p (E_D - E)`, clamped to `0..=stroke`
/// (a surplus gives no step: the nut cannot go above its upper stop).
pub fn step_m(c: &Config, act: &Actuator, x: &StanceInput) -> Result<f32, LawError> {
    check_finite(&[x.energy_j, x.desired_energy_j])?;
    let kp = gain_m_per_j(c, act, x.leg_compression_m)?;
    let step = kp * (x.desired_energy_j - x.energy_j);
    check_finite(&[step])?;
    Ok(crate::num::clamp(
        step,
        0.0,
        crate::num::max(act.stroke_m, 0.0),
    ))
}

/// Per-stance state: the step latched at `t1`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Latch {
    step_m: Option<f32>,
}

impl Latch {
    /// The latched step, m, if `t1` has passed this stance.
    pub fn step_m(&self) -> Option<f32> {
        self.step_m
    }

    /// Current command, A (positive compresses the spring), clamped. The first
    /// call with `after_bottom` latches the step from that sample's energy and
    /// compression; reset the latch at touchdown (`Latch::default()`).
    pub fn command(
        &mut self,
        c: &Config,
        act: &Actuator,
        x: &StanceInput,
    ) -> Result<f32, LawError> {
        check_finite(&[x.nut_position_m, x.nut_velocity_mps])?;
        let p_ref = if x.after_bottom {
            match self.step_m {
                Some(s) => s,
                None => {
                    let s = step_m(c, act, x)?;
                    self.step_m = Some(s);
                    s
                }
            }
        } else {
            0.0
        };
        c.pd.current_a(
            act,
            p_ref,
            x.nut_position_m,
            x.nut_velocity_mps,
            x.spring_force_n,
        )
    }
}

impl Config {
    /// Checks every field, naming the first one out of range.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// The thesis's closed-loop step controller: eqs 2.50-2.51 in stance, the
/// flight PD in flight. State: whether this stance's bottom has passed, and
/// the step latched there.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepClosed {
    cfg: Config,
    act: Actuator,
    flight: FlightPd,
    after_bottom: bool,
    latch: Latch,
}

impl StepClosed {
    /// Checks `cfg`.
    pub fn new(cfg: &Config, act: &Actuator, flight: FlightPd) -> Result<Self, InvalidField> {
        cfg.validate()?;
        Ok(Self {
            cfg: *cfg,
            act: *act,
            flight,
            after_bottom: false,
            latch: Latch::default(),
        })
    }
}

impl ControlLaw for StepClosed {
    fn on_event(&mut self, event: &EventInput) {
        if event.event == PhaseEvent::Touchdown {
            // Forget the step latched in the previous stance.
            self.latch = Latch::default();
        }
        track_bottom(&mut self.after_bottom, event);
    }

    fn current_a(&mut self, x: &ControlInput) -> f32 {
        match x.phase {
            Phase::Flight => self.flight.current_a(x.motor_angle_rad, x.motor_rate_rad_s),
            Phase::Stance => or_zero(self.latch.command(
                &self.cfg,
                &self.act,
                &x.stance(self.after_bottom),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::{close, input};
    use super::*;

    #[test]
    fn eq_2_50_step_and_latch() -> Result<(), LawError> {
        let act = Actuator::default();
        let c = Config {
            pd: NutPositionPd {
                spring_feedforward: false,
                ..NutPositionPd::default()
            },
            ..Config::default()
        };
        let mut latch = Latch::default();
        let mut x = input();
        x.energy_j = 65.0; // 5 J short -> 2e-3 * 5 = 0.01 m
        assert_eq!(latch.command(&c, &act, &x)?, 0.0);
        assert_eq!(latch.step_m(), None);
        x.after_bottom = true;
        let i = latch.command(&c, &act, &x)?;
        assert!(close(latch.step_m().unwrap_or(0.0), 0.01, 1e-6));
        assert!(close(i, 23.82, 0.02));
        // Latched: later energy changes do not move the reference.
        x.energy_j = 69.0;
        assert!(close(latch.command(&c, &act, &x)?, i, 1e-4));
        // Surplus energy: no step.
        let mut fresh = Latch::default();
        x.energy_j = 80.0;
        assert_eq!(fresh.command(&c, &act, &x)?, 0.0);
        Ok(())
    }

    #[test]
    fn eq_2_51_normalised_gain() -> Result<(), LawError> {
        let act = Actuator::default();
        let c = Config {
            gain: Gain::Normalised {
                min_compression_m: 0.005,
            },
            ..Config::default()
        };
        // 1 / (11000 * 0.05) = 1.818e-3 m/J.
        assert!(close(gain_m_per_j(&c, &act, 0.05)?, 1.818e-3, 1e-6));
        // Floor at 5 mm: 1 / 55 = 0.01818 m/J.
        assert!(close(gain_m_per_j(&c, &act, 0.0)?, 0.018_18, 1e-5));
        // Big deficit saturates at the stroke.
        let mut x = input();
        x.energy_j = 0.0;
        assert_eq!(step_m(&c, &act, &x)?, 0.05);
        Ok(())
    }
}
