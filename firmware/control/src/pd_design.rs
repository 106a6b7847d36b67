//! Flight-phase PD gain design for the motor position loop (thesis section 4.3).
//!
//! In flight the ball screw is driven back to its start position by a PD loop
//! on the motor angle. The plant input is the amplifier current `i` in A and
//! the output the motor angle `theta` in rad:
//!
//! ```text
//! theta_dd = (k_m / J_e) i          (eq 4.2)
//! P = A / s^2,  A = k_m / J_e       (eq 4.3), A in rad/(s^2 A)
//! C = k_d s + k_p                   (eq 4.4), k_p in A/rad, k_d in A s/rad
//! ```
//!
//! The closed loop is a standard second-order system with
//! `omega_n = sqrt(A k_p)` and `eta = sqrt(A / k_p) k_d / 2` (eq 4.7). The 5 %
//! settling time of its step-response envelope is
//! `t_s = -ln(0.05 sqrt(1 - eta^2)) / (eta omega_n)` (eq 4.10).
//!
//! Two forms of `omega_n(eta, t_s)` are provided:
//! - [`settling_omega_n_exact`]: eq 4.10 solved exactly. The thesis's worked
//!   gains (eq 4.13: `k_p = 20.3152`, `k_d = 0.6077` for `eta = 0.707`,
//!   `t_s = 0.1 s`, `A = 110`) come from this form, so [`pd_gains`] uses it.
//! - [`settling_omega_n_rounded`]: eq 4.11, which rounds `ln 20 = 2.9957` to 3.
//!   The thesis's optimum damping `eta_opt = 0.8893275` (eq 4.17) and ratio
//!   `k_p = 2.39124 k_d / t_s` (eq 4.18) come from this form, so [`eta_opt`],
//!   [`kp_over_kd`] and [`kp_over_kd_at_eta_opt`] use it.
//!
//! The two differ by about 0.1 % in `omega_n` (`ln 20` vs 3). With the exact
//! form the ratio at `eta_opt` would be `2.3885 / t_s` instead of `2.39124 / t_s`.

use core::f32::consts::{LN_10, LN_2};

/// `ln 20`, the exact constant of eq 4.10 (`-ln 0.05`).
const LN_20: f32 = LN_2 + LN_10;

/// Why a gain design was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DesignError {
    /// The damping ratio `eta` is not a finite number in `(0, 1)` (eq 4.8 needs `eta < 1`).
    DampingOutOfRange,
    /// The settling time `t_s` is not a finite number greater than zero.
    NonPositiveSettlingTime,
    /// The plant gain `A` is not a finite number greater than zero.
    NonPositivePlantGain,
    /// The natural frequency `omega_n` is not a finite number greater than zero.
    NonPositiveNaturalFrequency,
    /// The result overflowed (inputs at the edge of the `f32` range).
    NonFiniteResult,
}

/// PD gains of the controller `C = k_d s + k_p` (eq 4.4).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PdGains {
    /// Proportional gain `k_p`, amplifier current per motor-angle error, in A/rad.
    pub kp: f32,
    /// Derivative gain `k_d`, amplifier current per motor-speed error, in A s/rad.
    pub kd: f32,
}

/// Checks `eta` in `(0, 1)` and `t_s > 0`, both finite (NaN fails every comparison).
fn check_eta_and_settling_time(eta: f32, settling_time_s: f32) -> Result<(), DesignError> {
    if !(eta > 0.0 && eta < 1.0) {
        return Err(DesignError::DampingOutOfRange);
    }
    if !(settling_time_s > 0.0 && settling_time_s.is_finite()) {
        return Err(DesignError::NonPositiveSettlingTime);
    }
    Ok(())
}

/// `1 - eta^2` as `(1 - eta)(1 + eta)`: accurate near `eta = 1`, and `> 0` for `eta < 1`.
fn one_minus_square(eta: f32) -> f32 {
    (1.0 - eta) * (1.0 + eta)
}

/// Returns `value` if it is finite, otherwise [`DesignError::NonFiniteResult`].
fn finite(value: f32) -> Result<f32, DesignError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(DesignError::NonFiniteResult)
    }
}

/// Natural frequency in rad/s for damping `eta` and 5 % settling time `settling_time_s`:
/// eq 4.10 solved exactly, `omega_n = ln(20 / sqrt(1 - eta^2)) / (eta t_s)`.
pub fn settling_omega_n_exact(eta: f32, settling_time_s: f32) -> Result<f32, DesignError> {
    check_eta_and_settling_time(eta, settling_time_s)?;
    // ln(20 / sqrt(1 - eta^2)) = ln 20 - ln(1 - eta^2) / 2; 1 - eta^2 is in (0, 1].
    let log_term = LN_20 - 0.5 * libm::logf(one_minus_square(eta));
    finite(log_term / (eta * settling_time_s))
}

/// Natural frequency in rad/s from eq 4.11 (eq 4.10 with `ln 20` rounded to 3):
/// `omega_n = 3 / (eta t_s) - ln(1 - eta^2) / (2 eta t_s)`.
pub fn settling_omega_n_rounded(eta: f32, settling_time_s: f32) -> Result<f32, DesignError> {
    check_eta_and_settling_time(eta, settling_time_s)?;
    let log_term = 3.0 - 0.5 * libm::logf(one_minus_square(eta));
    finite(log_term / (eta * settling_time_s))
}

/// PD gains placing the closed-loop poles at `omega_n` (rad/s) and damping `eta`, eq 4.12:
/// `k_p = omega_n^2 / A`, `k_d = 2 eta sqrt(k_p) / sqrt(A)`.
///
/// `plant_gain_rad_per_s2_a` is `A = k_m / J_e` of eq 4.3. `k_d` is computed
/// as the algebraically identical `2 eta omega_n / A` (eq 4.7), avoiding a square root.
pub fn pd_gains_for_omega_n(
    plant_gain_rad_per_s2_a: f32,
    eta: f32,
    omega_n_rad_per_s: f32,
) -> Result<PdGains, DesignError> {
    let a = plant_gain_rad_per_s2_a;
    if !(a > 0.0 && a.is_finite()) {
        return Err(DesignError::NonPositivePlantGain);
    }
    if !(eta > 0.0 && eta < 1.0) {
        return Err(DesignError::DampingOutOfRange);
    }
    let omega = omega_n_rad_per_s;
    if !(omega > 0.0 && omega.is_finite()) {
        return Err(DesignError::NonPositiveNaturalFrequency);
    }
    Ok(PdGains {
        kp: finite(omega * omega / a)?,
        kd: finite(2.0 * eta * omega / a)?,
    })
}

/// PD gains for plant gain `A` (rad/(s^2 A)), damping `eta` and 5 % settling time:
/// eq 4.12 with `omega_n` from eq 4.10 solved exactly ([`settling_omega_n_exact`]).
///
/// This reproduces eq 4.13: `A = 110`, `eta = 0.707`, `t_s = 0.1 s` give
/// `k_p = 20.3152 A/rad`, `k_d = 0.6077 A s/rad`.
pub fn pd_gains(
    plant_gain_rad_per_s2_a: f32,
    eta: f32,
    settling_time_s: f32,
) -> Result<PdGains, DesignError> {
    let omega = settling_omega_n_exact(eta, settling_time_s)?;
    pd_gains_for_omega_n(plant_gain_rad_per_s2_a, eta, omega)
}

/// Gain ratio `k_p / k_d` in 1/s, eq 4.14:
/// `k_p / k_d = 3 / (2 eta^2 t_s) - ln(1 - eta^2) / (4 eta^2 t_s)`.
///
/// By eq 4.12 the ratio is `omega_n / (2 eta)`; eq 4.14 uses the rounded
/// `omega_n` of eq 4.11, and so does this function. It does not depend on `A`.
pub fn kp_over_kd(eta: f32, settling_time_s: f32) -> Result<f32, DesignError> {
    let omega = settling_omega_n_rounded(eta, settling_time_s)?;
    finite(omega / (2.0 * eta))
}

/// `eta^2 t_s d(omega_n)/d(eta)` of eq 4.16 (rounded form 4.11), as a function of `u = eta^2`:
/// `h = u / (1 - u) - 3 + ln(1 - u) / 2`.
///
/// `dh/d(eta) = eta / (1 - u) * (2 / (1 - u) - 1) > 0`, so `h` rises strictly
/// on `(0, 1)` and has one root there, the minimiser of `omega_n`.
fn scaled_omega_slope(eta: f32) -> f32 {
    let one_minus_u = one_minus_square(eta);
    (1.0 - one_minus_u) / one_minus_u - 3.0 + 0.5 * libm::logf(one_minus_u)
}

/// The damping ratio minimising `omega_n` (hence `k_p`) for a given settling time,
/// eqs 4.15-4.17: the root in `(0, 1)` of eq 4.16,
/// `-3 / eta^2 + 1 / (1 - eta^2) + ln(1 - eta^2) / (2 eta^2) = 0`.
///
/// Uses the rounded form 4.11, as the thesis does, and returns
/// `0.8893275` (eq 4.17). Found by bisection on the sign of eq 4.16 times
/// `eta^2 t_s` (a strictly increasing function): locating the root of the
/// slope is accurate to `f32` resolution, whereas a golden-section search on
/// the flat minimum of `omega_n` itself could only reach about `sqrt(f32::EPSILON)`.
/// `t_s` scales out of the condition, so this takes no argument.
pub fn eta_opt() -> f32 {
    // h(0.1) ~ -3.0 < 0 and h(0.999) ~ +493 > 0 (see the unit tests).
    let mut low = 0.1_f32;
    let mut high = 0.999_f32;
    for _ in 0..64 {
        let mid = 0.5 * (low + high);
        if mid <= low || mid >= high {
            break; // The interval is down to adjacent f32 values.
        }
        if scaled_omega_slope(mid) < 0.0 {
            low = mid;
        } else {
            high = mid;
        }
    }
    0.5 * (low + high)
}

/// Gain ratio `k_p / k_d` in 1/s at `eta = eta_opt`, eqs 4.14 and 4.18:
/// `k_p = 2.39124 k_d / t_s`.
pub fn kp_over_kd_at_eta_opt(settling_time_s: f32) -> Result<f32, DesignError> {
    kp_over_kd(eta_opt(), settling_time_s)
}

/// Motor-side PD gains for gains stated on the nut, as Table 2.1 states the
/// Chapter 2 flight law (`k_pf` in N/m, `k_vf` in N s/m): the nut sees the
/// force `eta k_m i / r` (eq 2.13's generalised force), and a nut error is
/// `r` times a motor-angle error, so `k_p = k_pf r^2 / (eta k_m)` and
/// `k_d = k_vf r^2 / (eta k_m)`. With the design machine (`r` = 7.958e-4
/// m/rad, `eta` 0.9, `k_m` 0.0297 N m/A) Table 2.1's 8e4 N/m and 300 N s/m
/// are 1.895 A/rad and 7.11e-3 A s/rad.
pub fn gains_from_nut(
    kp_n_per_m: f32,
    kd_ns_per_m: f32,
    model: &crate::model::ModelParams,
) -> Result<PdGains, DesignError> {
    let r = model.screw_m_per_rad();
    let per = r * r / (model.efficiency * model.torque_constant_nm_per_a);
    let g = PdGains {
        kp: kp_n_per_m * per,
        kd: kd_ns_per_m * per,
    };
    if g.kp.is_finite() && g.kd.is_finite() && g.kp >= 0.0 && g.kd >= 0.0 {
        Ok(g)
    } else {
        Err(DesignError::NonFiniteResult)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel_close(actual: f32, expected: f32, rel_tol: f32) -> bool {
        (actual - expected).abs() <= rel_tol * expected.abs()
    }

    #[test]
    fn table_2_1_nut_gains_on_the_motor() -> Result<(), DesignError> {
        use crate::model::{design, ModelParams};
        let g = gains_from_nut(
            design::FLIGHT_KPF_N_PER_M as f32,
            design::FLIGHT_KVF_NS_PER_M as f32,
            &ModelParams::default(),
        )?;
        assert!(rel_close(g.kp, 1.8953, 1e-4), "kp = {}", g.kp);
        assert!(rel_close(g.kd, 7.1073e-3, 1e-4), "kd = {}", g.kd);
        Ok(())
    }

    #[test]
    fn eq_4_13_worked_gains() -> Result<(), DesignError> {
        let g = pd_gains(110.0, 0.707, 0.1)?;
        assert!(rel_close(g.kp, 20.3152, 1e-3), "kp = {}", g.kp);
        assert!(rel_close(g.kd, 0.6077, 1e-3), "kd = {}", g.kd);
        // Tighter: f64 reference values of the same formula.
        assert!(rel_close(g.kp, 20.315_225, 1e-5), "kp = {}", g.kp);
        assert!(rel_close(g.kd, 0.607_664_5, 1e-5), "kd = {}", g.kd);
        Ok(())
    }

    #[test]
    fn eq_4_13_is_not_from_the_rounded_form() -> Result<(), DesignError> {
        // Erratum: the thesis says eq 4.13 uses eq 4.11, but the rounded form
        // gives kp = 20.3671, kd = 0.60844 (0.26 % and 0.12 % off).
        let omega = settling_omega_n_rounded(0.707, 0.1)?;
        let g = pd_gains_for_omega_n(110.0, 0.707, omega)?;
        assert!(rel_close(g.kp, 20.367_14, 1e-5), "kp = {}", g.kp);
        assert!(rel_close(g.kd, 0.608_440_5, 1e-5), "kd = {}", g.kd);
        assert!(!rel_close(g.kp, 20.3152, 1e-3));
        Ok(())
    }

    #[test]
    fn exact_omega_satisfies_eq_4_10() -> Result<(), DesignError> {
        for (eta, t_s) in [(0.3, 0.05), (0.707, 0.1), (0.95, 0.5)] {
            let omega = settling_omega_n_exact(eta, t_s)?;
            let t = -libm::logf(0.05 * libm::sqrtf(1.0 - eta * eta)) / (eta * omega);
            assert!(rel_close(t, t_s, 1e-5), "t = {t}");
        }
        Ok(())
    }

    #[test]
    fn gains_round_trip_through_eq_4_7() -> Result<(), DesignError> {
        let (a, eta, t_s) = (110.0, 0.6, 0.2);
        let g = pd_gains(a, eta, t_s)?;
        let omega = settling_omega_n_exact(eta, t_s)?;
        assert!(rel_close(libm::sqrtf(a * g.kp), omega, 1e-5));
        assert!(rel_close(0.5 * libm::sqrtf(a / g.kp) * g.kd, eta, 1e-5));
        Ok(())
    }

    #[test]
    fn eta_opt_matches_eq_4_17() {
        let eta = eta_opt();
        assert!((eta - 0.889_327_5).abs() <= 1e-5, "eta_opt = {eta}");
    }

    #[test]
    fn eta_opt_minimises_rounded_omega() -> Result<(), DesignError> {
        let eta = eta_opt();
        let at_opt = settling_omega_n_rounded(eta, 0.1)?;
        for delta in [-0.05, -0.01, 0.01, 0.05] {
            assert!(settling_omega_n_rounded(eta + delta, 0.1)? > at_opt);
        }
        Ok(())
    }

    #[test]
    fn bisection_bracket_has_a_sign_change() {
        assert!(scaled_omega_slope(0.1) < 0.0);
        assert!(scaled_omega_slope(0.999) > 0.0);
    }

    #[test]
    fn eq_4_18_ratio() -> Result<(), DesignError> {
        for t_s in [0.05, 0.1, 0.3] {
            let ratio = kp_over_kd_at_eta_opt(t_s)?;
            assert!(rel_close(ratio * t_s, 2.39124, 1e-4), "ratio = {ratio}");
        }
        Ok(())
    }

    #[test]
    fn eq_4_14_agrees_with_eq_4_12_on_the_rounded_form() -> Result<(), DesignError> {
        let (eta, t_s) = (0.8, 0.1);
        let omega = settling_omega_n_rounded(eta, t_s)?;
        let g = pd_gains_for_omega_n(110.0, eta, omega)?;
        assert!(rel_close(g.kp / g.kd, kp_over_kd(eta, t_s)?, 1e-5));
        Ok(())
    }

    #[test]
    fn rejects_bad_inputs() {
        for eta in [0.0, 1.0, -0.5, 1.5, f32::NAN] {
            assert_eq!(
                settling_omega_n_exact(eta, 0.1),
                Err(DesignError::DampingOutOfRange)
            );
        }
        for t_s in [0.0, -0.1, f32::NAN, f32::INFINITY] {
            assert_eq!(
                settling_omega_n_rounded(0.7, t_s),
                Err(DesignError::NonPositiveSettlingTime)
            );
        }
        for a in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(
                pd_gains(a, 0.7, 0.1),
                Err(DesignError::NonPositivePlantGain)
            );
        }
        assert_eq!(
            pd_gains_for_omega_n(110.0, 0.7, f32::NAN),
            Err(DesignError::NonPositiveNaturalFrequency)
        );
        assert_eq!(
            settling_omega_n_exact(0.7, 1e-45),
            Err(DesignError::NonFiniteResult)
        );
    }
}
