//! Energy estimate from measurements (thesis eqs 2.44-2.45).
//!
//! Stance (eq 2.44, with this crate's coordinates, ground reference):
//!
//! ```text
//! E = 0.5 J thd^2 + 0.5 M zd^2 + 0.5 m_s (zd - r thd)^2 + M g z + m_s g (z - p)
//!     + 0.5 F^2 / k                                        (spring, eq 2.45)
//! ```
//!
//! Flight adds the unsprung mass riding with the body:
//! `0.5 m_u zd^2 + m_u g (z - l0)`. This is the simulator's energy
//! (`plant/src/plant/dynamics.rs`) with the spring term taken from the load cell.
//! The load-cell force is clamped at `>= 0` (a spring cannot pull), so a
//! noisy negative reading never adds energy.

use crate::estimator::Phase;
use crate::model::ModelParams;

/// Why an energy estimate was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EnergyError {
    /// A measurement is NaN or infinite.
    NonFiniteInput,
    /// The spring stiffness is not positive (eq 2.45 divides by it).
    NonPositiveStiffness,
    /// The result overflowed.
    NonFiniteResult,
}

/// Measurements for one energy estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EnergyInput {
    /// Body height coordinate `z`, m (`l0` at touchdown).
    pub body_height_m: f32,
    /// Body velocity `zd`, m/s, up positive.
    pub body_velocity_mps: f32,
    /// Motor angular rate `theta dot`, rad/s (positive drives the nut down).
    pub motor_rate_rad_s: f32,
    /// Nut displacement `p`, m, down positive.
    pub nut_position_m: f32,
    /// Spring force from the load cell, N (compression positive; clamped at 0).
    pub spring_force_n: f32,
    /// Contact phase: flight adds the unsprung-mass terms.
    pub phase: Phase,
}

impl EnergyInput {
    /// Whether every field is finite: one sum, one test (NaN and infinities
    /// propagate through the sum; finite values whose sum overflows count as
    /// non-finite, which is the safe side).
    #[inline(always)]
    fn is_finite(&self) -> bool {
        (self.body_height_m
            + self.body_velocity_mps
            + self.motor_rate_rad_s
            + self.nut_position_m
            + self.spring_force_n)
            .is_finite()
    }
}

/// Spring energy from the measured force, eq 2.45: `0.5 F^2 / k`, J, with `F`
/// clamped at `>= 0` N and `k` in N/m.
pub fn spring_energy_j(spring_force_n: f32, stiffness_n_per_m: f32) -> Result<f32, EnergyError> {
    if !spring_force_n.is_finite() {
        return Err(EnergyError::NonFiniteInput);
    }
    if !(stiffness_n_per_m > 0.0 && stiffness_n_per_m.is_finite()) {
        return Err(EnergyError::NonPositiveStiffness);
    }
    let f = crate::num::max(spring_force_n, 0.0);
    finite(0.5 * f * f / stiffness_n_per_m)
}

fn finite(v: f32) -> Result<f32, EnergyError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(EnergyError::NonFiniteResult)
    }
}

/// Total mechanical energy, J: eq 2.44 with the spring term of eq 2.45, plus
/// the unsprung-mass terms in flight (see the module doc). Matches the
/// simulator's energy exactly when the load cell reads `k * compression`.
///
/// Validates the model on every call; the control step uses an
/// [`EnergyModel`] built once instead.
pub fn total_energy_j(m: &ModelParams, x: &EnergyInput) -> Result<f32, EnergyError> {
    EnergyModel::new(m)?.total_j(x)
}

/// The model's constants of eqs 2.44-2.45 worked out once (products of
/// masses, `g`, `1/k`), so a period's energy estimate is a dozen
/// multiply-adds.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EnergyModel {
    r: f32,
    half_j: f32,
    half_m_body: f32,
    half_m_nut: f32,
    m_body_g: f32,
    m_nut_g: f32,
    half_inv_k: f32,
    half_m_unsprung: f32,
    m_unsprung_g: f32,
    leg_length_m: f32,
}

impl EnergyModel {
    /// The constants of `m`; the spring stiffness must be positive and finite.
    pub fn new(m: &ModelParams) -> Result<Self, EnergyError> {
        let k = m.spring_stiffness_n_per_m;
        if !(k > 0.0 && k.is_finite()) {
            return Err(EnergyError::NonPositiveStiffness);
        }
        let g = m.gravity_mps2;
        Ok(EnergyModel {
            r: m.screw_m_per_rad(),
            half_j: 0.5 * m.rotor_inertia_kg_m2,
            half_m_body: 0.5 * m.body_mass_kg,
            half_m_nut: 0.5 * m.nut_mass_kg,
            m_body_g: m.body_mass_kg * g,
            m_nut_g: m.nut_mass_kg * g,
            half_inv_k: 0.5 / k,
            half_m_unsprung: 0.5 * m.unsprung_mass_kg,
            m_unsprung_g: m.unsprung_mass_kg * g,
            leg_length_m: m.leg_length_m,
        })
    }

    /// Total energy of [`total_energy_j`], J. A non-finite input is refused
    /// (one sum and one test), and so is a result that overflows.
    #[inline]
    pub fn total_j(&self, x: &EnergyInput) -> Result<f32, EnergyError> {
        if !x.is_finite() {
            return Err(EnergyError::NonFiniteInput);
        }
        let thd = x.motor_rate_rad_s;
        let zd = x.body_velocity_mps;
        let z = x.body_height_m;
        let nut_abs_velocity = zd - self.r * thd; // nut velocity over ground, m/s
        let f = crate::num::max(x.spring_force_n, 0.0);
        let e = self.half_j * thd * thd
            + self.half_m_body * zd * zd
            + self.half_m_nut * nut_abs_velocity * nut_abs_velocity
            + self.m_body_g * z
            + self.m_nut_g * (z - x.nut_position_m)
            + self.half_inv_k * f * f
            + self.unsprung_j(x);
        finite(e)
    }

    /// Body energy of [`body_energy_j`], J.
    #[inline]
    pub fn body_j(&self, x: &EnergyInput) -> Result<f32, EnergyError> {
        if !x.is_finite() {
            return Err(EnergyError::NonFiniteInput);
        }
        let zd = x.body_velocity_mps;
        let f = crate::num::max(x.spring_force_n, 0.0);
        let e = (self.half_m_body + self.half_m_nut) * zd * zd
            + (self.m_body_g + self.m_nut_g) * x.body_height_m
            + self.half_inv_k * f * f
            + self.unsprung_j(x);
        finite(e)
    }

    /// Unsprung-mass terms in flight: `0.5 m_u zd^2 + m_u g (z - l0)`, J.
    #[inline(always)]
    fn unsprung_j(&self, x: &EnergyInput) -> f32 {
        match x.phase {
            Phase::Flight => {
                self.half_m_unsprung * x.body_velocity_mps * x.body_velocity_mps
                    + self.m_unsprung_g * (x.body_height_m - self.leg_length_m)
            }
            Phase::Stance => 0.0,
        }
    }
}

/// Energy of the vertical (body) motion only, J: the body and nut treated as
/// one rigid mass `M + m_s` moving with `zd` at height `z`, plus the measured
/// spring energy (eq 2.45) and, in flight, the unsprung-mass terms:
///
/// ```text
/// E_body = 0.5 (M + m_s) zd^2 + (M + m_s) g z + 0.5 F^2 / k  (+ flight m_u terms)
/// ```
///
/// Left out: the rotor kinetic energy `0.5 J thd^2` and the nut's motion
/// relative to the body (`p`, `pd`). The rotor's kinetic energy (up to
/// `J/r^2 ~ 426 kg` reflected) mostly does not reach the body, so an
/// apex-regulating law should compare this quantity, not the total, with
/// [`ModelParams::desired_energy_j`]; at a flight apex with the nut at rest
/// on `p = 0` the two agree exactly. The spring term is kept whole, although
/// energy stored by the actuator and still in the spring at liftoff is lost
/// (the leg's extension stop takes it); that is the caller's margin.
pub fn body_energy_j(m: &ModelParams, x: &EnergyInput) -> Result<f32, EnergyError> {
    EnergyModel::new(m)?.body_j(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The simulator's energy (hopper-plant `Plant::energy`), written out in f64:
    /// `0.5 alpha pd^2 + 0.5 m_zz zd^2 - m_s zd pd + M g z + m_s g (z - p)
    ///  + 0.5 k x^2 (+ m_u g (z - l0) in flight)`.
    fn plant_energy(m: &ModelParams, z: f64, zd: f64, p: f64, pd: f64, stance: bool) -> f64 {
        let r = f64::from(m.screw_m_per_rad());
        let (mb, ms, mu) = (
            f64::from(m.body_mass_kg),
            f64::from(m.nut_mass_kg),
            f64::from(m.unsprung_mass_kg),
        );
        let alpha = f64::from(m.rotor_inertia_kg_m2) / (r * r) + ms;
        let m_zz = if stance { mb + ms } else { mb + ms + mu };
        let (g, k, l0, d0) = (9.81, 11_000.0, 0.61, 0.005);
        let x = if stance { d0 + l0 - z + p } else { d0 + p };
        let mut e = 0.5 * alpha * pd * pd + 0.5 * m_zz * zd * zd - ms * zd * pd
            + mb * g * z
            + ms * g * (z - p)
            + 0.5 * k * x * x;
        if !stance {
            e += mu * g * (z - l0);
        }
        e
    }

    #[test]
    fn matches_plant_formula() -> Result<(), EnergyError> {
        let m = ModelParams::default();
        let r = f64::from(m.screw_m_per_rad());
        let states = [
            (0.55, -1.2, 0.01, 0.3, true),
            (0.60, 0.8, 0.03, -0.2, true),
            (0.75, 0.0, 0.0, 0.0, false),
            (0.70, -1.5, 0.02, -0.4, false),
        ];
        for (z, zd, p, pd, stance) in states {
            let x_m = if stance {
                0.005 + 0.61 - z + p
            } else {
                0.005 + p
            };
            let input = EnergyInput {
                body_height_m: z as f32,
                body_velocity_mps: zd as f32,
                motor_rate_rad_s: (pd / r) as f32,
                nut_position_m: p as f32,
                spring_force_n: (11_000.0 * x_m) as f32,
                phase: if stance { Phase::Stance } else { Phase::Flight },
            };
            let expected = plant_energy(&m, z, zd, p, pd, stance);
            let got = f64::from(total_energy_j(&m, &input)?);
            assert!((got - expected).abs() < 2e-3, "{got} vs {expected}");
        }
        Ok(())
    }

    #[test]
    fn eq_2_45_equals_half_k_x_squared() -> Result<(), EnergyError> {
        let k = 11_000.0_f32;
        for x in [0.0_f32, 0.005, 0.02, 0.06] {
            let e = spring_energy_j(k * x, k)?;
            assert!((e - 0.5 * k * x * x).abs() < 1e-4);
        }
        // Negative (noisy) force is clamped: no energy.
        assert_eq!(spring_energy_j(-20.0, k)?, 0.0);
        assert_eq!(
            spring_energy_j(1.0, 0.0),
            Err(EnergyError::NonPositiveStiffness)
        );
        Ok(())
    }

    #[test]
    fn body_energy_equals_desired_energy_at_apex() -> Result<(), EnergyError> {
        let m = ModelParams::default();
        let h = 0.15;
        let input = EnergyInput {
            body_height_m: 0.61 + h,
            body_velocity_mps: 0.0,
            motor_rate_rad_s: 0.0,
            nut_position_m: 0.0,
            spring_force_n: m.spring_stiffness_n_per_m * m.preload_m,
            phase: Phase::Flight,
        };
        let ed = m
            .desired_energy_j(h)
            .map_err(|_| EnergyError::NonFiniteInput)?;
        assert!((body_energy_j(&m, &input)? - ed).abs() < 1e-3);
        assert!((total_energy_j(&m, &input)? - ed).abs() < 1e-3);
        let mut bad = input;
        bad.body_velocity_mps = f32::NAN;
        assert_eq!(total_energy_j(&m, &bad), Err(EnergyError::NonFiniteInput));
        Ok(())
    }
}
