//! The hopper's physical facts, shared by the firmware and the simulator:
//! the design machine's values (thesis Table 2.1 and the motor of section
//! 3.1) and the allowed range of each physical parameter. The controller's
//! `f32` model (`hopper_control::model::ModelParams`) and the simulator's
//! `f64` plant (`hopper_plant::Params`) both take their defaults and their
//! checks from here, so neither depends on the other.
//!
//! [`metrics`] holds the hop metrics (steady apex, hops to converge): the
//! one definition of "converged" the QEMU images, the simulator and
//! `hopper-link` share.
#![no_std]

pub mod metrics;

/// Which the control model's `ModelParams` field failed validation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelField {
    /// `ModelParams::body_mass_kg`.
    BodyMass,
    /// `ModelParams::unsprung_mass_kg`.
    UnsprungMass,
    /// `ModelParams::nut_mass_kg`.
    NutMass,
    /// `ModelParams::rotor_inertia_kg_m2`.
    RotorInertia,
    /// `ModelParams::screw_lead_m`.
    ScrewLead,
    /// `ModelParams::spring_stiffness_n_per_m`.
    SpringStiffness,
    /// `ModelParams::leg_length_m`.
    LegLength,
    /// `ModelParams::preload_m`.
    Preload,
    /// `ModelParams::stroke_m`.
    Stroke,
    /// `ModelParams::efficiency`.
    Efficiency,
    /// `ModelParams::gravity_mps2`.
    Gravity,
    /// `ModelParams::torque_limit_nm`.
    TorqueLimit,
    /// `ModelParams::torque_constant_nm_per_a`.
    TorqueConstant,
    /// `ModelParams::current_limit_a`.
    CurrentLimit,
}

/// The allowed range of a physical parameter: `min ..= max`. Written in
/// `f64` so the simulator's `f64` plant parameters (`hopper-plant`'s
/// `FIELDS`) share the one definition; the firmware's parameter table
/// (`model.*` entries) and `ModelParams::validate` compare in `f32`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldRange {
    /// Lower bound (inclusive).
    pub min: f64,
    /// Upper bound (inclusive).
    pub max: f64,
}

const fn range(min: f64, max: f64) -> FieldRange {
    FieldRange { min, max }
}

impl ModelField {
    /// The field's allowed range, the one definition the controller's model
    /// and the simulator's plant both check. The lower leg's and the nut's
    /// masses, the torque limit and the current limit may be small but not
    /// zero (a massless part or a motor that cannot push is not a machine):
    /// the masses down to a microgram (1e-9 kg, the plant's
    /// energy-conservation test's lower leg), the limits to 1e-3.
    pub const fn range(self) -> FieldRange {
        match self {
            ModelField::BodyMass => range(0.1, 1000.0),
            ModelField::UnsprungMass => range(1e-9, 100.0),
            ModelField::NutMass => range(1e-9, 100.0),
            ModelField::RotorInertia => range(1e-7, 1.0),
            ModelField::ScrewLead => range(1e-4, 0.1),
            ModelField::SpringStiffness => range(10.0, 1e7),
            ModelField::LegLength => range(0.05, 5.0),
            ModelField::Preload => range(0.0, 0.5),
            ModelField::Stroke => range(1e-3, 0.5),
            ModelField::Efficiency => range(0.05, 1.0),
            ModelField::Gravity => range(0.1, 100.0),
            ModelField::TorqueLimit => range(1e-3, 100.0),
            ModelField::TorqueConstant => range(1e-4, 10.0),
            ModelField::CurrentLimit => range(1e-3, 1000.0),
        }
    }
}

/// The thesis's design machine (Table 2.1, with the 80 W motor of section
/// 3.1), in `f64`: the one definition of its values. The
/// simulator's `design` plant preset takes them as they are;
/// [`ModelParams::default`] converts them to `f32` once.
pub mod design {
    /// Sprung (body) mass `M`, kg.
    pub const BODY_MASS_KG: f64 = 9.0;
    /// Unsprung mass `m_u`, kg.
    pub const UNSPRUNG_MASS_KG: f64 = 0.6;
    /// Sliding (ball nut) mass `m_s`, kg.
    pub const NUT_MASS_KG: f64 = 0.25;
    /// Rotor + screw inertia `J`, kg m^2.
    pub const ROTOR_INERTIA_KG_M2: f64 = 2.7e-4;
    /// Ball-screw lead, m per revolution.
    pub const SCREW_LEAD_M: f64 = 0.005;
    /// Leg spring stiffness `k`, N/m.
    pub const SPRING_STIFFNESS_N_PER_M: f64 = 11_000.0;
    /// Spring preload `delta0`, m: none. The thesis gives no preload, and
    /// its eq 2.43 puts the nut on its stop with no spring energy at the
    /// apex, which is zero preload. Keeping the nut seated needs only its
    /// sag under its own weight (`m_s g / k` = 0.22 mm), and the stops hold
    /// it while hopping anyway. A preload is a design knob (sweep
    /// `spring_preload_m`): 5 mm shortens the stance from 100 to 93 ms and
    /// strands spring energy in the actuator at liftoff (docs/thesis-comparison.md).
    pub const SPRING_PRELOAD_M: f64 = 0.0;
    /// Leg free length `l0`, m.
    pub const LEG_LENGTH_M: f64 = 0.61;
    /// Motor + ball-screw efficiency `eta`.
    pub const EFFICIENCY: f64 = 0.9;
    /// Nut stroke between the mechanical stops, m.
    pub const STROKE_M: f64 = 0.05;
    /// Gravitational acceleration, m/s^2.
    pub const GRAVITY_MPS2: f64 = 9.81;
    /// Motor torque constant, N m/A (110 rad/s^2/A times the 2.7e-4 kg m^2 rotor).
    pub const TORQUE_CONSTANT_NM_PER_A: f64 = 110.0 * 2.7e-4;
    /// Motor torque limit of Table 2.1, N m.
    pub const TORQUE_LIMIT_NM: f64 = 1.0;
    /// Amplifier current limit, A: the torque limit at the torque constant.
    pub const CURRENT_LIMIT_A: f64 = TORQUE_LIMIT_NM / TORQUE_CONSTANT_NM_PER_A;
    /// The actuated planar machine's hip drive (section 5.2's "trunk
    /// actuation system", which the thesis leaves to design): the leg's
    /// motor and amplifier through a 60:1 gearhead. Its 45 N m at the
    /// amplifier's limit covers the largest torque Raibert's controller
    /// asks for running 0 to 1 m/s (48 N m, briefly); its demand there,
    /// 3 to 4.5 N m RMS, is 2.3 to 3.3 A, below the motor's continuous
    /// current.
    pub const HIP_GEAR_RATIO: f64 = 60.0;
    /// The hip gearhead's efficiency (a planetary head's, three stages).
    pub const HIP_GEAR_EFFICIENCY: f64 = 0.75;
    /// The hip's torque per ampere of motor current, N m/A.
    pub const HIP_TORQUE_PER_AMP_NM_PER_A: f64 =
        TORQUE_CONSTANT_NM_PER_A * HIP_GEAR_RATIO * HIP_GEAR_EFFICIENCY;
    /// The hip's torque at the amplifier's current limit, N m.
    pub const HIP_TORQUE_LIMIT_NM: f64 = CURRENT_LIMIT_A * HIP_TORQUE_PER_AMP_NM_PER_A;
    /// The actuated planar machine's leg drive, as the vertical hopper's (a
    /// motor on a ball screw in series with the leg spring), scaled to its
    /// 16.3 kg and 40 kN/m spring: this many times the vertical motor's
    /// torque constant and rotor inertia, at the same amplifier limit (4 N
    /// m). On the vertical drive (1 N m on a 5 mm lead) the energy-apex
    /// law holds this machine's hop at 0.114 m in place, 24% short of 0.15
    /// m, the motor at its limit; on this one at 0.150 m, and within 9% of
    /// it running 0 to 1 m/s.
    pub const PLANAR_LEG_MOTOR_SCALE: f64 = 4.0;
    /// The planar leg drive's screw lead, m per revolution: twice the
    /// vertical's, so that the rotor seen at the nut (`J / r^2`, 426 kg)
    /// is the vertical drive's, four times the torque behind it.
    pub const PLANAR_SCREW_LEAD_M: f64 = 0.01;
    /// Flight-law position gain `k_pf` of Table 2.1, N/m: the force the nut
    /// sees (`eta tau / r`) per metre of nut error. The thesis states no
    /// unit; with N/m the Chapter 2 flight returns the nut within the
    /// flights it simulates. The Chapter 4 machine uses eq 4.13 instead.
    pub const FLIGHT_KPF_N_PER_M: f64 = 8.0e4;
    /// Flight-law velocity gain `k_vf` of Table 2.1, N s/m (as `k_pf`).
    pub const FLIGHT_KVF_NS_PER_M: f64 = 300.0;
}
