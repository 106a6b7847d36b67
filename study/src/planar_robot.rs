//! A planar robot file: the machine `hopper-sim planar run --robot FILE`
//! runs, in TOML. Four tables: `[machine]` (Appendix A's runner),
//! `[hip]` (the hip's motor, gear and amplifier), `[leg]` (the leg's
//! motor and ball screw, for `--thrust LAW`) and `[sensors]` (each
//! sensor's resolution). An entry left out keeps the design machine's
//! value ([`PlanarMachine::design`]); an unknown table or entry, a value
//! that is not a number, or one outside its range is refused with its
//! name, and the machine as a whole is checked before it runs.
//!
//! [`FIELDS`] is each entry's one declaration (name, unit, range, what it
//! is); [`template`] writes the design machine from it, every entry with
//! its line of documentation (`tests/robots/planar.toml` is that file).

use hopper_sil::planar::PlanarMachine;

/// One entry of the file.
#[derive(Clone, Copy)]
pub struct Field {
    /// Its table.
    pub table: &'static str,
    /// Its name.
    pub key: &'static str,
    /// Its unit.
    pub unit: &'static str,
    /// The smallest value allowed.
    pub min: f64,
    /// The largest.
    pub max: f64,
    /// What it is.
    pub doc: &'static str,
    get: fn(&PlanarMachine) -> f64,
    set: fn(&mut PlanarMachine, f64),
}

macro_rules! field {
    ($table:literal, $($path:ident).+ as $key:literal, $unit:literal, [$min:expr, $max:expr], $doc:literal) => {
        Field {
            table: $table,
            key: $key,
            unit: $unit,
            min: $min,
            max: $max,
            doc: $doc,
            get: |m| f64::from(m.$($path).+),
            set: |m, v| m.$($path).+ = v as _,
        }
    };
}

/// Every entry of a planar robot file.
pub const FIELDS: &[Field] = &[
    field!("machine", params.trunk_mass_kg as "trunk_mass_kg", "kg", [0.1, 1000.0], "The body's (trunk's) mass m_t (Table 2.2: 12.5 kg)."),
    field!("machine", params.trunk_inertia_kg_m2 as "trunk_inertia_kg_m2", "kg m^2", [1e-4, 100.0], "The body's pitch inertia about its centre J_t (Table 2.2's 0.82 kg m^2 about the hip)."),
    field!("machine", params.trunk_offset_x_m as "trunk_offset_x_m", "m", [-1.0, 1.0], "The body's centre ahead of the hip, in the body's frame d_x."),
    field!("machine", params.trunk_offset_z_m as "trunk_offset_z_m", "m", [-1.0, 1.0], "The body's centre above the hip, in the body's frame d_z."),
    field!("machine", params.leg_mass_kg as "leg_mass_kg", "kg", [0.01, 100.0], "The leg's mass above its spring m_l (Table 2.2: 3.5 kg)."),
    field!("machine", params.leg_inertia_kg_m2 as "leg_inertia_kg_m2", "kg m^2", [1e-5, 100.0], "The leg's inertia about its centre J_l."),
    field!("machine", params.leg_com_from_hip_m as "leg_com_from_hip_m", "m", [0.0, 1.0], "The leg's centre below the hip, along the leg d (at most the leg's length)."),
    field!("machine", params.toe_mass_kg as "toe_mass_kg", "kg", [0.0, 10.0], "The unsprung mass at the toe m_u (lost at each touchdown)."),
    field!("machine", params.leg_length_m as "leg_length_m", "m", [0.1, 5.0], "Hip to toe with the leg on its stop l_0 (Table 2.2: 0.65 m); the controller's and the estimator's follow it."),
    field!("machine", params.leg_stiffness_n_per_m as "leg_stiffness_n_per_m", "N/m", [10.0, 1e7], "The leg spring k_l (Table 2.2: 40,425 N/m)."),
    field!("machine", params.leg_damping_ns_per_m as "leg_damping_ns_per_m", "N s/m", [0.0, 1e4], "The leg's damper c_l."),
    field!("machine", params.hip_stiffness_nm_per_rad as "hip_stiffness_nm_per_rad", "N m/rad", [0.0, 1e4], "A hip spring beside the motor (the passive runner's; 0 on the actuated machine)."),
    field!("machine", params.hip_rest_angle_rad as "hip_rest_angle_rad", "rad", [-1.0, 1.0], "The hip spring's rest angle of the leg to the body."),
    field!("machine", params.hip_damping_nms_per_rad as "hip_damping_nms_per_rad", "N m s/rad", [0.0, 1e3], "The hip's damper."),
    field!("machine", params.planarizer_friction_n as "planarizer_friction_n", "N", [0.0, 1e3], "Dry friction of the boom (planarizer) on the hip's motion."),
    field!("machine", params.leg_friction_n as "leg_friction_n", "N", [0.0, 1e3], "Dry friction on the leg's sliding in stance."),
    field!("machine", params.hip_friction_nm as "hip_friction_nm", "N m", [0.0, 100.0], "Dry friction torque at the hip joint."),
    field!("machine", params.gravity_mps2 as "gravity_mps2", "m/s^2", [0.1, 100.0], "Gravitational acceleration g."),
    field!("hip", hip.torque_per_amp_nm_per_a as "torque_per_amp_nm_per_a", "N m/A", [1e-3, 100.0], "The hip's torque per ampere of motor current: the motor's constant times the gear's ratio and efficiency (the design: 29.7 mN m/A x 60 x 0.75)."),
    field!("hip", hip.current_limit_a as "current_limit_a", "A", [0.01, 1000.0], "The hip amplifier's current limit (the design: the leg's, 33.67 A); the controller's torque limit follows it."),
    field!("hip", hip_winding_ohm as "winding_resistance_ohm", "ohm", [1e-3, 100.0], "The hip motor's winding resistance, for its copper loss (the leg motor's: 0.356 ohm)."),
    field!("leg", leg.rotor_inertia_kg_m2 as "rotor_inertia_kg_m2", "kg m^2", [1e-7, 1.0], "The leg motor's rotor and screw inertia J, when the leg is driven through its ball screw (`--thrust LAW`; the design: four of the vertical hopper's, 1.08e-3 kg m^2)."),
    field!("leg", leg.screw_lead_m as "screw_lead_m", "m", [1e-4, 0.1], "The ball screw's lead, nut travel a motor turn (the design: 10 mm)."),
    field!("leg", leg.efficiency as "efficiency", "1", [0.05, 1.0], "Motor and screw efficiency eta: the nut sees eta tau / r (0.9)."),
    field!("leg", leg.torque_constant_nm_per_a as "torque_constant_nm_per_a", "N m/A", [1e-4, 10.0], "The leg motor's torque constant (the design: four of the vertical hopper's 29.7 mN m/A)."),
    field!("leg", leg.current_limit_a as "current_limit_a", "A", [1e-3, 1000.0], "The leg amplifier's current limit (33.67 A: 4 N m with the design's motor)."),
    field!("leg", leg.stroke_m as "stroke_m", "m", [1e-3, 0.5], "The nut's stroke between its stops (50 mm)."),
    field!("leg", leg.winding_ohm as "winding_resistance_ohm", "ohm", [1e-3, 100.0], "The leg motor's winding resistance, for its copper loss (0.356 ohm)."),
    field!("leg", leg.supply_voltage_v as "supply_voltage_v", "V", [1.0, 1000.0], "The leg amplifier's supply: the current it drives falls as the motor's back-EMF rises (24 V)."),
    field!("sensors", sensors.boom_x_m as "boom_x_m", "m", [0.0, 0.1], "The boom's forward encoder, metres at the hip a count; 0: none, the forward speed taken from the leg's kinematics in stance (the pitch and hip encoders and the potentiometer) and held through the flight."),
    field!("sensors", sensors.boom_z_m as "boom_z_m", "m", [1e-9, 0.1], "The boom's height encoder, metres at the hip a count."),
    field!("sensors", sensors.pitch_rad as "pitch_rad", "rad", [1e-9, 0.1], "The body's pitch encoder, radians a count."),
    field!("sensors", sensors.hip_rad as "hip_rad", "rad", [1e-9, 0.1], "The hip encoder (the leg against the body), radians a count."),
    field!("sensors", sensors.leg_m as "leg_m", "m", [1e-9, 0.01], "The leg potentiometer, metres a converter step."),
    field!("sensors", sensors.leg_motor_rad as "leg_motor_rad", "rad", [1e-9, 0.1], "The leg motor's encoder, radians a count (2,000 counts a turn), when the leg is driven through its screw."),
];

/// The machine `text` describes (`origin` names it in errors).
pub fn from_toml_str(text: &str, origin: &str) -> Result<PlanarMachine, String> {
    let doc: toml::Table = text
        .parse()
        .map_err(|e| format!("{origin}: not TOML: {e}"))?;
    let mut m = PlanarMachine::design();
    for (table, entries) in &doc {
        let Some(entries) = entries.as_table() else {
            return Err(format!(
                "{origin}: `{table}` is not a table (the file has [machine], [hip], [leg] and [sensors])"
            ));
        };
        if !FIELDS.iter().any(|f| f.table == table) {
            return Err(format!(
                "{origin}: unknown table [{table}] (the file has [machine], [hip], [leg] and [sensors])"
            ));
        }
        for (key, value) in entries {
            let Some(f) = FIELDS.iter().find(|f| f.table == table && f.key == key) else {
                return Err(format!("{origin}: unknown entry {table}.{key}"));
            };
            let v = match value {
                toml::Value::Float(v) => *v,
                toml::Value::Integer(v) => *v as f64,
                _ => {
                    return Err(format!(
                        "{origin}: {table}.{key} must be a number, {}",
                        f.unit
                    ))
                }
            };
            if !(v.is_finite() && v >= f.min && v <= f.max) {
                return Err(format!(
                    "{origin}: {table}.{key} = {v} is outside {} ..= {} {}",
                    f.min, f.max, f.unit
                ));
            }
            (f.set)(&mut m, v);
        }
    }
    m.validate()
        .map_err(|e| format!("{origin}: the machine is refused: {e:?}"))?;
    Ok(m)
}

/// The machine in the file at `path`.
pub fn load(path: &std::path::Path) -> Result<PlanarMachine, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read the robot file {}: {e}", path.display()))?;
    from_toml_str(&text, &path.display().to_string())
}

/// The design machine as a robot file, every entry with its line of
/// documentation, unit and range.
pub fn template() -> String {
    let m = PlanarMachine::design();
    let mut out = String::from(
        "# A planar hopper on a boom: Appendix A's runner with its hip actuated, the\n\
         # hip's drive and the sensors. `hopper-sim planar run --controller raibert\n\
         # --robot FILE` runs it. An entry left out keeps the value below (the\n\
         # design machine: Table 2.2's masses, the leg's motor through a 60:1\n\
         # gearhead at the hip, a 1.5 m boom). Written by `hopper-sim planar\n\
         # robot-template`.\n",
    );
    let mut table = "";
    for f in FIELDS {
        if f.table != table {
            table = f.table;
            out.push_str(&format!("\n[{table}]\n"));
        }
        out.push_str(&format!(
            "# {} Allowed: {} ..= {} {}.\n{} = {}\n",
            f.doc,
            f.min,
            f.max,
            f.unit,
            f.key,
            shortest((f.get)(&m))
        ));
    }
    out
}

/// `v` in the fewest digits that read back to it: an `f32` entry's (the
/// firmware's) as that `f32`.
fn shortest(v: f64) -> String {
    let single = v as f32;
    if f64::from(single) == v {
        format!("{single:?}")
    } else {
        format!("{v:?}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_template_is_the_design_machine_and_the_committed_file() {
        let t = template();
        assert_eq!(
            from_toml_str(&t, "template").ok(),
            Some(PlanarMachine::design())
        );
        let committed = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/robots/planar.toml"
        ))
        .unwrap_or_default();
        assert_eq!(
            committed, t,
            "tests/robots/planar.toml is not `hopper-sim planar robot-template`"
        );
    }

    #[test]
    fn a_bad_entry_is_refused_by_name() {
        let bad = |text: &str| from_toml_str(text, "f.toml").err().unwrap_or_default();
        assert!(bad("[machine]\ntrunk_mas_kg = 3\n").contains("unknown entry machine.trunk_mas_kg"));
        assert!(bad("[arm]\nx = 1\n").contains("unknown table [arm]"));
        assert!(
            bad("[hip]\ncurrent_limit_a = -1\n").contains("hip.current_limit_a = -1 is outside")
        );
        assert!(bad("[sensors]\nleg_m = \"fine\"\n").contains("sensors.leg_m must be a number, m"));
        assert!(bad("[machine\n").contains("not TOML"));
        // In range alone, out of the machine's whole: the leg's centre
        // below its toe.
        assert!(
            bad("[machine]\nleg_length_m = 0.2\nleg_com_from_hip_m = 0.5\n")
                .contains("leg_com_from_hip_m")
        );
        // An entry left out keeps the design's.
        let m = from_toml_str("[machine]\ntrunk_mass_kg = 15\n", "f.toml");
        assert!(m.is_ok_and(|m| m.params.trunk_mass_kg == 15.0
            && m.params.leg_length_m == PlanarMachine::design().params.leg_length_m));
    }
}
