//! The trajectory sample the plots draw: what the simulator records
//! (`hal_sim::run`) and what `hopper-link` makes of the robot's telemetry.

use serde::Serialize;

/// Contact phase of a sample: the plant's contact mode
/// (`hopper_plant::Mode`, which the simulator converts from) without the
/// plant behind it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Toe off the ground.
    Flight,
    /// Toe on the ground, leg compressed.
    Stance,
    /// Toe on the ground, body resting on the fully extended leg.
    Standing,
}

impl Phase {
    /// Short lower-case name, as in CSV and JSON output (the plant mode's
    /// name).
    pub fn name(self) -> &'static str {
        match self {
            Phase::Flight => "flight",
            Phase::Stance => "stance",
            Phase::Standing => "standing",
        }
    }
}

/// One trajectory sample (a CSV row).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Sample {
    /// Time, s.
    pub t_s: f64,
    /// Contact mode.
    #[serde(serialize_with = "phase_name")]
    pub phase: Phase,
    /// Body coordinate `z`, m.
    pub z_m: f64,
    /// Body velocity, m/s.
    pub zd_mps: f64,
    /// Nut displacement `p`, m.
    pub p_m: f64,
    /// Nut velocity, m/s.
    pub pd_mps: f64,
    /// Toe height above ground, m.
    pub toe_height_m: f64,
    /// Spring force, N.
    pub spring_force_n: f64,
    /// Motor torque, N m.
    pub torque_nm: f64,
    /// Total mechanical energy, J.
    pub energy_j: f64,
    /// The firmware's estimate of the motor's winding temperature, C
    /// (`None` without firmware).
    pub winding_c: Option<f64>,
}

fn phase_name<S: serde::Serializer>(p: &Phase, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(p.name())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The phase serializes as its name, the fields in order.
    #[test]
    fn a_sample_serializes_its_phase_by_name() {
        let s = Sample {
            t_s: 0.5,
            phase: Phase::Stance,
            z_m: 0.6,
            zd_mps: -1.0,
            p_m: 0.01,
            pd_mps: 0.0,
            toe_height_m: 0.0,
            spring_force_n: 110.0,
            torque_nm: 0.25,
            energy_j: 60.0,
            winding_c: None,
        };
        let json = serde_json::to_string(&s).unwrap_or_default();
        assert_eq!(
            json,
            r#"{"t_s":0.5,"phase":"stance","z_m":0.6,"zd_mps":-1.0,"p_m":0.01,"pd_mps":0.0,"toe_height_m":0.0,"spring_force_n":110.0,"torque_nm":0.25,"energy_j":60.0,"winding_c":null}"#
        );
        let names = [Phase::Flight, Phase::Stance, Phase::Standing].map(Phase::name);
        assert_eq!(names, ["flight", "stance", "standing"]);
    }
}
