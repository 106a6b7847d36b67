//! Physical parameters of the vertical hopper and its actuator, the thesis's
//! named parameter sets, and validation.
//!
//! Every field is in SI units, named with its unit. One table, [`FIELDS`],
//! describes each field (unit, meaning, allowed range, accessor): validation,
//! the TOML printer and the TOML reader all use it, so they cannot drift apart.

use core::fmt;
use hopper_model::ModelField;

/// Parameters of the plant (thesis Table 2.1 and section 4.5, MODEL.md).
///
/// Coordinates: `z` body height (`z = leg_length_m` at touchdown), `p` nut
/// displacement, positive down (compressing the spring), `0 ..= stroke_m`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(deny_unknown_fields)
)]
pub struct Params {
    /// Sprung (body) mass `M`, kg.
    pub body_mass_kg: f64,
    /// Unsprung mass `m_u` (lower leg and toe), kg.
    pub unsprung_mass_kg: f64,
    /// Sliding mass `m_s` (ball nut plus a share of the spring), kg.
    pub nut_mass_kg: f64,
    /// Rotor + screw moment of inertia `J`, kg m^2.
    pub rotor_inertia_kg_m2: f64,
    /// Ball-screw lead, metres of nut travel per motor revolution.
    pub screw_lead_m: f64,
    /// Leg spring stiffness `k`, N/m.
    pub spring_stiffness_n_per_m: f64,
    /// Viscous spring damping `c`, N s/m.
    pub spring_damping_ns_per_m: f64,
    /// Spring preload `delta0` with the nut at `p = 0` and the leg fully
    /// extended, m (MODEL.md: the thesis's `s0 - l0` read as a compression).
    pub spring_preload_m: f64,
    /// Leg free length `l0`: body coordinate at touchdown, m.
    pub leg_length_m: f64,
    /// Motor + ball-screw efficiency `eta` (the nut sees `eta tau / r`).
    pub efficiency: f64,
    /// Planarizer dry friction `F_fp` on the body, both phases, N.
    pub planarizer_friction_n: f64,
    /// Leg sliding dry friction `F_fs`, stance only, N.
    pub leg_friction_n: f64,
    /// Ball-screw stroke between the mechanical stops, m (`0 <= p <= stroke`).
    pub stroke_m: f64,
    /// Gravitational acceleration, m/s^2.
    pub gravity_mps2: f64,
    /// Motor torque constant (= back-EMF constant in SI), N m/A.
    pub torque_constant_nm_per_a: f64,
    /// Motor winding resistance, ohm.
    pub winding_resistance_ohm: f64,
    /// Servo-amplifier supply voltage, V.
    pub supply_voltage_v: f64,
    /// Servo-amplifier current limit, A.
    pub current_limit_a: f64,
}

/// Flight PD gains stated on the nut (Table 2.1's form): the force the nut
/// sees per metre of nut error, N/m, and per m/s of nut speed, N s/m
/// (`hopper_control::pd_design::gains_from_nut` converts them to the
/// firmware's motor-side A/rad and A s/rad).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NutPdGains {
    /// Position gain `k_pf`, N/m.
    pub kp_n_per_m: f64,
    /// Velocity gain `k_vf`, N s/m.
    pub kd_ns_per_m: f64,
}

/// Torque constant chosen so that the thesis's DC-motor plant gain
/// `A = k_m / J_e = 110` (eq 4.3, eq 4.13's worked numbers) holds with
/// Table 2.1's `J = 2.7e-4 kg m^2`: `k_m = 110 * 2.7e-4` (defined with the
/// rest of the design machine in `hopper_model::design`).
const KT_NM_PER_A: f64 = hopper_model::design::TORQUE_CONSTANT_NM_PER_A;

impl Params {
    /// The "design" set: thesis Table 2.1 (vertical hopper simulation).
    ///
    /// The motor is the 80 W Maxon class of section 3.1: stall torque 2.0 N m
    /// (Table 3.1) at 24 V sets the winding resistance
    /// (`R = k_t V / tau_stall`); the amplifier limit gives the 1.0 N m of
    /// Table 2.1. No preload: the thesis gives none
    /// ([`hopper_model::design::SPRING_PRELOAD_M`] says why).
    pub const fn design() -> Self {
        use hopper_model::design as d;
        Params {
            body_mass_kg: d::BODY_MASS_KG,
            unsprung_mass_kg: d::UNSPRUNG_MASS_KG,
            nut_mass_kg: d::NUT_MASS_KG,
            rotor_inertia_kg_m2: d::ROTOR_INERTIA_KG_M2,
            screw_lead_m: d::SCREW_LEAD_M,
            spring_stiffness_n_per_m: d::SPRING_STIFFNESS_N_PER_M,
            spring_damping_ns_per_m: 0.0,
            spring_preload_m: d::SPRING_PRELOAD_M,
            leg_length_m: d::LEG_LENGTH_M,
            efficiency: d::EFFICIENCY,
            planarizer_friction_n: 5.0,
            leg_friction_n: 5.0,
            stroke_m: d::STROKE_M,
            gravity_mps2: d::GRAVITY_MPS2,
            torque_constant_nm_per_a: KT_NM_PER_A,
            winding_resistance_ohm: KT_NM_PER_A * 24.0 / 2.0,
            supply_voltage_v: 24.0,
            current_limit_a: d::CURRENT_LIMIT_A,
        }
    }

    /// The "identified" set: thesis section 4.5 (eqs 4.19-4.20). Planarizer
    /// friction 13 N, total stance friction 28 N (so leg sliding 15 N), nut
    /// mass 300 g, and the effective stance torque 0.62 N m expressed as the
    /// amplifier current limit.
    pub const fn identified() -> Self {
        let d = Self::design();
        Params {
            planarizer_friction_n: 13.0,
            leg_friction_n: 15.0,
            nut_mass_kg: 0.30,
            current_limit_a: 0.62 / KT_NM_PER_A,
            ..d
        }
    }

    /// Look a named preset up: `"design"` or `"identified"`.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "design" => Some(Self::design()),
            "identified" => Some(Self::identified()),
            _ => None,
        }
    }

    /// Names of the presets [`Params::preset`] accepts.
    pub const PRESET_NAMES: [&'static str; 2] = ["design", "identified"];

    /// The preset name as a `'static` string, if `name` is one.
    pub fn preset_name(name: &str) -> Option<&'static str> {
        Self::PRESET_NAMES.iter().copied().find(|n| *n == name)
    }

    /// The flight PD a preset's machine was simulated with, stated on the
    /// nut: `design` runs Table 2.1's Chapter 2 flight law (`k_pf` 8e4 N/m,
    /// `k_vf` 300 N s/m) with the Chapter 2 stance laws; `identified`, the
    /// Chapter 4 machine, has `None`: the firmware's own default, eq 4.13's
    /// gains on the motor.
    pub fn preset_flight_gains(name: &str) -> Option<NutPdGains> {
        use hopper_model::design as d;
        match name {
            "design" => Some(NutPdGains {
                kp_n_per_m: d::FLIGHT_KPF_N_PER_M,
                kd_ns_per_m: d::FLIGHT_KVF_NS_PER_M,
            }),
            _ => None,
        }
    }

    /// Screw transmission `r = lead / (2 pi)`, m/rad (`theta = p / r`, eq 2.4).
    pub fn screw_m_per_rad(&self) -> f64 {
        self.screw_lead_m / (2.0 * core::f64::consts::PI)
    }

    /// Inertia the nut coordinate sees, `alpha = J / r^2 + m_s` (MODEL.md
    /// eqs 2.12-2.14: the rotor reflected through the screw plus the nut), kg.
    pub fn reflected_inertia_kg(&self) -> f64 {
        let r = self.screw_m_per_rad();
        self.rotor_inertia_kg_m2 / (r * r) + self.nut_mass_kg
    }

    /// Maximum motor torque the amplifier can produce at standstill, N m.
    pub fn max_torque_nm(&self) -> f64 {
        let stall_a = self.supply_voltage_v / self.winding_resistance_ohm;
        self.torque_constant_nm_per_a * self.current_limit_a.min(stall_a)
    }

    /// Motor no-load speed `V / k_e`, rad/s.
    pub fn no_load_speed_rad_s(&self) -> f64 {
        self.supply_voltage_v / self.torque_constant_nm_per_a
    }

    /// Check every field against its documented range.
    pub fn validate(&self) -> Result<(), ParamError> {
        for f in FIELDS.iter() {
            let v = (f.get)(self);
            if !f.allows(v) {
                return Err(ParamError {
                    field: f.name,
                    value: v,
                    range: f.range,
                });
            }
        }
        Ok(())
    }
}

impl Default for Params {
    fn default() -> Self {
        Self::design()
    }
}

/// A parameter outside its allowed range: names the field, the value and the
/// range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamError {
    /// Field name as in TOML.
    pub field: &'static str,
    /// The offending value.
    pub value: f64,
    /// What is allowed.
    pub range: Range,
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "parameter `{}` = {} is out of range: allowed {}",
            self.field, self.value, self.range
        )
    }
}

/// An allowed range of a number, with its unit: checks a value and prints as
/// the messages do, `0.1 ..= 1000 kg`, or `> 0 and <= 100 kg` when the lower
/// bound itself is refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    min: f64,
    min_exclusive: bool,
    max: f64,
    unit: &'static str,
}

impl Range {
    /// The range of a field the controller's model shares, in `unit`.
    pub const fn of_model(field: ModelField, unit: &'static str) -> Self {
        let r = field.range();
        Self::new(r.min, false, r.max, unit)
    }

    /// `min ..= max` (`min` itself refused if `min_exclusive`), in `unit`.
    pub const fn new(min: f64, min_exclusive: bool, max: f64, unit: &'static str) -> Self {
        Self {
            min,
            min_exclusive,
            max,
            unit,
        }
    }

    /// Whether `v` is finite and inside.
    pub fn allows(&self, v: f64) -> bool {
        let above_min = if self.min_exclusive {
            v > self.min
        } else {
            v >= self.min
        };
        v.is_finite() && above_min && v <= self.max
    }

    /// The same range printed without its unit (when it is printed beside).
    pub fn without_unit(self) -> Self {
        Self { unit: "", ..self }
    }
}

impl fmt::Display for Range {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.min_exclusive {
            write!(f, "> {} and <= {}", self.min, self.max)?;
        } else {
            write!(f, "{} ..= {}", self.min, self.max)?;
        }
        if self.unit.is_empty() {
            Ok(())
        } else {
            write!(f, " {}", self.unit)
        }
    }
}

/// Description of one parameter field.
#[derive(Clone, Copy)]
pub struct FieldSpec {
    /// Field name (TOML key).
    pub name: &'static str,
    /// What it is, and where it comes from.
    pub doc: &'static str,
    /// Allowed values and the unit (a field the controller's model has
    /// too takes the model's range, `hopper_model::ModelField::range`).
    pub range: Range,
    /// Read the field.
    pub get: fn(&Params) -> f64,
    /// Write the field.
    pub set: fn(&mut Params, f64),
}

impl FieldSpec {
    /// Unit, as printed in comments.
    pub fn unit(&self) -> &'static str {
        self.range.unit
    }

    /// Whether `v` is finite and in the allowed range.
    pub fn allows(&self, v: f64) -> bool {
        self.range.allows(v)
    }
}

macro_rules! field {
    // A field the controller's model has too: its range is the model's
    // (`hopper_model::ModelField::range`, the one definition).
    ($name:ident, $unit:expr, $doc:expr, model $field:ident) => {
        FieldSpec {
            name: stringify!($name),
            doc: $doc,
            range: Range::of_model(ModelField::$field, $unit),
            get: |p| p.$name,
            set: |p, v| p.$name = v,
        }
    };
    ($name:ident, $unit:expr, $doc:expr, > $min:expr, $max:expr) => {
        field!($name, $unit, $doc, $min, true, $max)
    };
    ($name:ident, $unit:expr, $doc:expr, $min:expr, $max:expr) => {
        field!($name, $unit, $doc, $min, false, $max)
    };
    ($name:ident, $unit:expr, $doc:expr, $min:expr, $excl:expr, $max:expr) => {
        FieldSpec {
            name: stringify!($name),
            doc: $doc,
            range: Range::new($min, $excl, $max, $unit),
            get: |p| p.$name,
            set: |p, v| p.$name = v,
        }
    };
}

/// Every parameter field, in TOML order.
pub const FIELDS: [FieldSpec; 18] = [
    field!(body_mass_kg, "kg", "sprung (body) mass M", model BodyMass),
    field!(unsprung_mass_kg, "kg", "unsprung mass m_u (lower leg, toe)", model UnsprungMass),
    field!(nut_mass_kg, "kg", "sliding mass m_s (ball nut + share of spring)", model NutMass),
    field!(rotor_inertia_kg_m2, "kg m^2", "rotor + screw inertia J", model RotorInertia),
    field!(screw_lead_m, "m/rev", "ball-screw lead", model ScrewLead),
    field!(spring_stiffness_n_per_m, "N/m", "leg spring stiffness k", model SpringStiffness),
    field!(
        spring_damping_ns_per_m,
        "N s/m",
        "viscous spring damping c",
        0.0,
        1e4
    ),
    field!(spring_preload_m, "m", "spring preload delta0 (nut at p = 0, leg extended)", model Preload),
    field!(leg_length_m, "m", "leg free length l0 (body height at touchdown)", model LegLength),
    field!(efficiency, "1", "motor + ball-screw efficiency eta", model Efficiency),
    field!(
        planarizer_friction_n,
        "N",
        "planarizer dry friction F_fp (both phases)",
        0.0,
        1e4
    ),
    field!(
        leg_friction_n,
        "N",
        "leg sliding dry friction F_fs (stance only)",
        0.0,
        1e4
    ),
    field!(stroke_m, "m", "ball-screw stroke between the mechanical stops", model Stroke),
    field!(gravity_mps2, "m/s^2", "gravitational acceleration", model Gravity),
    field!(torque_constant_nm_per_a, "N m/A", "motor torque constant (= back-EMF constant)", model TorqueConstant),
    field!(
        winding_resistance_ohm,
        "ohm",
        "motor winding resistance",
        1e-3,
        100.0
    ),
    field!(
        supply_voltage_v,
        "V",
        "amplifier supply voltage",
        1.0,
        1000.0
    ),
    field!(current_limit_a, "A", "amplifier current limit", model CurrentLimit),
];

/// Look a field up by its TOML name.
pub fn field(name: &str) -> Option<&'static FieldSpec> {
    FIELDS.iter().find(|f| f.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_match_the_thesis() {
        let d = Params::design();
        d.validate().unwrap();
        assert!((d.max_torque_nm() - 1.0).abs() < 1e-12);
        // MODEL.md: J / r^2 is about 426 kg.
        let r = d.screw_m_per_rad();
        assert!((r - 7.96e-4).abs() < 1e-6);
        let reflected = d.rotor_inertia_kg_m2 / (r * r);
        assert!((reflected - 426.0).abs() < 1.0, "{reflected}");
        let i = Params::identified();
        i.validate().unwrap();
        assert!((i.max_torque_nm() - 0.62).abs() < 1e-12);
        assert_eq!(i.planarizer_friction_n + i.leg_friction_n, 28.0);
    }

    #[test]
    fn validation_names_field_value_and_range() {
        let mut p = Params::design();
        p.body_mass_kg = -1.0;
        let e = p.validate().unwrap_err();
        assert_eq!(e.field, "body_mass_kg");
        assert_eq!(e.value, -1.0);
        let msg = std::format!("{e}");
        assert!(msg.contains("body_mass_kg") && msg.contains("-1") && msg.contains("0.1"));
        p = Params::design();
        p.efficiency = f64::NAN;
        assert_eq!(p.validate().unwrap_err().field, "efficiency");
    }

    #[test]
    fn field_table_round_trips_every_field() {
        let mut p = Params::design();
        for (i, f) in FIELDS.iter().enumerate() {
            (f.set)(&mut p, i as f64 + 0.5);
        }
        for (i, f) in FIELDS.iter().enumerate() {
            assert_eq!((f.get)(&p), i as f64 + 0.5, "{}", f.name);
        }
    }
}
