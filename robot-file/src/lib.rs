//! A robot file: one machine described by the firmware parameter table's
//! own names (docs/parameters.md), as TOML.
//!
//! ```toml
//! [model]
//! body_mass_kg = 12.0
//! spring_stiffness_n_per_m = 15000.0
//!
//! [calibration]
//! motor_counts_per_rev = 2000
//! motor_counts_positive_down = true
//!
//! [supervisor]
//! spring_rate_n_per_m = 15000.0
//!
//! [plant]                  # the simulator's alone: what the firmware
//! leg_friction_n = 5.0     # does not model (friction, damping, supply)
//! ```
//!
//! Its entries are exactly what the firmware saves to flash with its
//! calibration ([`hopper_control::persist::SAVED`]): the machine's
//! constants (`model.*`), the sensors' and the DAC's calibration and the
//! spring the bench measured. An entry left out keeps its value. Reading a
//! file checks every value (a name of the table, a number in its range,
//! whole for counts) before any is used, and a refusal names the file,
//! the line, the entry and its range. `[plant]` is read by the simulator
//! (`hopper-sim --robot`), which takes the machine's constants for its plant
//! too; a robot ignores it.

use hopper_control::hopper::HopperConfig;
use hopper_control::params::{self, Kind, Param};
use hopper_control::persist::SAVED;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// The sections whose keys are the table's (`model.body_mass_kg` is
/// `body_mass_kg` in `[model]`).
const TABLE_SECTIONS: [&str; 3] = ["model", "calibration", "supervisor"];

/// The simulator's own section.
pub const PLANT: &str = "plant";

/// A robot file could not be used: where, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotFileError {
    /// `file:line`, or the file.
    pub location: String,
    /// What is wrong, naming the entry and its range.
    pub message: String,
}

impl std::fmt::Display for RobotFileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.location, self.message)
    }
}

impl std::error::Error for RobotFileError {}

/// A robot file, read and checked.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Robot {
    /// The table's entries the file gives, in the firmware's saved order
    /// (the model first: an entry that follows it and is set apart comes
    /// after it).
    pub values: Vec<(&'static Param, f32)>,
    /// The `[plant]` section, for the simulator: each key, its value and
    /// its line.
    pub plant: Vec<(String, toml::Value, Option<usize>)>,
}

impl Robot {
    /// The value the file gives entry `name`, if it does.
    pub fn get(&self, name: &str) -> Option<f32> {
        self.values
            .iter()
            .find_map(|(p, v)| (p.name == name).then_some(*v))
    }

    /// `cfg` with every entry of the file set (the model's first, so what
    /// follows from it follows, [`HopperConfig::follow_model`]).
    pub fn apply(&self, cfg: &mut HopperConfig) -> Result<(), String> {
        for (p, v) in &self.values {
            params::write(cfg, p, *v).map_err(|e| format!("{}: {e:?}", p.name))?;
        }
        Ok(())
    }
}

/// The entries a robot file holds, in its order.
pub fn entries() -> &'static [&'static Param] {
    &SAVED
}

/// The robot file's values of configuration `cfg`.
pub fn of_config(cfg: &HopperConfig) -> Vec<(&'static Param, f32)> {
    let mut c = *cfg;
    SAVED
        .iter()
        .filter_map(|p| params::read(&mut c, p).ok().map(|v| (*p, v)))
        .collect()
}

/// One number as the table prints its bounds (large ones in exponent form).
fn number(v: f32) -> String {
    if v.abs() >= 1e7 {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// `p`'s allowed values, with the unit: `0.1 ..= 1000 kg`, `0 or 1`, or
/// `a whole number in 1 ..= 1000000 counts`.
pub fn range_text(p: &Param) -> String {
    let unit = match p.unit {
        "-" | "1" => String::new(),
        u => format!(" {u}"),
    };
    match p.kind {
        Kind::Flag => "true or false (1 or 0)".to_string(),
        Kind::Choice(names) => names.join(", "),
        Kind::Count => format!(
            "a whole number in {} ..= {}{unit}",
            number(p.min),
            number(p.max)
        ),
        Kind::Real => format!("{} ..= {}{unit}", number(p.min), number(p.max)),
    }
}

/// One value as a robot file writes it: a flag as a boolean, a count
/// whole, a real number in its shortest form that reads back exactly.
fn value_text(p: &Param, v: f32) -> String {
    match p.kind {
        Kind::Flag => (v != 0.0).to_string(),
        Kind::Count | Kind::Choice(_) => format!("{}", v as i64),
        // `{:?}` of an f32 is its shortest exact form, with a `.0` on a
        // whole number: TOML reads it as that float.
        Kind::Real => format!("{v:?}"),
    }
}

/// `values` as a commented robot file titled `title`; `plant`, when given,
/// is the simulator's `[plant]` section (its lines as they are).
pub fn to_toml(values: &[(&Param, f32)], title: &str, plant: Option<&str>) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "# A hopper robot: {title}");
    let _ = writeln!(
        out,
        "# The machine's constants and its sensors' calibration, by their names in the\n\
         # firmware's parameter table (docs/parameters.md). `hopper-sim run --robot FILE`\n\
         # simulates it; `hopper-link robot load FILE` gives it to a robot (disarmed), and\n\
         # `hopper-link save` keeps it there. An entry left out keeps its value."
    );
    let mut section = "";
    for (p, v) in values {
        let Some((head, key)) = p.name.split_once('.') else {
            continue;
        };
        if head != section {
            section = head;
            let _ = writeln!(out, "\n[{head}]");
        }
        let _ = writeln!(out, "# {} Allowed: {}.", p.doc, range_text(p));
        let _ = writeln!(out, "{key} = {}", value_text(p, *v));
    }
    if let Some(plant) = plant {
        let _ = writeln!(out, "\n[{PLANT}]");
        out.push_str(plant);
    }
    out
}

/// The line of byte `offset` in `text` (1-based).
fn line_of(text: &str, offset: usize) -> usize {
    text.get(..offset.min(text.len()))
        .unwrap_or_default()
        .matches('\n')
        .count()
        + 1
}

/// Reads the robot file at `path`.
pub fn load(path: &Path) -> Result<Robot, RobotFileError> {
    let origin = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| RobotFileError {
        location: origin.clone(),
        message: format!("cannot read the robot file: {e}"),
    })?;
    parse(&text, &origin)
}

/// Reads a robot file's `text`; `origin` names it in errors. Every value is
/// checked before the file is accepted: nothing of a refused file is used.
pub fn parse(text: &str, origin: &str) -> Result<Robot, RobotFileError> {
    let err = |line: Option<usize>, message: String| RobotFileError {
        location: match line {
            Some(l) => format!("{origin}:{l}"),
            None => origin.to_string(),
        },
        message,
    };
    let table: toml::Table = toml::from_str(text).map_err(|e| {
        let line = e.span().map(|s| line_of(text, s.start));
        err(line, format!("malformed TOML: {}", e.message()))
    })?;
    // The same text again with each value's place, for the lines of the
    // messages (the structure is checked on `table` below).
    type Spans = BTreeMap<String, BTreeMap<String, toml::Spanned<toml::Value>>>;
    let spans: Option<Spans> = toml::from_str(text).ok();
    let line = |section: &str, key: &str| {
        spans
            .as_ref()
            .and_then(|s| s.get(section)?.get(key))
            .map(|v| line_of(text, v.span().start))
    };
    let mut robot = Robot::default();
    let mut given: BTreeMap<&'static str, f32> = BTreeMap::new();
    for (section, body) in &table {
        let known = TABLE_SECTIONS.contains(&section.as_str()) || section == PLANT;
        let Some(body) = body.as_table().filter(|_| known) else {
            return Err(err(
                None,
                format!(
                    "`{section}` is not a section of a robot file: expected [{}] and [{PLANT}]",
                    TABLE_SECTIONS.join("], [")
                ),
            ));
        };
        if section == PLANT {
            for (key, value) in body {
                robot
                    .plant
                    .push((key.clone(), value.clone(), line(section, key)));
            }
            continue;
        }
        for (key, value) in body {
            let name = format!("{section}.{key}");
            let at = line(section, key);
            let Some(p) = SAVED.iter().copied().find(|p| p.name == name) else {
                let message = match params::find(&name) {
                    Some(_) => format!(
                        "`{name}` is a setting, not one of the machine's constants: set it with `hopper-link params set` (or `hopper-sim --set`)"
                    ),
                    None => format!(
                        "unknown entry `{name}` (a robot file holds: {}; `hopper-sim params show design` writes one)",
                        SAVED.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
                    ),
                };
                return Err(err(at, message));
            };
            let v = match (value, p.kind) {
                (toml::Value::Boolean(b), Kind::Flag) => f32::from(u8::from(*b)),
                (toml::Value::Integer(i), _) => *i as f32,
                (toml::Value::Float(f), _) => *f as f32,
                (other, _) => {
                    return Err(err(
                        at,
                        format!(
                            "`{name}` must be {}, got {other}",
                            match p.kind {
                                Kind::Flag => "true or false",
                                _ => "a number",
                            }
                        ),
                    ))
                }
            };
            if p.check(v).is_err() {
                return Err(err(
                    at,
                    format!(
                        "`{name} = {value}` is out of range: allowed {}",
                        range_text(p)
                    ),
                ));
            }
            given.insert(p.name, v);
        }
    }
    robot.values = SAVED
        .iter()
        .filter_map(|p| given.get(p.name).map(|v| (*p, *v)))
        .collect();
    // Each value in its range may still not be a machine the controller
    // takes together (a stroke the flight law's start lies beyond, say):
    // the file's machine is built as the firmware would build it.
    let mut cfg = HopperConfig::default();
    robot.apply(&mut cfg).map_err(|e| err(None, e))?;
    hopper_control::hopper::Hopper::new(cfg).map_err(|e| {
        err(
            None,
            format!("its values together are not a machine the controller takes: {e:?}"),
        )
    })?;
    Ok(robot)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_design_machine_round_trips() {
        let cfg = HopperConfig::default();
        let values = of_config(&cfg);
        assert_eq!(values.len(), SAVED.len());
        let text = to_toml(&values, "design", None);
        assert!(text.contains("[model]\n") && text.contains("body_mass_kg = 9.0\n"));
        assert!(
            text.contains("motor_counts_positive_down = true\n"),
            "{text}"
        );
        assert!(text.contains("motor_counts_per_rev = 2000\n"), "{text}");
        let back = parse(&text, "r.toml").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back.values, values);
        let mut c = HopperConfig::default();
        assert_eq!(back.apply(&mut c), Ok(()));
        assert_eq!(c, cfg);
    }

    #[test]
    fn another_machine_is_every_entry_it_gives() {
        let text = "[model]\nbody_mass_kg = 12\nspring_stiffness_n_per_m = 15000.0\n\n[plant]\nleg_friction_n = 6.5\n";
        let r = parse(text, "r.toml").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(r.get("model.body_mass_kg"), Some(12.0));
        assert_eq!(r.values.len(), 2);
        assert_eq!(r.plant.len(), 1);
        assert_eq!(r.plant[0].2, Some(6));
        let mut c = HopperConfig::default();
        assert_eq!(r.apply(&mut c), Ok(()));
        assert_eq!(c.supervisor.spring_rate_n_per_m, 15_000.0, "follows");
    }

    #[test]
    fn a_bad_file_is_refused_naming_the_entry_and_its_range() {
        let e = parse("[model]\n\nbody_mass_kg = 0.0\n", "r.toml").unwrap_err();
        assert_eq!(e.location, "r.toml:3");
        assert!(
            e.message
                .contains("`model.body_mass_kg = 0.0` is out of range: allowed 0.1 ..= 1000 kg"),
            "{e}"
        );
        let e = parse("[model]\nbody_mas_kg = 3\n", "r.toml").unwrap_err();
        assert!(
            e.message.contains("unknown entry `model.body_mas_kg`"),
            "{e}"
        );
        assert_eq!(e.location, "r.toml:2");
        let e = parse("[calibration]\nmotor_counts_per_rev = 2.5\n", "r.toml").unwrap_err();
        assert!(
            e.message.contains("a whole number in 1 ..= 1000000 counts"),
            "{e}"
        );
        let e = parse("[supervisor]\ncontact_force_n = 100\n", "r.toml").unwrap_err();
        assert!(e.message.contains("is a setting"), "{e}");
        let e = parse("[controller]\nname = 1\n", "r.toml").unwrap_err();
        assert!(e.message.contains("not a section"), "{e}");
        let e = parse("[model]\nbody_mass_kg = \"heavy\"\n", "r.toml").unwrap_err();
        assert!(e.message.contains("must be a number"), "{e}");
        let e = parse("[model\n", "r.toml").unwrap_err();
        assert!(e.message.contains("malformed TOML"), "{e}");
    }
}
