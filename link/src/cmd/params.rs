//! `params list`, `params get` and `params set`: the parameter table on
//! the robot, described by the robot itself.

use super::common::{get, read_param, wire_name};
use anyhow::{bail, Result};
use hopper_link::names::{self, Described};
use hopper_link::Client;
use hopper_protocol::{Request, Response};

pub(crate) fn params_list(c: &mut Client) -> Result<()> {
    let selected = selected_controller(c)?;
    let table = names::table(c)?;
    let n = table.len();
    println!(
        "{:<42} {:>14} {:<8} {:>25} {:>12}  armed",
        "name", "value", "unit", "range", "default"
    );
    let mut inactive = 0;
    for d in &table {
        inactive += usize::from(d.info.value.is_nan());
        println!("{}", param_row(d, selected.as_deref()));
    }
    if inactive > 0 {
        println!(
            "{n} parameters; {inactive} inactive (not used by the selected controller{}: shown at their defaults)",
            selected.map_or(String::new(), |c| format!(", {c}"))
        );
    } else {
        println!("{n} parameters");
    }
    Ok(())
}

/// `params get NAME`: one parameter's value.
pub(crate) fn params_get(c: &mut Client, name: &str) -> Result<()> {
    let d = names::describe(c, name)?;
    let v = match read_param(c, name)? {
        Ok(v) => v,
        Err(why) => match inactive_hint(c, d.as_ref())? {
            Some(hint) => bail!("get {name}: {hint}"),
            None => bail!("get {name}: {why}"),
        },
    };
    println!("{name} = {}", shown(d.as_ref(), v));
    Ok(())
}

/// `params set NAME VALUE`: set a parameter, checked on the robot.
pub(crate) fn params_set(c: &mut Client, name: &str, value: &str) -> Result<()> {
    let d = names::describe(c, name)?;
    let v = match (&d, value.parse::<f32>()) {
        (_, Ok(v)) => v,
        (Some(d), Err(_)) => d.parse(value)?,
        (None, Err(_)) => bail!("`{value}` is not a number"),
    };
    match c.request(Request::ParamSet {
        name: wire_name(name)?,
        value: v,
    })? {
        Response::Ok => {
            let now = get(c, name)?;
            println!("{name} = {} (set)", shown(d.as_ref(), now));
            Ok(())
        }
        Response::Refused(why) => match read_param(c, name)? {
            Ok(now) => bail!(
                "set {name} = {value} refused: {why} (unchanged: {})",
                shown(d.as_ref(), now)
            ),
            Err(_) => match inactive_hint(c, d.as_ref())? {
                Some(hint) => bail!("set {name} = {value} refused: {why} ({hint})"),
                None => bail!("set {name} = {value} refused: {why}"),
            },
        },
        r => bail!("unexpected answer {r:?}"),
    }
}

/// A value for display: a choice by name, else the number and unit.
fn shown(d: Option<&Described>, v: f32) -> String {
    d.map_or_else(|| format!("{v}"), |d| d.shown(v))
}

/// For a parameter that the robot's configuration lacks (another
/// controller's, which the robot refuses to read or set): why, its
/// default, and the command(s) that make it active.
fn inactive_hint(c: &mut Client, d: Option<&Described>) -> Result<Option<String>> {
    let Some(d) = d.filter(|d| d.owner.is_some()) else {
        return Ok(None);
    };
    let selected = selected_controller(c)?;
    let steps: Vec<String> = d
        .activation(selected.as_deref())
        .iter()
        .map(|s| format!("`{s}`"))
        .collect();
    let mut hint = format!(
        "{}; default {}",
        d.inactive_reason(selected.as_deref()),
        d.shown(d.info.default)
    );
    if !steps.is_empty() {
        hint += &format!("; activate it with {}", steps.join(" then "));
    }
    Ok(Some(hint))
}

/// The selected controller's name, if the robot says.
fn selected_controller(c: &mut Client) -> Result<Option<String>> {
    let names = names::controller_names(c)?;
    Ok(get(c, names::CONTROLLER)
        .ok()
        .filter(|v| *v >= 0.0)
        .and_then(|v| names.get(v as usize).cloned()))
}

/// One row of `params list`. The robot reports no value (NaN) for a
/// parameter its configuration lacks (another controller's): the row shows
/// the default, which selecting that controller starts it from, and says
/// what would make it active.
fn param_row(d: &Described, selected: Option<&str>) -> String {
    let p = &d.info;
    let (value, note) = if p.value.is_nan() {
        (p.default, format!("  ({})", d.inactive_reason(selected)))
    } else {
        (p.value, String::new())
    };
    format!(
        "{:<42} {:>14} {:<8} {:>25} {:>12}  {:<8}{note}",
        p.name.as_str(),
        d.value(value),
        p.unit.as_str(),
        format!("{} ..= {}", p.min, p.max),
        d.value(p.default),
        if p.live { "settable" } else { "-" }
    )
    .trim_end()
    .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use hopper_link::names::Owner;
    use hopper_protocol::vocab::ParamKind;
    use hopper_protocol::ParamInfo;

    /// A parameter as the robot would describe it.
    fn described(
        name: &str,
        value: f32,
        default: f32,
        kind: ParamKind,
        choices: &[&str],
        owner: Option<&str>,
    ) -> Described {
        Described {
            info: ParamInfo {
                name: name.try_into().unwrap_or_default(),
                unit: "-".try_into().unwrap_or_default(),
                min: 0.0,
                max: 100.0,
                default,
                value,
                live: false,
            },
            kind: Some(kind),
            choices: choices.iter().map(|c| c.to_string()).collect(),
            owner: owner.map(|c| Owner {
                controller: c.into(),
                choice: None,
            }),
        }
    }

    #[test]
    fn an_inactive_parameter_shows_its_default_and_why() {
        let d = described(
            "energy.gain_nm_per_j",
            f32::NAN,
            0.2,
            ParamKind::Real,
            &[],
            Some("energy"),
        );
        let row = param_row(&d, Some("shaped"));
        assert!(!row.contains("NaN"), "{row}");
        let cells: Vec<&str> = row.split_whitespace().collect();
        assert_eq!(cells[..2], ["energy.gain_nm_per_j", "0.2"], "{row}");
        assert!(
            row.ends_with("(inactive: controller energy not selected)"),
            "{row}"
        );
        // The parameter table's row filter (` ..= `) still finds it.
        assert!(row.contains("0 ..= 100"), "{row}");
    }

    #[test]
    fn an_inactive_choice_is_not_shown_as_its_first_name() {
        // NaN cast to an index is 0: it used to read `fixed`.
        let d = described(
            "step_closed.gain",
            f32::NAN,
            0.0,
            ParamKind::Choice,
            &["fixed", "normalised"],
            Some("step-closed"),
        );
        let row = param_row(&d, Some("shaped"));
        assert!(
            row.ends_with("(inactive: controller step-closed not selected)"),
            "{row}"
        );
        assert_eq!(row.split_whitespace().nth(1), Some("fixed"), "the default");
    }

    #[test]
    fn choices_show_by_name_value_and_default() {
        let d = described(
            "controller",
            2.0,
            1.0,
            ParamKind::Choice,
            &["energy", "energy-apex", "shaped"],
            None,
        );
        let row = param_row(&d, Some("shaped"));
        let cells: Vec<&str> = row.split_whitespace().collect();
        assert_eq!(cells[1], "shaped", "{row}");
        assert!(row.contains(" energy-apex "), "{row}");
        assert!(!row.contains("inactive"), "{row}");
    }
}
