//! The planar one-legged runner of thesis section 2.2 (after Thompson and
//! Raibert): body of mass `m_b` and pitch inertia `J_b` with its centre at
//! the hip, a leg of mass `m_l` and inertia `J_l` (centre at the hip) on a
//! torsional hip spring `k_h`, a massless leg spring `k_l` of rest length
//! `r_0`, no losses (issue 20).
//!
//! This module holds Table 2.2's parameters and the passive-dynamics design
//! of sections 2.2.2.4-2.2.2.5: from the step period `T_step`, the stance
//! fraction `rho` and the running speed, the spring constants (eqs 2.73,
//! 2.75) and the initial conditions (eqs 2.76-2.78). The flight and stance
//! dynamics (eqs 2.54-2.61) are not built yet (below).
//!
//! The dynamics to build next. Eqs 2.54-2.61 give the leg spring's force
//! along the leg but not the ground force across it that a pinned toe
//! needs (the hip spring's torque on the leg, `J_l theta''`). Appendix A
//! writes stance in polar coordinates about the toe (eqs A.14-A.17), and
//! the section 2.2 model is its special case (no offsets, no unsprung
//! mass, no friction): with `m = m_b + m_l`, the toe at `x_f`, `x = x_f -
//! r sin theta`, `z = r cos theta`, Lagrange gives
//! `m (r'' - r theta'^2) = k_l (r_0 - r) - m g cos theta`,
//! `(m r^2 + J_l) theta'' + 2 m r r' theta' = m g r sin theta + k_h (phi - theta)`,
//! `J_b phi'' = k_h (theta - phi)`; flight is eqs 2.54-2.57 with `F = 0`.
//! At touchdown the hip's velocity is continuous and the leg's rate jumps
//! to the pinned toe's `theta' = -(x' cos theta + z' sin theta) / r_0`
//! (zero when the toe lands at rest, which the passive design aims at):
//! the energy that jump takes is to be reported, not hidden.
//!
//! Erratum: eq 2.77 prints the zero-angular-momentum condition as
//! `phi_dot / J_l = -theta_dot / J_d`; the angular momentum of body and leg
//! about the hip is `J_b phi_dot + J_l theta_dot`, so the condition is
//! `J_b phi_dot = -J_l theta_dot`, which is the thesis's own result
//! `phi_dot_0 = -(J_l / J_b) theta_dot_0`.

use core::f64::consts::PI;

/// The runner's masses, inertias, springs and leg length (SI).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarParams {
    /// Body mass `m_b`, kg.
    pub body_mass_kg: f64,
    /// Body pitch inertia about the hip `J_b`, kg m^2.
    pub body_inertia_kg_m2: f64,
    /// Leg mass `m_l`, kg.
    pub leg_mass_kg: f64,
    /// Leg inertia about its centre, at the hip, `J_l`, kg m^2.
    pub leg_inertia_kg_m2: f64,
    /// Leg rest length `r_0`, m.
    pub leg_rest_length_m: f64,
    /// Hip torsional spring `k_h`, N m/rad.
    pub hip_stiffness_nm_per_rad: f64,
    /// Leg spring `k_l`, N/m.
    pub leg_stiffness_n_per_m: f64,
    /// Gravity `g`, m/s^2.
    pub gravity_mps2: f64,
}

impl PlanarParams {
    /// Table 2.2.
    pub const fn table_2_2() -> Self {
        PlanarParams {
            body_mass_kg: 12.5,
            body_inertia_kg_m2: 0.82,
            leg_mass_kg: 3.5,
            leg_inertia_kg_m2: 0.23,
            leg_rest_length_m: 0.65,
            hip_stiffness_nm_per_rad: 28.4,
            leg_stiffness_n_per_m: 40_425.0,
            gravity_mps2: 9.81,
        }
    }

    /// Total mass `m_b + m_l`, kg.
    pub fn total_mass_kg(&self) -> f64 {
        self.body_mass_kg + self.leg_mass_kg
    }

    /// The hip oscillation's effective inertia `J_b J_l / (J_b + J_l)`
    /// (eq 2.70), kg m^2.
    pub fn effective_inertia_kg_m2(&self) -> f64 {
        self.body_inertia_kg_m2 * self.leg_inertia_kg_m2
            / (self.body_inertia_kg_m2 + self.leg_inertia_kg_m2)
    }

    /// The hip oscillation's natural frequency `sqrt(k_h / J_eff)` (eq
    /// 2.68), rad/s.
    pub fn hip_rate_rad_s(&self) -> f64 {
        libm::sqrt(self.hip_stiffness_nm_per_rad / self.effective_inertia_kg_m2())
    }

    /// The stance rebound's natural frequency `sqrt(k_l / m)` (eq 2.65),
    /// rad/s.
    pub fn leg_rate_rad_s(&self) -> f64 {
        libm::sqrt(self.leg_stiffness_n_per_m / self.total_mass_kg())
    }

    /// Every field positive and finite, else the first that is not.
    pub fn validate(&self) -> Result<(), PlanarError> {
        for (name, v) in [
            ("body_mass_kg", self.body_mass_kg),
            ("body_inertia_kg_m2", self.body_inertia_kg_m2),
            ("leg_mass_kg", self.leg_mass_kg),
            ("leg_inertia_kg_m2", self.leg_inertia_kg_m2),
            ("leg_rest_length_m", self.leg_rest_length_m),
            ("hip_stiffness_nm_per_rad", self.hip_stiffness_nm_per_rad),
            ("leg_stiffness_n_per_m", self.leg_stiffness_n_per_m),
            ("gravity_mps2", self.gravity_mps2),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(PlanarError::NotPositive(name));
            }
        }
        Ok(())
    }
}

/// The gait asked for: the three independent parameters of section
/// 2.2.2.5.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gait {
    /// Step period `T_step`, s.
    pub step_period_s: f64,
    /// Stance time over step time `rho` (the thesis tried 0.125-0.25).
    pub stance_fraction: f64,
    /// Running speed `x_dot_d`, m/s.
    pub speed_mps: f64,
}

/// A gait or parameter set that cannot be designed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlanarError {
    /// A field that must be positive and finite is not (its name).
    NotPositive(&'static str),
    /// `rho` is not within (0, 1).
    StanceFraction,
}

/// What the passive-dynamics design gives: the springs and the initial
/// conditions (the drop at mid flight, angles zero).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PassiveDesign {
    /// `k_h = (2 pi / T_step)^2 J_eff` (eq 2.73), N m/rad.
    pub hip_stiffness_nm_per_rad: f64,
    /// `k_l = m (pi / (rho T_step))^2` (eq 2.75), N/m.
    pub leg_stiffness_n_per_m: f64,
    /// Leg rate at the apex `x_dot_d / r_0` (eq 2.76), rad/s.
    pub leg_rate0_rad_s: f64,
    /// Body rate at the apex `-(J_l / J_b) theta_dot_0` (eq 2.77), rad/s.
    pub body_rate0_rad_s: f64,
    /// Flight time `T_step (1 - rho)`, s.
    pub flight_time_s: f64,
    /// The leg angle at touchdown `theta_dot_0 / omega_h sin(omega_h T_f
    /// / 2)` (eq 2.72 at half the flight), rad.
    pub touchdown_angle_rad: f64,
    /// Drop height of the hip `z_max` (eq 2.78), m.
    pub apex_height_m: f64,
}

/// The passive-dynamics design of `gait` for the masses, inertias and leg
/// length of `p` (its springs are what this computes; eqs 2.73-2.78).
pub fn passive_design(p: &PlanarParams, gait: &Gait) -> Result<PassiveDesign, PlanarError> {
    p.validate()?;
    if !(gait.step_period_s.is_finite() && gait.step_period_s > 0.0) {
        return Err(PlanarError::NotPositive("step_period_s"));
    }
    if !(gait.speed_mps.is_finite() && gait.speed_mps >= 0.0) {
        return Err(PlanarError::NotPositive("speed_mps"));
    }
    let rho = gait.stance_fraction;
    if !(rho > 0.0 && rho < 1.0) {
        return Err(PlanarError::StanceFraction);
    }
    let omega_h = 2.0 * PI / gait.step_period_s;
    let k_h = omega_h * omega_h * p.effective_inertia_kg_m2();
    let leg = PI / (rho * gait.step_period_s);
    let k_l = p.total_mass_kg() * leg * leg;
    let theta0 = gait.speed_mps / p.leg_rest_length_m;
    let phi0 = -p.leg_inertia_kg_m2 / p.body_inertia_kg_m2 * theta0;
    let t_f = gait.step_period_s * (1.0 - rho);
    let td_angle = theta0 / omega_h * libm::sin(omega_h * t_f / 2.0);
    let z_max = p.gravity_mps2 / 8.0 * t_f * t_f + p.leg_rest_length_m * libm::cos(td_angle);
    Ok(PassiveDesign {
        hip_stiffness_nm_per_rad: k_h,
        leg_stiffness_n_per_m: k_l,
        leg_rate0_rad_s: theta0,
        body_rate0_rad_s: phi0,
        flight_time_s: t_f,
        touchdown_angle_rad: td_angle,
        apex_height_m: z_max,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const TABLE_GAIT: Gait = Gait {
        step_period_s: 0.5,
        stance_fraction: 0.125,
        speed_mps: 2.0,
    };

    /// Table 2.2's springs are the design's for its T_step = 0.5 s and rho
    /// = 0.125: 28.4 N m/rad and 40 425 N/m.
    #[test]
    fn table_2_2_springs_follow_from_the_passive_design() {
        let p = PlanarParams::table_2_2();
        let d = passive_design(&p, &TABLE_GAIT).unwrap_or_else(|e| panic!("{e:?}"));
        assert!((d.hip_stiffness_nm_per_rad - 28.4).abs() < 0.05, "{d:?}");
        assert!((d.leg_stiffness_n_per_m - 40_425.0).abs() < 2.0, "{d:?}");
        // And rho = omega_h / (2 omega_l) (eq 2.74) with them.
        assert!((p.hip_rate_rad_s() / (2.0 * p.leg_rate_rad_s()) - 0.125).abs() < 1e-3);
    }

    /// The initial conditions at 2 and 4 m/s (eqs 2.76-2.78).
    #[test]
    fn initial_conditions_at_2_and_4_mps() {
        let p = PlanarParams::table_2_2();
        for (v, theta0, phi0, z) in [
            (2.0, 3.0769, -0.8630, 0.8819),
            (4.0, 6.1538, -1.7261, 0.8733),
        ] {
            let d = passive_design(
                &p,
                &Gait {
                    speed_mps: v,
                    ..TABLE_GAIT
                },
            )
            .unwrap_or_else(|e| panic!("{e:?}"));
            assert!((d.leg_rate0_rad_s - theta0).abs() < 1e-4, "{d:?}");
            assert!((d.body_rate0_rad_s - phi0).abs() < 1e-4, "{d:?}");
            assert!((d.flight_time_s - 0.4375).abs() < 1e-12);
            assert!((d.apex_height_m - z).abs() < 1e-4, "{v}: {d:?}");
            // Zero angular momentum about the hip in flight.
            let h =
                p.body_inertia_kg_m2 * d.body_rate0_rad_s + p.leg_inertia_kg_m2 * d.leg_rate0_rad_s;
            assert!(h.abs() < 1e-12);
        }
    }

    #[test]
    fn bad_gaits_and_parameters_are_refused_by_name() {
        let p = PlanarParams::table_2_2();
        let g = |rho| Gait {
            stance_fraction: rho,
            ..TABLE_GAIT
        };
        assert_eq!(
            passive_design(&p, &g(0.0)),
            Err(PlanarError::StanceFraction)
        );
        assert_eq!(
            passive_design(&p, &g(1.0)),
            Err(PlanarError::StanceFraction)
        );
        assert_eq!(
            passive_design(&p, &g(f64::NAN)),
            Err(PlanarError::StanceFraction)
        );
        let bad = PlanarParams {
            leg_inertia_kg_m2: -1.0,
            ..p
        };
        assert_eq!(
            passive_design(&bad, &TABLE_GAIT),
            Err(PlanarError::NotPositive("leg_inertia_kg_m2"))
        );
    }
}
