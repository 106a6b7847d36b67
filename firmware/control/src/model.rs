//! Physical parameters of the vertical hopper and the desired-energy map
//! (thesis section 2.1, Table 2.1; coordinates of `MODEL.md`).
//!
//! Coordinates: `z` is the body height coordinate, `z = l0` at touchdown, so
//! the toe is `z - l0` above the ground in flight; `p` is the ball-nut
//! displacement, positive down (it compresses the spring), `p = r theta` with
//! `r = lead / (2 pi)` in m/rad. Spring compression is `delta0 + l0 - z + p`
//! in stance and `delta0 + p` in flight (`delta0` the preload).

use core::f32::consts::PI;

pub use hopper_model::{FieldRange, ModelField};

/// Why a [`ModelParams`] or a model computation was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelError {
    /// The named field is non-finite or outside its documented range.
    OutOfRange(ModelField),
    /// An argument (for example a desired apex height) is non-finite or negative.
    BadArgument,
}

/// Physical parameters of the hopper, f32 SI, each in the range
/// [`ModelField::range`] gives (the simulator's plant checks the same ranges).
/// `Default` is the thesis's
/// "design" set (Table 2.1) plus the motor of section 3.1, with no preload
/// (the thesis gives none; see [`design::SPRING_PRELOAD_M`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ModelParams {
    /// Sprung (body) mass `M`, kg. Default 9.0.
    pub body_mass_kg: f32,
    /// Unsprung (lower leg + toe) mass `m_u`, kg. Default 0.6.
    pub unsprung_mass_kg: f32,
    /// Sliding (ball nut) mass `m_s`, kg. Default 0.25.
    pub nut_mass_kg: f32,
    /// Rotor + screw moment of inertia `J`, kg m^2. Default 2.7e-4.
    pub rotor_inertia_kg_m2: f32,
    /// Ball-screw lead, m per revolution. Default 0.005.
    pub screw_lead_m: f32,
    /// Leg spring stiffness `k`, N/m. Default 11 000.
    pub spring_stiffness_n_per_m: f32,
    /// Leg free length `l0`, m (body coordinate at touchdown). Default 0.61.
    pub leg_length_m: f32,
    /// Spring preload `delta0`, m. Default 0 (the thesis's design).
    pub preload_m: f32,
    /// Nut stroke, m (`p` in `0..stroke`). Default 0.05.
    pub stroke_m: f32,
    /// Motor + ball-screw efficiency `eta`, dimensionless. Default 0.9.
    pub efficiency: f32,
    /// Gravitational acceleration `g`, m/s^2. Default 9.81.
    pub gravity_mps2: f32,
    /// Motor torque limit, N m. Default 1.0 (Table 2.1).
    pub torque_limit_nm: f32,
    /// Motor torque constant `k_m`, N m/A. Default 0.0297.
    pub torque_constant_nm_per_a: f32,
    /// Amplifier current limit, A. Default 33.670 (= 1.0 N m / 0.0297 N m/A).
    pub current_limit_a: f32,
}

pub use hopper_model::design;

impl Default for ModelParams {
    /// [`design`], in `f32`.
    fn default() -> Self {
        Self {
            body_mass_kg: design::BODY_MASS_KG as f32,
            unsprung_mass_kg: design::UNSPRUNG_MASS_KG as f32,
            nut_mass_kg: design::NUT_MASS_KG as f32,
            rotor_inertia_kg_m2: design::ROTOR_INERTIA_KG_M2 as f32,
            screw_lead_m: design::SCREW_LEAD_M as f32,
            spring_stiffness_n_per_m: design::SPRING_STIFFNESS_N_PER_M as f32,
            leg_length_m: design::LEG_LENGTH_M as f32,
            preload_m: design::SPRING_PRELOAD_M as f32,
            stroke_m: design::STROKE_M as f32,
            efficiency: design::EFFICIENCY as f32,
            gravity_mps2: design::GRAVITY_MPS2 as f32,
            torque_limit_nm: design::TORQUE_LIMIT_NM as f32,
            torque_constant_nm_per_a: design::TORQUE_CONSTANT_NM_PER_A as f32,
            current_limit_a: design::CURRENT_LIMIT_A as f32,
        }
    }
}

/// `Ok` if `v` is within `field`'s range, else the field error.
fn check(v: f32, field: ModelField) -> Result<(), ModelError> {
    let r = field.range();
    let (lo, hi) = (r.min as f32, r.max as f32);
    let low_ok = if r.min_exclusive { v > lo } else { v >= lo };
    // NaN fails every comparison, so it is rejected here too.
    if low_ok && v <= hi && v.is_finite() {
        Ok(())
    } else {
        Err(ModelError::OutOfRange(field))
    }
}

impl ModelParams {
    /// Checks every field against its range ([`ModelField::range`]); the
    /// error names the first bad field.
    pub fn validate(&self) -> Result<(), ModelError> {
        use ModelField as F;
        for (v, field) in [
            (self.body_mass_kg, F::BodyMass),
            (self.unsprung_mass_kg, F::UnsprungMass),
            (self.nut_mass_kg, F::NutMass),
            (self.rotor_inertia_kg_m2, F::RotorInertia),
            (self.screw_lead_m, F::ScrewLead),
            (self.spring_stiffness_n_per_m, F::SpringStiffness),
            (self.leg_length_m, F::LegLength),
            (self.preload_m, F::Preload),
            (self.stroke_m, F::Stroke),
            (self.efficiency, F::Efficiency),
            (self.gravity_mps2, F::Gravity),
            (self.torque_limit_nm, F::TorqueLimit),
            (self.torque_constant_nm_per_a, F::TorqueConstant),
            (self.current_limit_a, F::CurrentLimit),
        ] {
            check(v, field)?;
        }
        Ok(())
    }

    /// Screw transmission ratio `r = lead / (2 pi)`, m/rad (`p = r theta`). Design: 7.96e-4.
    #[inline(always)]
    pub fn screw_m_per_rad(&self) -> f32 {
        self.screw_lead_m / (2.0 * PI)
    }

    /// Total mass `m_t = M + m_s + m_u`, kg.
    pub fn total_mass_kg(&self) -> f32 {
        self.body_mass_kg + self.nut_mass_kg + self.unsprung_mass_kg
    }

    /// Reflected rotor inertia `J / r^2`, kg (about 426 kg for the design set);
    /// 0 if `r` is not positive.
    pub fn reflected_inertia_kg(&self) -> f32 {
        let r = self.screw_m_per_rad();
        if r > 0.0 {
            self.rotor_inertia_kg_m2 / (r * r)
        } else {
            0.0
        }
    }

    /// The motor current limit actually usable: the smaller of the amplifier
    /// limit and `torque_limit / k_m`, A (never negative; 0 if `k_m <= 0`).
    pub fn usable_current_limit_a(&self) -> f32 {
        let from_torque = if self.torque_constant_nm_per_a > 0.0 {
            self.torque_limit_nm / self.torque_constant_nm_per_a
        } else {
            0.0
        };
        let i = self.current_limit_a.min(from_torque);
        if i.is_finite() && i > 0.0 {
            i
        } else {
            0.0
        }
    }

    /// Preload energy `0.5 k delta0^2`, J: the spring term at rest in flight with `p = 0`.
    pub fn preload_energy_j(&self) -> f32 {
        0.5 * self.spring_stiffness_n_per_m * self.preload_m * self.preload_m
    }

    /// Desired total energy `E_D` for a desired toe apex height `H_D` (`apex_m`, m), J.
    ///
    /// Thesis eq 2.43 is `E_D = M g (l0 + H) + m_s g (s0 + H) + m_u g H`. In
    /// this crate's coordinates (those of the energy estimate and of the
    /// simulator, ground reference, nut height `z - p`) the robot at rest at the
    /// apex with `p = 0` has
    /// `E_D = M g (l0 + H) + m_s g (l0 + H) + m_u g H + 0.5 k delta0^2`.
    /// Differences from eq 2.43, all constant offsets: the nut term uses `l0`
    /// instead of the thesis's `s0` (the nut is at body height when `p = 0`),
    /// and the preload spring energy `0.5 k delta0^2` is added (the thesis has
    /// no preload). With the design set and `H = 0.15 m` this is 69.98 J,
    /// so the thesis's Table 2.1 `E_d = 70 J` is a 0.15 m hop here.
    pub fn desired_energy_j(&self, apex_m: f32) -> Result<f32, ModelError> {
        if !(apex_m >= 0.0 && apex_m.is_finite()) {
            return Err(ModelError::BadArgument);
        }
        let g = self.gravity_mps2;
        let height = self.leg_length_m + apex_m;
        Ok((self.body_mass_kg + self.nut_mass_kg) * g * height
            + self.unsprung_mass_kg * g * apex_m
            + self.preload_energy_j())
    }

    /// Stance-energy target for apex `H_D` (`apex_m`, m), J: the desired
    /// energy without the unsprung mass, `(M + m_s) g (l0 + H) + 0.5 k delta0^2`.
    ///
    /// This is what eq 2.44 (which has no `m_u` terms) reads just after a
    /// touchdown from a drop of `H` with the nut at `p = 0`: at touchdown the
    /// unsprung mass stops (its `0.5 m_u zd^2` is lost) and its potential
    /// `m_u g (z - l0)` is zero.
    pub fn stance_energy_at_touchdown_j(&self, apex_m: f32) -> Result<f32, ModelError> {
        if !(apex_m >= 0.0 && apex_m.is_finite()) {
            return Err(ModelError::BadArgument);
        }
        let height = self.leg_length_m + apex_m;
        Ok(
            (self.body_mass_kg + self.nut_mass_kg) * self.gravity_mps2 * height
                + self.preload_energy_j(),
        )
    }

    /// Stance energy (eq 2.44, no rotor or relative nut motion, `p = 0`) needed
    /// just before liftoff to reach toe apex `H` afterwards, J.
    ///
    /// The liftoff pick-up of `m_u` conserves momentum (eq 2.40):
    /// `zd+ = (M + m_s)/m_t zd-`, `H = zd+^2 / (2 g)`, so
    /// `E = (M + m_s) g l0 + 0.5 k delta0^2 + m_t^2 / (M + m_s) g H`.
    /// Larger than [`stance_energy_at_touchdown_j`](Self::stance_energy_at_touchdown_j)
    /// by the liftoff loss (MODEL.md erratum: about 1.13 J at 2 m/s).
    pub fn stance_energy_for_liftoff_j(&self, apex_m: f32) -> Result<f32, ModelError> {
        if !(apex_m >= 0.0 && apex_m.is_finite()) {
            return Err(ModelError::BadArgument);
        }
        let m_sprung = self.body_mass_kg + self.nut_mass_kg;
        if m_sprung <= 0.0 || !m_sprung.is_finite() {
            return Err(ModelError::OutOfRange(ModelField::BodyMass));
        }
        let m_t = self.total_mass_kg();
        let g = self.gravity_mps2;
        Ok(m_sprung * g * self.leg_length_m
            + self.preload_energy_j()
            + m_t * m_t / m_sprung * g * apex_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid_and_derived_values() -> Result<(), ModelError> {
        let m = ModelParams::default();
        m.validate()?;
        assert!((m.screw_m_per_rad() - 7.957_747e-4).abs() < 1e-9);
        assert!((m.reflected_inertia_kg() - 426.4).abs() < 0.5);
        assert!((m.usable_current_limit_a() - 33.67).abs() < 1e-3);
        Ok(())
    }

    #[test]
    fn desired_energy_matches_plant_at_rest() -> Result<(), ModelError> {
        let m = ModelParams::default();
        let h = 0.15_f32;
        let z = m.leg_length_m + h;
        // Plant energy at rest in flight, p = 0: M g z + m_s g z + 0.5 k d0^2 + m_u g (z - l0).
        let plant = m.body_mass_kg * 9.81 * z
            + m.nut_mass_kg * 9.81 * z
            + 0.5 * m.spring_stiffness_n_per_m * m.preload_m * m.preload_m
            + m.unsprung_mass_kg * 9.81 * (z - m.leg_length_m);
        assert!((m.desired_energy_j(h)? - plant).abs() < 1e-3);
        // (M + m_s) g (l0 + H) + m_u g H with no preload (69.985 J with 5 mm).
        assert!((m.desired_energy_j(h)? - 69.848).abs() < 1e-2);
        let stance = m.stance_energy_at_touchdown_j(h)?;
        assert!((m.desired_energy_j(h)? - stance - 0.6 * 9.81 * h).abs() < 1e-3);
        assert!(m.stance_energy_for_liftoff_j(h)? > stance);
        Ok(())
    }

    #[test]
    fn validation_names_the_field() {
        let m = ModelParams {
            spring_stiffness_n_per_m: f32::NAN,
            ..ModelParams::default()
        };
        assert_eq!(
            m.validate(),
            Err(ModelError::OutOfRange(ModelField::SpringStiffness))
        );
        let m = ModelParams {
            efficiency: 1.5,
            ..ModelParams::default()
        };
        assert_eq!(
            m.validate(),
            Err(ModelError::OutOfRange(ModelField::Efficiency))
        );
        assert_eq!(
            ModelParams::default().desired_energy_j(-0.1),
            Err(ModelError::BadArgument)
        );
    }
}
