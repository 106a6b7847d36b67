//! One name per quantity, and every other name the host tools accept for
//! it, in one table.
//!
//! A quantity's name is the firmware table's for the firmware's parameters
//! ([`hopper_control::params`], what `--set`, a scenario's `[params]`, the
//! link and docs/parameters.md use), the plant's field for the machine's
//! ([`crate::params::FIELDS`]), and the run's own for the two settings
//! that are neither (`start_apex_m`, `noise_seed`). Older names are
//! contracts (scripts and scenario files use them): a run flag and its
//! scenario key for the settings that have one, a sweep axis's short name
//! and its CSV column. They are all here, as aliases of that one name;
//! [`crate::scenario::Dedicated`] (which settings have a flag of their
//! own) and the sweep's axes (`hopper_study::sweep::Knob`) read them from here.
//! The flags and keys themselves are clap's and serde's (literals in
//! `hopper-sim` and `scenario.rs`); tests check that each one named here
//! exists.

/// A quantity's other names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Alias {
    /// The quantity's names in the firmware table or the plant's fields:
    /// the first is the one reported; more than one when a setting sets
    /// several (the open-loop torque of `open-torque` and
    /// `modified-torque`).
    pub names: &'static [&'static str],
    /// `hopper-sim run`'s flag that sets it (then `--set` refuses it).
    pub flag: Option<&'static str>,
    /// The scenario file's key that sets it (with the flag).
    pub key: Option<&'static str>,
    /// A sweep axis's short name (`--param NAME=...`).
    pub short: Option<&'static str>,
    /// The sweep's CSV column (default: the name).
    pub column: Option<&'static str>,
}

impl Alias {
    /// The name it is reported under.
    pub fn name(&self) -> &'static str {
        self.names[0]
    }

    /// `--flag / scenario.key`, where a setting with a flag of its own is
    /// set.
    pub fn setter(&self) -> Option<String> {
        Some(format!("{} / {}", self.flag?, self.key?))
    }
}

/// Every alias, in the order the sweep's error message lists the short
/// names (settings first, then the plant's thesis symbols).
pub const ALIASES: &[Alias] = &[
    Alias {
        names: &["controller"],
        flag: Some("--controller"),
        key: Some("controller.name"),
        short: None,
        column: None,
    },
    Alias {
        names: &["constant_torque.torque_nm", "modified_torque.torque_nm"],
        flag: Some("--torque"),
        key: Some("controller.torque_nm"),
        short: Some("torque"),
        column: Some("torque_nm"),
    },
    Alias {
        names: &["target_apex_m"],
        flag: Some("--target-apex"),
        key: Some("controller.target_apex_m"),
        short: Some("target_apex"),
        column: None,
    },
    Alias {
        names: &["start_apex_m"],
        flag: Some("--start-apex"),
        key: Some("start_apex_m"),
        short: Some("start_apex"),
        column: None,
    },
    Alias {
        names: &["energy.gain_nm_per_j", "energy_apex.gain_nm_per_j"],
        flag: Some("--ke"),
        key: Some("controller.energy_gain_nm_per_j"),
        short: Some("ke"),
        column: Some("energy_gain_nm_per_j"),
    },
    Alias {
        names: &["flight.kp_a_per_rad"],
        flag: Some("--flight-kp"),
        key: Some("controller.flight_kp_a_per_rad"),
        short: Some("flight_kp"),
        column: Some("flight_kp_a_per_rad"),
    },
    Alias {
        names: &["flight.kd_a_s_per_rad"],
        flag: Some("--flight-kd"),
        key: Some("controller.flight_kd_a_s_per_rad"),
        short: Some("flight_kd"),
        column: Some("flight_kd_a_s_per_rad"),
    },
    Alias {
        names: &["noise_seed"],
        flag: Some("--seed"),
        key: Some("sensors.seed"),
        short: Some("seed"),
        column: None,
    },
    shaped(
        &["shaped.spin_up_fraction"],
        "spin_up",
        "shaped_spin_up_fraction",
    ),
    shaped(
        &["shaped.switch_fraction"],
        "switch",
        "shaped_switch_fraction",
    ),
    shaped(&["shaped.brake_fraction"], "brake", "shaped_brake_fraction"),
    shaped(
        &["shaped.level_gain_per_j"],
        "level_ki",
        "shaped_level_gain_per_j",
    ),
    shaped(
        &["shaped.level_proportional_per_j"],
        "level_kp",
        "shaped_level_proportional_per_j",
    ),
    shaped(
        &["shaped.braking_margin"],
        "braking_margin",
        "shaped_braking_margin",
    ),
    shaped(
        &["shaped.integral_start"],
        "integral_start",
        "shaped_integral_start",
    ),
    // The thesis's symbols for the leg spring (section 2.2) and the ball
    // screw's lead (Table 2.1), so `--param k=8000:20000:13` works as
    // written.
    plant(&["spring_stiffness_n_per_m"], "k"),
    plant(&["spring_damping_ns_per_m"], "c"),
    plant(&["screw_lead_m"], "lead"),
];

/// A `shaped` constant's sweep names.
const fn shaped(
    names: &'static [&'static str],
    short: &'static str,
    column: &'static str,
) -> Alias {
    Alias {
        names,
        flag: None,
        key: None,
        short: Some(short),
        column: Some(column),
    }
}

/// A plant field's short name.
const fn plant(names: &'static [&'static str], short: &'static str) -> Alias {
    Alias {
        names,
        flag: None,
        key: None,
        short: Some(short),
        column: None,
    }
}

/// The alias entry of the quantity named `name` (any of its names).
pub fn of(name: &str) -> Option<&'static Alias> {
    ALIASES.iter().find(|a| a.names.contains(&name))
}

/// The one name of whatever a sweep axis calls `name`: its short name or
/// its column resolved, any other name unchanged.
pub fn resolve(name: &str) -> &str {
    ALIASES
        .iter()
        .find(|a| a.short == Some(name) || a.column == Some(name))
        .map_or(name, |a| a.name())
}

/// The sweep CSV column of the quantity named `name`.
pub fn column(name: &'static str) -> &'static str {
    of(name).and_then(|a| a.column).unwrap_or(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_is_the_tables_the_plants_or_the_runs() {
        for a in ALIASES {
            for n in a.names {
                let known = hopper_control::params::find(n).is_some()
                    || crate::params::field(n).is_some()
                    || ["start_apex_m", "noise_seed"].contains(n);
                assert!(known, "{n} is no quantity's name");
            }
        }
    }

    #[test]
    fn no_alias_names_two_quantities() {
        let mut owner = std::collections::HashMap::new();
        for (i, a) in ALIASES.iter().enumerate() {
            let all = a.names.iter().copied().chain(a.short).chain(a.column);
            for n in all.chain(a.flag).chain(a.key) {
                let first = *owner.entry(n).or_insert(i);
                assert_eq!(first, i, "{n} names two quantities");
            }
        }
    }
}
