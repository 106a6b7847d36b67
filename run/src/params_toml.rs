//! Parameter sets as TOML: the printer `hopper-sim params show` uses and the
//! reader behind `--params PATH.toml`.
//!
//! A file may start from a preset (`base = "identified"`) and override any
//! field; without `base` every field must be given. Unknown keys, non-numeric
//! values and out-of-range values are errors that name the file, line and
//! field.

use crate::params::{field, Params, FIELDS};
use serde::Deserialize as _;
use std::fmt::Write as _;
use std::path::Path;

/// A parameter file could not be used.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamsFileError {
    /// Where: `file:line` (or just the file).
    pub location: String,
    /// What went wrong.
    pub message: String,
}

impl std::fmt::Display for ParamsFileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.location, self.message)
    }
}

impl std::error::Error for ParamsFileError {}

/// Render a parameter set as commented TOML that [`from_toml_str`] reads back.
pub fn to_toml(params: &Params, title: &str) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "# Vertical hopper parameters: {title}");
    let _ = writeln!(
        out,
        "# SI units throughout; each line gives the unit and the allowed range."
    );
    let _ = writeln!(
        out,
        "# Optionally start from a preset and override only some fields:\n# base = \"design\"   # or \"identified\""
    );
    for f in FIELDS.iter() {
        let _ = writeln!(
            out,
            "\n# {} [{}], allowed {}",
            f.doc,
            f.unit(),
            f.range.without_unit()
        );
        let _ = writeln!(out, "{} = {:?}", f.name, (f.get)(params));
    }
    out
}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

/// Parse a parameter file's text. `origin` names it in errors.
pub fn from_toml_str(text: &str, origin: &str) -> Result<Params, ParamsFileError> {
    let err = |line: Option<usize>, message: String| ParamsFileError {
        location: match line {
            Some(l) => format!("{origin}:{l}"),
            None => origin.to_string(),
        },
        message,
    };
    let table: toml::Spanned<toml::Table> = toml::from_str(text).map_err(|e| {
        let line = e.span().map(|s| line_of(text, s.start));
        err(line, format!("malformed TOML: {}", e.message()))
    })?;
    // Spans per key: re-parse keys as spanned values.
    let spanned: std::collections::BTreeMap<String, toml::Spanned<toml::Value>> =
        toml::from_str(text).map_err(|e| err(None, format!("malformed TOML: {}", e.message())))?;
    let line_for = |key: &str| spanned.get(key).map(|v| line_of(text, v.span().start));

    params_from_table(&table.into_inner(), origin, "", &line_for)
}

/// Build a parameter set from a parsed TOML table with the rules of a
/// parameter file (`base`, no unknown keys, numbers in range, every field
/// without `base`). `section` prefixes key names in messages (`"plant."` for
/// a table inside a scenario file); `line_for` gives a key's line in the file.
pub fn params_from_table(
    table: &toml::Table,
    origin: &str,
    section: &str,
    line_for: &dyn Fn(&str) -> Option<usize>,
) -> Result<Params, ParamsFileError> {
    let err = |line: Option<usize>, message: String| ParamsFileError {
        location: match line {
            Some(l) => format!("{origin}:{l}"),
            None => origin.to_string(),
        },
        message,
    };
    let params = match table.get("base") {
        None => None,
        Some(toml::Value::String(name)) => Some(Params::preset(name).ok_or_else(|| {
            err(
                line_for("base"),
                format!(
                    "unknown preset `{section}base = \"{name}\"`: expected one of {:?}",
                    Params::PRESET_NAMES
                ),
            )
        })?),
        Some(other) => {
            return Err(err(
                line_for("base"),
                format!("`{section}base` must be a preset name string, got {other}"),
            ))
        }
    };
    // The file's fields over the preset's (or over nothing: then serde's
    // missing-field check asks for every one), read by serde into `Params`,
    // which refuses unknown fields and non-numbers.
    let mut merged = match &params {
        Some(base) => {
            toml::Table::try_from(base).map_err(|e| err(None, format!("preset as TOML: {e}")))?
        }
        None => toml::Table::new(),
    };
    for (key, value) in table.iter().filter(|(k, _)| k.as_str() != "base") {
        merged.insert(key.clone(), value.clone());
    }
    let p = Params::deserialize(toml::Value::Table(merged)).map_err(|e| {
        let message = e.message();
        // The key serde names: `unknown field `K``, `missing field `K``, or
        // the value's key after "in" in the full text.
        let quoted = |m: &str| m.split('`').nth(1).map(str::to_string);
        let full = e.to_string();
        if message.starts_with("unknown field") {
            let key = quoted(message).unwrap_or_default();
            return err(
                line_for(&key),
                format!("unknown parameter `{section}{key}` (see `hopper-sim params show design` for the fields)"),
            );
        }
        if message.starts_with("missing field") {
            let key = quoted(message).unwrap_or_default();
            let unit = field(&key).map_or("", |f| f.unit());
            return err(
                None,
                format!(
                    "missing parameter `{section}{key}` [{unit}] (give every field, or start from a preset with `base = \"design\"`)"
                ),
            );
        }
        let key = full
            .rsplit_once("in `")
            .and_then(|(_, k)| k.split('`').next())
            .unwrap_or_default()
            .to_string();
        let unit = field(&key).map_or("its unit", |f| f.unit());
        let got = message
            .trim_start_matches("invalid type: ")
            .split(", expected")
            .next()
            .unwrap_or(message);
        err(
            line_for(&key),
            format!("parameter `{section}{key}` must be a number in {unit}, got {got}"),
        )
    })?;
    // Each field the file gives, against its range, at its line.
    for (key, _) in table.iter().filter(|(k, _)| k.as_str() != "base") {
        if let Some(spec) = field(key) {
            let v = (spec.get)(&p);
            if !spec.allows(v) {
                return Err(err(
                    line_for(key),
                    format!(
                        "parameter `{section}{key}` = {v} is out of range: allowed {}",
                        spec.range
                    ),
                ));
            }
        }
    }
    p.validate().map_err(|e| {
        let table = section.trim_end_matches('.');
        let within = if table.is_empty() {
            String::new()
        } else {
            format!(" (in table `{table}`)")
        };
        err(line_for(e.field), format!("{e}{within}"))
    })?;
    Ok(p)
}

/// A plant parameter set as given: the values, the name runs report them
/// under (the preset or the file), and the preset they start from (the
/// preset itself, or a file's `base`), whose machine brings its own
/// controller defaults ([`Params::preset_flight_gains`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PlantSet {
    /// The parameter values.
    pub params: Params,
    /// Name reported in summaries.
    pub name: String,
    /// The preset the set starts from, if any.
    pub preset: Option<&'static str>,
}

impl PlantSet {
    /// A preset by name.
    pub fn preset(name: &str) -> Option<PlantSet> {
        let preset = Params::preset_name(name)?;
        Some(PlantSet {
            params: Params::preset(preset)?,
            name: preset.to_string(),
            preset: Some(preset),
        })
    }
}

/// The preset a parameter table starts from (`base = "NAME"`), if a known one.
pub fn base_of(table: &toml::Table) -> Option<&'static str> {
    table
        .get("base")
        .and_then(toml::Value::as_str)
        .and_then(Params::preset_name)
}

/// Resolve `--params`: a preset name or a path to a TOML file.
pub fn load(spec: &str) -> Result<PlantSet, ParamsFileError> {
    load_as(spec, "--params")
}

/// [`load`] for the command-line flag `flag` (named in the error for an
/// unknown preset; file errors name the file).
pub fn load_as(spec: &str, flag: &str) -> Result<PlantSet, ParamsFileError> {
    if let Some(set) = PlantSet::preset(spec) {
        return Ok(set);
    }
    let path = Path::new(spec);
    let looks_like_file = spec.ends_with(".toml") || spec.contains('/') || path.exists();
    if !looks_like_file {
        return Err(ParamsFileError {
            location: flag.into(),
            message: format!(
                "unknown preset `{spec}`: expected one of {:?} or a path to a .toml file",
                Params::PRESET_NAMES
            ),
        });
    }
    let text = std::fs::read_to_string(path).map_err(|e| ParamsFileError {
        location: spec.to_string(),
        message: format!("cannot read parameter file: {e}"),
    })?;
    if is_robot_file(&text) {
        let robot = hopper_robot_file::parse(&text, spec).map_err(|e| ParamsFileError {
            location: e.location,
            message: e.message,
        })?;
        return plant_from_robot(&robot, spec);
    }
    let params = from_toml_str(&text, spec)?;
    // Parsed already, so this cannot fail; only the `base` is wanted.
    let preset = toml::from_str::<toml::Table>(&text)
        .ok()
        .and_then(|t| base_of(&t));
    Ok(PlantSet {
        params,
        name: spec.to_string(),
        preset,
    })
}

/// The plant's fields that are the machine's constants, each with its
/// `model.*` entry in a robot file; the plant's other fields (friction,
/// damping, the winding and the supply) are the simulator's alone, in a
/// robot file's `[plant]` section.
pub const FROM_MODEL: [(&str, &str); 13] = [
    ("body_mass_kg", "model.body_mass_kg"),
    ("unsprung_mass_kg", "model.unsprung_mass_kg"),
    ("nut_mass_kg", "model.nut_mass_kg"),
    ("rotor_inertia_kg_m2", "model.rotor_inertia_kg_m2"),
    ("screw_lead_m", "model.screw_lead_m"),
    ("spring_stiffness_n_per_m", "model.spring_stiffness_n_per_m"),
    ("spring_preload_m", "model.preload_m"),
    ("leg_length_m", "model.leg_length_m"),
    ("efficiency", "model.efficiency"),
    ("stroke_m", "model.stroke_m"),
    ("gravity_mps2", "model.gravity_mps2"),
    ("torque_constant_nm_per_a", "model.torque_constant_nm_per_a"),
    ("current_limit_a", "model.current_limit_a"),
];

/// The `model.*` entry a plant field is, if it is one.
fn model_entry(plant_field: &str) -> Option<&'static str> {
    FROM_MODEL
        .iter()
        .find_map(|(f, m)| (*f == plant_field).then_some(*m))
}

/// Preset `name` as a robot file (`hopper-sim params show`): the
/// firmware's entries for the machine (its model, the default calibration,
/// the spring the supervisor checks) and the plant's own fields in
/// `[plant]`. `--params` and `--robot` read it back as this plant.
pub fn robot_toml(params: &Params, name: &str) -> String {
    let cfg = hopper_sil::sim_io::firmware_config(
        params,
        params,
        hopper_control::hopper::Strategy::default(),
        0.05,
        0.0,
    );
    let mut plant = String::new();
    for f in FIELDS.iter().filter(|f| model_entry(f.name).is_none()) {
        let _ = writeln!(
            plant,
            "# {} [{}], allowed {}\n{} = {:?}",
            f.doc,
            f.unit(),
            f.range.without_unit(),
            f.name,
            (f.get)(params)
        );
    }
    // The supervisor's spring is the model's here: left out, it follows
    // the model's spring when the file's is edited (a bench-measured one
    // is added under [supervisor]).
    let values: Vec<_> = hopper_robot_file::of_config(&cfg)
        .into_iter()
        .filter(|(p, _)| !p.name.starts_with("supervisor."))
        .collect();
    hopper_robot_file::to_toml(
        &values,
        &format!("the {name} preset (hopper-sim params show {name})"),
        Some(&plant),
    )
}

/// The plant a robot file describes: its `[plant]` section's `base`
/// preset (design when none) with the machine's constants from `[model]`
/// and the plant's own fields from `[plant]`, each checked against its
/// range.
pub fn plant_from_robot(
    robot: &hopper_robot_file::Robot,
    origin: &str,
) -> Result<PlantSet, ParamsFileError> {
    let err = |line: Option<usize>, message: String| ParamsFileError {
        location: match line {
            Some(l) => format!("{origin}:{l}"),
            None => origin.to_string(),
        },
        message,
    };
    let base = robot.plant.iter().find(|(k, _, _)| k == "base");
    let preset = match base {
        None => None,
        Some((_, toml::Value::String(name), line)) => {
            Some(Params::preset_name(name).ok_or_else(|| {
                err(
                    *line,
                    format!(
                        "unknown preset `plant.base = \"{name}\"`: expected one of {:?}",
                        Params::PRESET_NAMES
                    ),
                )
            })?)
        }
        Some((_, other, line)) => {
            return Err(err(
                *line,
                format!("`plant.base` must be a preset name string, got {other}"),
            ))
        }
    };
    let mut p = Params::preset(preset.unwrap_or(DESIGN)).unwrap_or_else(Params::design);
    for (field_name, entry) in FROM_MODEL {
        if let (Some(v), Some(f)) = (robot.get(entry), field(field_name)) {
            // The decimal the file wrote (the f32's shortest form), not the
            // f32's binary value: `0.6` is 0.6 to the plant.
            (f.set)(&mut p, v.to_string().parse().unwrap_or(f64::from(v)));
        }
    }
    for (key, value, line) in robot.plant.iter().filter(|(k, _, _)| k != "base") {
        if let Some(entry) = model_entry(key) {
            return Err(err(
                *line,
                format!("`plant.{key}` is one of the machine's constants: give it as `{entry}` in [model], which the firmware reads too"),
            ));
        }
        let f = field(key).ok_or_else(|| {
            err(
                *line,
                format!("unknown parameter `plant.{key}` (see `hopper-sim params show design` for the fields)"),
            )
        })?;
        let v = value
            .as_float()
            .or_else(|| value.as_integer().map(|i| i as f64))
            .ok_or_else(|| {
                err(
                    *line,
                    format!(
                        "parameter `plant.{key}` must be a number in {}, got {value}",
                        f.unit()
                    ),
                )
            })?;
        if !f.allows(v) {
            return Err(err(
                *line,
                format!(
                    "parameter `plant.{key}` = {v} is out of range: allowed {}",
                    f.range
                ),
            ));
        }
        (f.set)(&mut p, v);
    }
    p.validate().map_err(|e| err(None, e.to_string()))?;
    Ok(PlantSet {
        params: p,
        name: origin.to_string(),
        preset,
    })
}

/// The preset a robot file's plant starts from when it names none.
const DESIGN: &str = "design";

/// Whether TOML `text` is a robot file (it has a `[model]`,
/// `[calibration]` or `[supervisor]` section) rather than a plant
/// parameter file.
pub fn is_robot_file(text: &str) -> bool {
    toml::from_str::<toml::Table>(text).is_ok_and(|t| {
        ["model", "calibration", "supervisor"]
            .iter()
            .any(|s| t.get(*s).is_some_and(toml::Value::is_table))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_round_trip_through_toml() {
        for name in Params::PRESET_NAMES {
            let p = Params::preset(name).unwrap();
            let text = to_toml(&p, name);
            assert!(text.contains("[kg]") && text.contains("[N/m]"));
            assert_eq!(from_toml_str(&text, "x.toml").unwrap(), p);
        }
    }

    #[test]
    fn base_and_override() {
        let p = from_toml_str("base = \"identified\"\nbody_mass_kg = 10\n", "f.toml").unwrap();
        assert_eq!(p.body_mass_kg, 10.0);
        assert_eq!(p.planarizer_friction_n, 13.0);
    }

    #[test]
    fn errors_name_file_line_and_field() {
        let e = from_toml_str("base = \"design\"\n\nbody_mass_kg = -3.0\n", "f.toml").unwrap_err();
        assert_eq!(e.location, "f.toml:3");
        assert!(
            e.message.contains("body_mass_kg") && e.message.contains("-3"),
            "{e}"
        );

        let e = from_toml_str("base = \"design\"\nbody_mas_kg = 3.0\n", "f.toml").unwrap_err();
        assert_eq!(e.location, "f.toml:2");
        assert!(e.message.contains("unknown parameter `body_mas_kg`"), "{e}");

        let e = from_toml_str("base = \"design\"\nbody_mass_kg = [1\n", "f.toml").unwrap_err();
        assert!(e.message.contains("malformed TOML"), "{e}");
        assert!(e.location.starts_with("f.toml:"), "{e}");

        let e = from_toml_str("body_mass_kg = 3.0\n", "f.toml").unwrap_err();
        assert!(e.message.contains("missing parameter"), "{e}");

        let e = from_toml_str("base = \"moon\"\n", "f.toml").unwrap_err();
        assert!(e.message.contains("unknown preset"), "{e}");

        let e = from_toml_str("base = \"design\"\nstroke_m = \"long\"\n", "f.toml").unwrap_err();
        assert!(e.message.contains("must be a number"), "{e}");
    }

    #[test]
    fn load_rejects_unknown_preset() {
        let e = load("designn").unwrap_err();
        assert!(e.message.contains("unknown preset `designn`"));
    }
}
