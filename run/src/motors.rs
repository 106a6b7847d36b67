//! The motors a run can take by name (`--motor NAME`, a scenario's
//! `motor = "NAME"`): each one's electrical data for the plant and thermal
//! data for the firmware's winding estimate together, with where each
//! figure comes from (docs/endurance.md, "Other motors").
//!
//! The thesis names its motors (Table 3.1) but gives no thermal data for
//! any; of its four, catalogue sheets were found for two (docs/design.md).
//! Where a sheet lacks a figure the two-body model needs, the stand-in's
//! (the maxon RE 40's) is taken and the motor's `source` says so.

use crate::params::Params;
use hopper_control::params as p;
use serde::Serialize;

/// A candidate motor (datasheet values at its nominal voltage).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Motor {
    /// The thesis's name (Table 3.1).
    pub thesis_name: &'static str,
    /// The catalogue motor taken for it.
    pub model: &'static str,
    /// Torque constant, N m/A.
    pub torque_constant_nm_per_a: f64,
    /// Terminal resistance, ohm.
    pub resistance_ohm: f64,
    /// Rotor inertia, kg m^2.
    pub rotor_inertia_kg_m2: f64,
    /// Supply (nominal) voltage, V.
    pub supply_v: f64,
    /// Table 3.1's stall torque, N m.
    pub thesis_stall_nm: f64,
    /// Table 3.1's energy added in the first stance, J.
    pub thesis_energy_j: f64,
}

impl Motor {
    /// Stall current `V / R`, A.
    pub fn stall_current_a(&self) -> f64 {
        self.supply_v / self.resistance_ohm
    }

    /// Stall torque `k_t V / R`, N m.
    pub fn stall_torque_nm(&self) -> f64 {
        self.torque_constant_nm_per_a * self.stall_current_a()
    }

    /// No-load speed `V / k_e`, rad/s.
    pub fn no_load_speed_rad_s(&self) -> f64 {
        self.supply_v / self.torque_constant_nm_per_a
    }
}

/// The design machine's motor (`Params::design`: the 80 W class of Table
/// 3.1, 2.0 N m stall at 24 V, Table 2.1's inertia for rotor and screw).
pub const DESIGN_MOTOR: Motor = Motor {
    thesis_name: "Maxon 80",
    model: "the design preset's motor (Table 2.1, 2.0 N m stall at 24 V)",
    torque_constant_nm_per_a: hopper_control::model::design::TORQUE_CONSTANT_NM_PER_A,
    resistance_ohm: hopper_control::model::design::TORQUE_CONSTANT_NM_PER_A * 24.0 / 2.0,
    rotor_inertia_kg_m2: hopper_control::model::design::ROTOR_INERTIA_KG_M2,
    supply_v: 24.0,
    thesis_stall_nm: 2.0,
    thesis_energy_j: 15.0,
};

/// Table 3.1's four motors as the table defines them: its stall torque on
/// the design motor's torque constant and 24 V (the resistance set for that
/// stall torque, so each runs on the straight line from its stall torque to
/// the design's 808 rad/s no-load speed) and Table 2.1's inertia.
pub fn table_3_1() -> [Motor; 4] {
    let at = |thesis_name: &'static str, stall_nm: f64, energy_j: f64| Motor {
        thesis_name,
        model: "Table 3.1's stall torque on the design motor's k_t and 24 V",
        resistance_ohm: DESIGN_MOTOR.torque_constant_nm_per_a * DESIGN_MOTOR.supply_v / stall_nm,
        thesis_stall_nm: stall_nm,
        thesis_energy_j: energy_j,
        ..DESIGN_MOTOR
    };
    [
        at("Maxon 100 WEC", 0.382, 1.8),
        at("Maxon 100 EC", 0.470, 1.5),
        at("Maxon 80", 2.0, 15.0),
        at("Pittman 14006", 2.0, 14.8),
    ]
}

/// Table 2.1's rotor-and-screw inertia less the Maxon RE 40's rotor: what
/// the transmission adds to a catalogue motor's rotor, kg m^2.
pub const TRANSMISSION_INERTIA_KG_M2: f64 =
    hopper_control::model::design::ROTOR_INERTIA_KG_M2 - 142.0e-7;

/// The catalogue motors found for two of Table 3.1's (docs/design.md
/// gives the sources; none was found for the two brushless Maxons): 24 V
/// windings, the rotor plus [`TRANSMISSION_INERTIA_KG_M2`].
pub const CATALOGUE: [Motor; 2] = [
    Motor {
        thesis_name: "Maxon 80",
        model: "Maxon RE 40 (148867, 24 V)",
        torque_constant_nm_per_a: 0.0302,
        resistance_ohm: 0.299,
        rotor_inertia_kg_m2: 142.0e-7 + TRANSMISSION_INERTIA_KG_M2,
        supply_v: 24.0,
        thesis_stall_nm: 2.0,
        thesis_energy_j: 15.0,
    },
    Motor {
        thesis_name: "Pittman 14006",
        model: "Pittman 14204S006 (24 V)",
        torque_constant_nm_per_a: 0.0612,
        resistance_ohm: 1.01,
        rotor_inertia_kg_m2: 260.0e-7 + TRANSMISSION_INERTIA_KG_M2,
        supply_v: 24.0,
        thesis_stall_nm: 2.0,
        thesis_energy_j: 14.8,
    },
];

/// A motor's thermal data, the two-body model of `hopper_control::thermal`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Heat {
    /// Winding resistance at 25 C the estimate heats with, ohm.
    pub winding_resistance_ohm: f64,
    /// Winding to housing, K/W.
    pub winding_to_housing_k_per_w: f64,
    /// Housing to ambient, K/W.
    pub housing_to_ambient_k_per_w: f64,
    /// Winding time constant, s.
    pub winding_time_constant_s: f64,
    /// Housing time constant, s.
    pub housing_time_constant_s: f64,
    /// The most the winding may reach, C (the firmware trips
    /// [`TRIP_BELOW_MAX_K`] below).
    pub max_winding_c: f64,
}

/// How far below a motor's largest winding temperature the firmware trips,
/// K (the stand-in's 155 C against the 150 C default).
pub const TRIP_BELOW_MAX_K: f64 = 5.0;

/// The stand-in's thermal data: the maxon RE 40, as the firmware's
/// `thermal.*` defaults hold it.
const RE40_HEAT: Heat = Heat {
    winding_resistance_ohm: p::THERMAL_RESISTANCE_OHM.default as f64,
    winding_to_housing_k_per_w: p::THERMAL_WINDING_TO_HOUSING.default as f64,
    housing_to_ambient_k_per_w: p::THERMAL_HOUSING_TO_AMBIENT.default as f64,
    winding_time_constant_s: p::THERMAL_WINDING_TAU.default as f64,
    housing_time_constant_s: p::THERMAL_HOUSING_TAU.default as f64,
    max_winding_c: p::THERMAL_TRIP.default as f64 + TRIP_BELOW_MAX_K,
};

/// The Pittman 14204's one thermal impedance (winding to ambient, 7.70 C/W,
/// the 14204 frame's sheet), split as the RE 40's winding-to-housing and
/// housing-to-ambient resistances.
const PITTMAN_TOTAL_K_PER_W: f64 = 7.70;
/// The RE 40's share of its thermal resistance that is winding to housing.
const RE40_WINDING_SHARE: f64 = RE40_HEAT.winding_to_housing_k_per_w
    / (RE40_HEAT.winding_to_housing_k_per_w + RE40_HEAT.housing_to_ambient_k_per_w);

/// A motor a run can take by name.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CatalogueMotor {
    /// Its name on the command line.
    pub name: &'static str,
    /// Electrical and mechanical data (the rotor plus the transmission).
    pub motor: Motor,
    /// Thermal data.
    pub heat: Heat,
    /// Where the figures come from, the stand-in's named as such.
    pub source: &'static str,
}

/// Every motor `--motor` takes; the first is the design preset's.
pub const MOTORS: [CatalogueMotor; 3] = [
    CatalogueMotor {
        name: "design",
        motor: DESIGN_MOTOR,
        heat: RE40_HEAT,
        source: "the design preset's motor (Table 2.1, 2.0 N m stall at 24 V); thermal data the stand-in's, the maxon RE 40's (the thesis gives none)",
    },
    CatalogueMotor {
        name: "re40",
        motor: CATALOGUE[0],
        heat: RE40_HEAT,
        source: "maxon RE 40 (148867, 24 V), its catalogue sheet, electrical and thermal",
    },
    CatalogueMotor {
        name: "pittman-14204",
        motor: CATALOGUE[1],
        heat: Heat {
            winding_resistance_ohm: 1.01,
            winding_to_housing_k_per_w: PITTMAN_TOTAL_K_PER_W * RE40_WINDING_SHARE,
            housing_to_ambient_k_per_w: PITTMAN_TOTAL_K_PER_W * (1.0 - RE40_WINDING_SHARE),
            winding_time_constant_s: RE40_HEAT.winding_time_constant_s,
            housing_time_constant_s: RE40_HEAT.housing_time_constant_s,
            max_winding_c: 155.0,
        },
        source: "Pittman 14204S006 (24 V), its sheet (electrical) and the 14204 frame's thermal impedance, 7.70 C/W, and 155 C; the split of that impedance and both time constants are the stand-in's (RE 40's): the sheet gives neither",
    },
];

/// The motor called `name`, or an error naming the choices.
pub fn named(name: &str) -> Result<&'static CatalogueMotor, String> {
    MOTORS.iter().find(|m| m.name == name).ok_or_else(|| {
        format!(
            "unknown motor `{name}`: expected one of {:?}",
            MOTORS.iter().map(|m| m.name).collect::<Vec<_>>()
        )
    })
}

impl CatalogueMotor {
    /// `params` with this motor: its torque constant, resistance, rotor
    /// (plus the transmission) and supply; the amplifier's current limit is
    /// the amplifier's and stays.
    pub fn on(&self, params: &Params) -> Params {
        Params {
            torque_constant_nm_per_a: self.motor.torque_constant_nm_per_a,
            winding_resistance_ohm: self.motor.resistance_ohm,
            rotor_inertia_kg_m2: self.motor.rotor_inertia_kg_m2,
            supply_voltage_v: self.motor.supply_v,
            ..*params
        }
    }

    /// `params` with this motor, and `own` firmware settings after the
    /// motor's (so they win): how a run takes a motor ([`Self::on`],
    /// [`Self::firmware_settings`]).
    pub fn apply(
        &self,
        params: &Params,
        own: Vec<(&'static p::Param, f32)>,
    ) -> (Params, Vec<(&'static p::Param, f32)>) {
        let mut set = self.firmware_settings();
        set.extend(own);
        (self.on(params), set)
    }

    /// The firmware's `thermal.*` parameters for this motor.
    pub fn firmware_settings(&self) -> Vec<(&'static p::Param, f32)> {
        let h = &self.heat;
        vec![
            (&p::THERMAL_RESISTANCE_OHM, h.winding_resistance_ohm as f32),
            (
                &p::THERMAL_WINDING_TO_HOUSING,
                h.winding_to_housing_k_per_w as f32,
            ),
            (
                &p::THERMAL_HOUSING_TO_AMBIENT,
                h.housing_to_ambient_k_per_w as f32,
            ),
            (&p::THERMAL_WINDING_TAU, h.winding_time_constant_s as f32),
            (&p::THERMAL_HOUSING_TAU, h.housing_time_constant_s as f32),
            (
                &p::THERMAL_TRIP,
                (h.max_winding_c - TRIP_BELOW_MAX_K) as f32,
            ),
        ]
    }

    /// The firmware's thermal configuration with this motor's data (the
    /// other `thermal.*` parameters at their defaults).
    pub fn thermal_config(&self) -> hopper_control::thermal::ThermalConfig {
        let h = &self.heat;
        hopper_control::thermal::ThermalConfig {
            winding_resistance_ohm: h.winding_resistance_ohm as f32,
            winding_to_housing_k_per_w: h.winding_to_housing_k_per_w as f32,
            housing_to_ambient_k_per_w: h.housing_to_ambient_k_per_w as f32,
            winding_time_constant_s: h.winding_time_constant_s as f32,
            housing_time_constant_s: h.housing_time_constant_s as f32,
            trip_winding_c: (h.max_winding_c - TRIP_BELOW_MAX_K) as f32,
            ..Default::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_design_motor_is_the_design_preset_and_the_firmware_defaults() {
        let d = Params::design();
        assert_eq!(MOTORS[0].on(&d), d);
        for (param, value) in MOTORS[0].firmware_settings() {
            assert_eq!(value, param.default, "{}", param.name);
        }
        assert_eq!(
            MOTORS[0].thermal_config(),
            hopper_control::thermal::ThermalConfig::default()
        );
    }

    #[test]
    fn every_motor_is_a_valid_plant_and_firmware_configuration() {
        for m in &MOTORS {
            let params = m.on(&Params::design());
            params
                .validate()
                .unwrap_or_else(|e| panic!("{}: {e}", m.name));
            for (param, value) in m.firmware_settings() {
                assert!(
                    (param.min..=param.max).contains(&value),
                    "{} {}",
                    m.name,
                    param.name
                );
            }
            m.thermal_config()
                .validate()
                .unwrap_or_else(|e| panic!("{}: {e:?}", m.name));
        }
        // The Pittman's rating: 3.3 A against the stand-in's 6.5 A.
        let c = MOTORS[2].thermal_config().continuous_current_a();
        assert!((c - 3.3).abs() < 0.05, "{c}");
        assert!(named("re40").is_ok());
        let e = named("maxon").unwrap_err();
        assert!(e.contains("pittman-14204"), "{e}");
    }
}
