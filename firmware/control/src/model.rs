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

/// The least value of `field`'s range, in the table's `f32`.
const fn lo(field: ModelField) -> f32 {
    field.range().min as f32
}

/// The largest value of `field`'s range, in the table's `f32`.
const fn hi(field: ModelField) -> f32 {
    field.range().max as f32
}

/// The fields' names as the declarations below use them.
use ModelField as F;

pub use hopper_model::design;

crate::param::config! {
    /// Physical parameters of the hopper, f32 SI, each a runtime parameter
    /// (`model.*`: changed only disarmed, saved with the calibration) in
    /// the range [`ModelField::range`] gives (the simulator's plant checks
    /// the same ranges). `Default` is the thesis's "design" set (Table 2.1)
    /// plus the motor of section 3.1, with no preload (the thesis gives
    /// none; see [`design::SPRING_PRELOAD_M`]). Setting one re-derives what
    /// follows from it ([`crate::config::HopperConfig::follow_model`]).
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct ModelParams;
    params {
        111 MODEL_BODY_MASS body_mass_kg: f32 {
            "model.body_mass_kg", "kg", Real, [lo(F::BodyMass), hi(F::BodyMass)],
            design::BODY_MASS_KG as f32, DISARMED,
            "Sprung (body) mass M (Table 2.1: 9 kg)."
        }
        112 MODEL_UNSPRUNG_MASS unsprung_mass_kg: f32 {
            "model.unsprung_mass_kg", "kg", Real, [lo(F::UnsprungMass), hi(F::UnsprungMass)],
            design::UNSPRUNG_MASS_KG as f32, DISARMED,
            "Unsprung (lower leg and toe) mass m_u (Table 2.1: 0.6 kg)."
        }
        113 MODEL_NUT_MASS nut_mass_kg: f32 {
            "model.nut_mass_kg", "kg", Real, [lo(F::NutMass), hi(F::NutMass)],
            design::NUT_MASS_KG as f32, DISARMED,
            "Sliding (ball nut) mass m_s (Table 2.1: 0.25 kg)."
        }
        114 MODEL_ROTOR_INERTIA rotor_inertia_kg_m2: f32 {
            "model.rotor_inertia_kg_m2", "kg m^2", Real, [lo(F::RotorInertia), hi(F::RotorInertia)],
            design::ROTOR_INERTIA_KG_M2 as f32, DISARMED,
            "Rotor and screw moment of inertia J (Table 2.1: 2.7e-4 kg m^2)."
        }
        115 MODEL_SCREW_LEAD screw_lead_m: f32 {
            "model.screw_lead_m", "m", Real, [lo(F::ScrewLead), hi(F::ScrewLead)],
            design::SCREW_LEAD_M as f32, DISARMED,
            "Ball-screw lead, nut travel per motor revolution (Table 2.1: 5 mm); the calibration's lead follows it."
        }
        116 MODEL_SPRING_STIFFNESS spring_stiffness_n_per_m: f32 {
            "model.spring_stiffness_n_per_m", "N/m", Real, [lo(F::SpringStiffness), hi(F::SpringStiffness)],
            design::SPRING_STIFFNESS_N_PER_M as f32, DISARMED,
            "Leg spring stiffness k the controller believes (Table 2.1: 11 000 N/m); supervisor.spring_rate_n_per_m follows it unless set apart."
        }
        117 MODEL_LEG_LENGTH leg_length_m: f32 {
            "model.leg_length_m", "m", Real, [lo(F::LegLength), hi(F::LegLength)],
            design::LEG_LENGTH_M as f32, DISARMED,
            "Leg free length l0: the body coordinate z at touchdown (Table 2.1: 0.61 m)."
        }
        118 MODEL_PRELOAD preload_m: f32 {
            "model.preload_m", "m", Real, [lo(F::Preload), hi(F::Preload)],
            design::SPRING_PRELOAD_M as f32, DISARMED,
            "Spring preload delta0 with the nut home and the leg extended (the design has none); supervisor.spring_preload_m follows it unless set apart."
        }
        119 MODEL_STROKE stroke_m: f32 {
            "model.stroke_m", "m", Real, [lo(F::Stroke), hi(F::Stroke)],
            design::STROKE_M as f32, DISARMED,
            "Nut stroke between the mechanical stops (p in 0..stroke); the supervisor's stops and soft limits follow it."
        }
        120 MODEL_EFFICIENCY efficiency: f32 {
            "model.efficiency", "1", Real, [lo(F::Efficiency), hi(F::Efficiency)],
            design::EFFICIENCY as f32, DISARMED,
            "Motor and ball-screw efficiency eta: the nut sees eta tau / r (Table 2.1: 0.9)."
        }
        121 MODEL_GRAVITY gravity_mps2: f32 {
            "model.gravity_mps2", "m/s^2", Real, [lo(F::Gravity), hi(F::Gravity)],
            design::GRAVITY_MPS2 as f32, DISARMED,
            "Gravitational acceleration g."
        }
        122 MODEL_TORQUE_LIMIT torque_limit_nm: f32 {
            "model.torque_limit_nm", "N m", Real, [lo(F::TorqueLimit), hi(F::TorqueLimit)],
            design::TORQUE_LIMIT_NM as f32, DISARMED,
            "Motor torque limit (Table 2.1: 1 N m); the usable current is the smaller of this over k_m and the current limit."
        }
        123 MODEL_TORQUE_CONSTANT torque_constant_nm_per_a: f32 {
            "model.torque_constant_nm_per_a", "N m/A", Real, [lo(F::TorqueConstant), hi(F::TorqueConstant)],
            design::TORQUE_CONSTANT_NM_PER_A as f32, DISARMED,
            "Motor torque constant k_m (110 rad/s^2/A times J, eq 4.3: 0.0297 N m/A); the calibration's follows it."
        }
        124 MODEL_CURRENT_LIMIT current_limit_a: f32 {
            "model.current_limit_a", "A", Real, [lo(F::CurrentLimit), hi(F::CurrentLimit)],
            design::CURRENT_LIMIT_A as f32, DISARMED,
            "Amplifier current limit (the torque limit over k_m: 33.67 A); the overcurrent trip follows it."
        }
    }
}

/// `Ok` if `v` is within `field`'s range, else the field error.
fn check(v: f32, field: ModelField) -> Result<(), ModelError> {
    let r = field.range();
    let (lo, hi) = (r.min as f32, r.max as f32);
    // NaN fails every comparison, so it is rejected here too.
    if v >= lo && v <= hi && v.is_finite() {
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
