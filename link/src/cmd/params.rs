//! `params list`, `params get` and `params set`: the parameter table on
//! the robot.

use super::common::{get, read_param, wire_name};
use anyhow::{anyhow, bail, Result};
use hopper_control::params::{self, Kind};
use hopper_link::{names, Client};
use hopper_protocol::{Request, Response};

pub(crate) fn params_list(c: &mut Client) -> Result<()> {
    let n = match c.request(Request::ParamCount)? {
        Response::ParamCount(n) => n,
        r => bail!("unexpected answer {r:?}"),
    };
    let selected = selected_controller(c);
    println!(
        "{:<42} {:>14} {:<8} {:>25} {:>12}  armed",
        "name", "value", "unit", "range", "default"
    );
    let mut inactive = 0;
    for index in 0..n {
        match c.request(Request::ParamInfo { index })? {
            Response::ParamInfo(p) => {
                inactive += usize::from(p.value.is_nan());
                println!("{}", param_row(&p, selected));
            }
            Response::Refused(why) => bail!("parameter {index}: {why}"),
            r => bail!("unexpected answer {r:?}"),
        }
    }
    if inactive > 0 {
        println!(
            "{n} parameters; {inactive} inactive (not used by the selected controller{}: shown at their defaults)",
            selected
                .and_then(|i| params::CONTROLLER_NAMES.get(i))
                .map_or(String::new(), |c| format!(", {c}"))
        );
    } else {
        println!("{n} parameters");
    }
    Ok(())
}

/// `params get NAME`: one parameter's value.
pub(crate) fn params_get(c: &mut Client, name: &str) -> Result<()> {
    let v = match read_param(c, name)? {
        Ok(v) => v,
        Err(why) => match inactive_hint(c, name) {
            Some(hint) => bail!("get {name}: {hint}"),
            None => bail!("get {name}: {why}"),
        },
    };
    println!("{name} = {}", shown(name, v));
    Ok(())
}

/// `params set NAME VALUE`: set a parameter, checked on the robot.
pub(crate) fn params_set(c: &mut Client, name: &str, value: &str) -> Result<()> {
    let v = parse_value(name, value)?;
    match c.request(Request::ParamSet {
        name: wire_name(name)?,
        value: v,
    })? {
        Response::Ok => {
            let now = get(c, name)?;
            println!("{name} = {} (set)", shown(name, now));
            Ok(())
        }
        Response::Refused(why) => match read_param(c, name)? {
            Ok(now) => bail!(
                "set {name} = {value} refused: {why} (unchanged: {})",
                shown(name, now)
            ),
            Err(_) => match inactive_hint(c, name) {
                Some(hint) => bail!("set {name} = {value} refused: {why} ({hint})"),
                None => bail!("set {name} = {value} refused: {why}"),
            },
        },
        r => bail!("unexpected answer {r:?}"),
    }
}

/// A value as typed: a number, or a choice's name (`controller shaped`).
fn parse_value(name: &str, value: &str) -> Result<f32> {
    if let Ok(v) = value.parse::<f32>() {
        return Ok(v);
    }
    match params::find(name).map(|p| p.kind) {
        Some(Kind::Choice(names)) => names
            .iter()
            .position(|n| *n == value)
            .map(|i| i as f32)
            .ok_or_else(|| anyhow!("`{name}` is one of {names:?}, not `{value}`")),
        _ => bail!("`{value}` is not a number"),
    }
}

/// A value for display: a choice by name, else the number and unit.
fn shown(name: &str, v: f32) -> String {
    match params::find(name) {
        Some(p) => match p.kind {
            Kind::Choice(names) => names
                .get(v as usize)
                .map_or(format!("{v}"), |n| format!("{n} ({v})")),
            _ if p.unit == "1" || p.unit == "-" => format!("{v}"),
            _ => format!("{v} {}", p.unit),
        },
        None => format!("{v}"),
    }
}

/// For a parameter of the table that the robot's configuration lacks
/// (another controller's, which the robot refuses to read or set): why,
/// its default, and the command(s) that make it active.
fn inactive_hint(c: &mut Client, name: &str) -> Option<String> {
    let p = params::find(name)?;
    names::owner(name)?;
    let selected = selected_controller(c);
    let steps: Vec<String> = names::activation(name, selected)
        .iter()
        .map(|s| format!("`{s}`"))
        .collect();
    let mut hint = format!(
        "{}; default {}",
        names::inactive_reason(name, selected),
        shown(name, p.default)
    );
    if !steps.is_empty() {
        hint += &format!("; activate it with {}", steps.join(" then "));
    }
    Some(hint)
}

/// The selected controller's index, if the robot says.
fn selected_controller(c: &mut Client) -> Option<usize> {
    get(c, params::CONTROLLER.name)
        .ok()
        .filter(|v| *v >= 0.0)
        .map(|v| v as usize)
}

/// One row of `params list`. The robot reports no value (NaN) for a
/// parameter its configuration lacks (another controller's): the row shows
/// the default, which selecting that controller starts it from, and says
/// what would make it active.
fn param_row(p: &hopper_protocol::ParamInfo, selected: Option<usize>) -> String {
    let name = p.name.as_str();
    let (value, note) = if p.value.is_nan() {
        (
            p.default,
            format!("  ({})", names::inactive_reason(name, selected)),
        )
    } else {
        (p.value, String::new())
    };
    format!(
        "{:<42} {:>14} {:<8} {:>25} {:>12}  {:<8}{note}",
        name,
        names::param_value(name, value),
        p.unit.as_str(),
        format!("{} ..= {}", p.min, p.max),
        names::param_value(name, p.default),
        if p.live { "settable" } else { "-" }
    )
    .trim_end()
    .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use hopper_protocol::{Name, ParamInfo};

    fn info(name: &str, value: f32, default: f32) -> ParamInfo {
        let p = params::find(name).unwrap_or_else(|| panic!("{name}"));
        let mut n = Name::new();
        n.push_str(name).unwrap();
        ParamInfo {
            name: n,
            unit: p.unit.try_into().unwrap(),
            min: p.min,
            max: p.max,
            default,
            value,
            live: false,
        }
    }

    fn index(controller: &str) -> Option<usize> {
        params::CONTROLLER_NAMES
            .iter()
            .position(|c| *c == controller)
    }

    #[test]
    fn an_inactive_parameter_shows_its_default_and_why() {
        let row = param_row(
            &info("energy.gain_nm_per_j", f32::NAN, 0.2),
            index("shaped"),
        );
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
        let row = param_row(&info("step_closed.gain", f32::NAN, 0.0), index("shaped"));
        assert!(
            row.ends_with("(inactive: controller step-closed not selected)"),
            "{row}"
        );
    }

    #[test]
    fn choices_show_by_name_value_and_default() {
        let row = param_row(&info("controller", 8.0, 5.0), index("shaped"));
        let cells: Vec<&str> = row.split_whitespace().collect();
        assert_eq!(cells[1], "shaped", "{row}");
        assert!(row.contains(" energy-apex "), "{row}");
        assert!(!row.contains("inactive"), "{row}");
    }
}
