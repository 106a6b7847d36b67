//! Names for the wire's codes (the protocol's vocabulary) and the
//! parameters' values and owners, as the robot describes them.

use crate::Client;
use anyhow::{anyhow, bail, Result};
use hopper_protocol::vocab::{DisarmReason, Fault, ParamKind, Refusal};
use hopper_protocol::{ArmState, Name, ParamInfo, Request, Response};

/// The latched faults by name (`none` when empty), comma-separated.
pub fn faults(bits: u16) -> String {
    if bits == 0 {
        return "none".into();
    }
    let (known, unknown) = Fault::names(bits);
    let mut names: Vec<String> = known.map(str::to_string).collect();
    if unknown != 0 {
        names.push(format!("unknown bits {unknown:#06x}"));
    }
    names.join(",")
}

/// The arming state as the firmware names it: `armed`, `disarmed (boot)`, ...
pub fn arm_state(s: ArmState) -> String {
    match s {
        ArmState::Armed => "armed".into(),
        ArmState::Disarmed(code) => match DisarmReason::from_code(code) {
            Some(r) => format!("disarmed ({})", r.name()),
            None => format!("disarmed (reason {code})"),
        },
    }
}

/// What a disarm reason means and what to do about it (the book's troubleshooting page).
pub fn advice(s: ArmState) -> &'static str {
    use DisarmReason as R;
    match s {
        ArmState::Armed => "the amplifier is enabled and the controller drives the motor",
        ArmState::Disarmed(code) => match DisarmReason::from_code(code) {
            Some(R::Boot) => "powered up: check the sensors, then arm",
            Some(R::WatchdogReset) => {
                "the watchdog reset the MCU (the loop stalled): read `dump`, then reset-faults"
            }
            Some(R::Command) => "disarmed on request",
            Some(R::Estop) => "the e-stop was pressed: release it, reset-faults, arm",
            Some(R::Fault) => {
                "a fault latched: read `status` and `dump`, fix the cause, reset-faults"
            }
            Some(R::LinkLost) => {
                "no frame from the host within the link timeout: reconnect and arm"
            }
            None => "unknown reason (a newer firmware?)",
        },
    }
}

/// A parameter as the robot describes it: its table entry
/// (`Request::ParamInfo`) and what `Request::ParamMeta` adds. The host keeps
/// no copy of the firmware's table: a newer firmware's parameters show
/// with their own names, units, choices and owners.
#[derive(Debug, Clone, PartialEq)]
pub struct Described {
    /// The table entry (name, unit, range, default, value now: NaN when the
    /// robot's configuration lacks it).
    pub info: ParamInfo,
    /// Its kind (`None`: a code this host does not know, shown as a number).
    pub kind: Option<ParamKind>,
    /// A choice's values by name, in order.
    pub choices: Vec<String>,
    /// What it needs to be part of the configuration (`None`: every
    /// configuration has it).
    pub owner: Option<Owner>,
}

/// What a parameter needs to be part of the configuration: a controller,
/// and possibly a value of one of that controller's choices
/// (`step_closed.min_compression_m` only exists with `step_closed.gain`
/// normalised, `step_closed.kp_m_per_j` only with it fixed).
#[derive(Debug, Clone, PartialEq)]
pub struct Owner {
    /// The controller, by name.
    pub controller: String,
    /// The choice of that controller and the value it must have.
    pub choice: Option<Choice>,
}

/// A choice parameter set to one value.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    /// The choice's name (`step_closed.gain`).
    pub param: String,
    /// The value needed, by name (`normalised`).
    pub value: String,
    /// Whether that value is the choice's default (selecting the
    /// controller starts it from its defaults).
    pub is_default: bool,
}

fn wire(name: &str) -> Result<Name> {
    let mut n = Name::new();
    n.push_str(name)
        .map_err(|_| anyhow!("parameter name `{name}` is too long"))?;
    Ok(n)
}

fn info_at(c: &mut Client, index: u16) -> Result<ParamInfo> {
    match c.request(Request::ParamInfo { index })? {
        Response::ParamInfo(p) => Ok(p),
        r => bail!("parameter {index}: unexpected answer {r:?}"),
    }
}

fn choice_name(c: &mut Client, name: &str, value: u8) -> Result<String> {
    match c.request(Request::ParamChoice {
        name: wire(name)?,
        value,
    })? {
        Response::Name(n) => Ok(n.as_str().to_string()),
        r => bail!("{name} value {value}: unexpected answer {r:?}"),
    }
}

/// The choice names of the robot's `controller` parameter, in order.
pub fn controller_names(c: &mut Client) -> Result<Vec<String>> {
    Ok(describe(c, CONTROLLER)?.map_or_else(Vec::new, |d| d.choices))
}

/// The robot's name for the parameter that selects the controller.
pub const CONTROLLER: &str = "controller";

/// Parameter `name` as the robot describes it; `None` when the robot has
/// no parameter of that name.
pub fn describe(c: &mut Client, name: &str) -> Result<Option<Described>> {
    described(c, name, None, &mut None)
}

/// Every parameter as the robot describes it, in the robot's order: two
/// requests a parameter and one per choice, the controllers' names asked
/// once for the whole table.
pub fn table(c: &mut Client) -> Result<Vec<Described>> {
    let n = match c.request(Request::ParamCount)? {
        Response::ParamCount(n) => n,
        r => bail!("unexpected answer {r:?}"),
    };
    let mut controllers = None;
    let mut rows = Vec::with_capacity(usize::from(n));
    for index in 0..n {
        let info = info_at(c, index)?;
        let name = info.name.as_str().to_string();
        match described(c, &name, Some(info), &mut controllers)? {
            Some(d) => rows.push(d),
            None => bail!("parameter {index} ({name}): the robot does not describe it"),
        }
    }
    Ok(rows)
}

/// [`describe`], with the table entry when the caller has it already and
/// the controllers' names once known (`None`: ask when needed).
fn described(
    c: &mut Client,
    name: &str,
    info: Option<ParamInfo>,
    controllers: &mut Option<Vec<String>>,
) -> Result<Option<Described>> {
    let meta = match c.request(Request::ParamMeta { name: wire(name)? })? {
        Response::ParamMeta(m) => m,
        Response::Refused(why) if why == Refusal::UnknownParameter => return Ok(None),
        r => bail!("describe {name}: unexpected answer {r:?}"),
    };
    let info = match info {
        Some(i) => i,
        None => info_at(c, meta.index)?,
    };
    let choices = (0..meta.choices)
        .map(|v| choice_name(c, name, v))
        .collect::<Result<Vec<_>>>()?;
    let owner = match meta.controller {
        None => None,
        Some(i) => {
            if controllers.is_none() && name != CONTROLLER {
                *controllers = Some(controller_names(c)?);
            }
            let controller = if name == CONTROLLER {
                None
            } else {
                controllers
                    .as_ref()
                    .and_then(|n| n.get(usize::from(i)).cloned())
            }
            .unwrap_or_else(|| format!("{i}"));
            let choice = match meta.needs {
                None => None,
                Some((q, v)) => {
                    let q = info_at(c, q)?;
                    Some(Choice {
                        value: choice_name(c, q.name.as_str(), v)?,
                        is_default: q.default == f32::from(v),
                        param: q.name.as_str().to_string(),
                    })
                }
            };
            Some(Owner { controller, choice })
        }
    };
    Ok(Some(Described {
        info,
        kind: ParamKind::from_code(meta.kind),
        choices,
        owner,
    }))
}

/// [`Described::number`] for any number.
pub fn plain_number(v: f32) -> String {
    let a = v.abs();
    if a != 0.0 && a.is_finite() && !(1e-3..1e6).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

impl Described {
    /// A value as the operator types it: a choice by its name (`shaped`),
    /// anything else as the number (a choice index without a name stays
    /// a number).
    pub fn value(&self, v: f32) -> String {
        match self.kind {
            Some(ParamKind::Choice) if v >= 0.0 && v == v.trunc() => self
                .choices
                .get(v as usize)
                .map_or_else(|| format!("{v}"), Clone::clone),
            _ => format!("{v}"),
        }
    }

    /// A value as typed: a number, or a choice's name (`controller shaped`).
    pub fn parse(&self, value: &str) -> Result<f32> {
        if let Ok(v) = value.parse::<f32>() {
            return Ok(v);
        }
        match self.kind {
            Some(ParamKind::Choice) => self
                .choices
                .iter()
                .position(|n| n == value)
                .map(|i| i as f32)
                .ok_or_else(|| {
                    anyhow!(
                        "`{}` is one of {:?}, not `{value}`",
                        self.info.name,
                        self.choices
                    )
                }),
            _ => bail!("`{value}` is not a number"),
        }
    }

    /// A number for a person to read: the shortest decimal that is the
    /// `f32` (not its `f64` widening, `0.00009999999747378752`), in
    /// exponent form beyond a million or below a thousandth (`1e30`,
    /// `1e-4`), a choice by its name.
    pub fn number(&self, v: f32) -> String {
        match self.kind {
            Some(ParamKind::Choice) => self.value(v),
            _ => plain_number(v),
        }
    }

    /// A value for display: a choice by name and number, else the number
    /// and unit.
    pub fn shown(&self, v: f32) -> String {
        let unit = self.info.unit.as_str();
        match self.kind {
            Some(ParamKind::Choice) => self
                .choices
                .get(v as usize)
                .map_or(format!("{v}"), |n| format!("{n} ({v})")),
            _ if unit == "1" || unit == "-" => format!("{v}"),
            _ => format!("{v} {unit}"),
        }
    }

    /// Why it is not in the robot's configuration (the robot reports no
    /// value for it), given the selected controller's name if known:
    /// `inactive: controller energy not selected`.
    pub fn inactive_reason(&self, selected: Option<&str>) -> String {
        match &self.owner {
            Some(Owner {
                controller,
                choice: Some(q),
            }) if selected == Some(controller.as_str()) => {
                format!("inactive: {} is not {}", q.param, q.value)
            }
            // Selecting the controller starts it from its defaults: name
            // the choice only when its default is not the one needed.
            Some(Owner {
                controller,
                choice: Some(q),
            }) if !q.is_default => format!(
                "inactive: controller {controller} with {} {} not selected",
                q.param, q.value
            ),
            Some(Owner { controller, .. }) => {
                format!("inactive: controller {controller} not selected")
            }
            None => "inactive: not in the robot's configuration".into(),
        }
    }

    /// The commands that make it active, given the selected controller's
    /// name if known (empty when every configuration has it).
    pub fn activation(&self, selected: Option<&str>) -> Vec<String> {
        let Some(o) = &self.owner else {
            return Vec::new();
        };
        let mut steps = Vec::new();
        let switch = selected != Some(o.controller.as_str());
        if switch {
            steps.push(format!("params set controller {}", o.controller));
        }
        if let Some(q) = &o.choice {
            if !switch || !q.is_default {
                steps.push(format!("params set {} {}", q.param, q.value));
            }
        }
        steps
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_read_as_the_f32_they_are() {
        assert_eq!(plain_number(1e-4), "1e-4");
        assert_eq!(plain_number(1e30), "1e30");
        assert_eq!(plain_number(0.15), "0.15");
        assert_eq!(plain_number(-2.5), "-2.5");
        assert_eq!(plain_number(0.0), "0");
        assert_eq!(plain_number(200_000.0), "200000");
    }

    #[test]
    fn names_come_from_the_firmware() {
        assert_eq!(faults(0), "none");
        let both = Fault::Estop.bit() | Fault::Overrun.bit();
        let s = faults(both);
        assert!(
            s.contains(Fault::Estop.name()) && s.contains(Fault::Overrun.name()),
            "{s}"
        );
        assert_eq!(arm_state(ArmState::Disarmed(5)), "disarmed (link-lost)");
        assert_eq!(arm_state(ArmState::Disarmed(0)), "disarmed (boot)");
        assert_eq!(arm_state(ArmState::Disarmed(77)), "disarmed (reason 77)");
    }

    fn described(name: &str, kind: ParamKind, choices: &[&str], owner: Option<Owner>) -> Described {
        Described {
            info: ParamInfo {
                name: name.try_into().unwrap_or_default(),
                unit: "-".try_into().unwrap_or_default(),
                min: 0.0,
                max: 1.0,
                default: 0.0,
                value: f32::NAN,
                live: false,
            },
            kind: Some(kind),
            choices: choices.iter().map(|c| c.to_string()).collect(),
            owner,
        }
    }

    fn owned(controller: &str, choice: Option<(&str, &str, bool)>) -> Option<Owner> {
        Some(Owner {
            controller: controller.into(),
            choice: choice.map(|(param, value, is_default)| Choice {
                param: param.into(),
                value: value.into(),
                is_default,
            }),
        })
    }

    #[test]
    fn choices_are_shown_by_name() {
        let c = described("controller", ParamKind::Choice, &["energy", "shaped"], None);
        assert_eq!(c.value(1.0), "shaped");
        assert_eq!(c.shown(1.0), "shaped (1)");
        assert_eq!(c.parse("shaped").ok(), Some(1.0));
        assert_eq!(c.parse("0").ok(), Some(0.0));
        assert!(c.parse("nope").is_err());
        // Beyond the names (a newer firmware) or not whole: the number.
        assert_eq!(c.value(42.0), "42");
        assert_eq!(c.value(0.5), "0.5");
        let r = described("target_apex_m", ParamKind::Real, &[], None);
        assert_eq!(r.value(0.12), "0.12");
        assert!(r.parse("high").is_err());
    }

    #[test]
    fn inactive_parameters_say_what_would_activate_them() {
        let energy = described(
            "energy.gain_nm_per_j",
            ParamKind::Real,
            &[],
            owned("energy", None),
        );
        assert_eq!(
            energy.inactive_reason(Some("shaped")),
            "inactive: controller energy not selected"
        );
        // Needs the non-default value of step-closed's gain choice.
        let normalised = described(
            "step_closed.min_compression_m",
            ParamKind::Real,
            &[],
            owned(
                "step-closed",
                Some(("step_closed.gain", "normalised", false)),
            ),
        );
        assert_eq!(
            normalised.inactive_reason(Some("step-closed")),
            "inactive: step_closed.gain is not normalised"
        );
        assert_eq!(
            normalised.inactive_reason(Some("shaped")),
            "inactive: controller step-closed with step_closed.gain normalised not selected"
        );
        assert_eq!(
            normalised.activation(Some("shaped")),
            [
                "params set controller step-closed",
                "params set step_closed.gain normalised"
            ]
        );
        // Needs the default value: selecting the controller is enough.
        let fixed = described(
            "step_closed.kp_m_per_j",
            ParamKind::Real,
            &[],
            owned("step-closed", Some(("step_closed.gain", "fixed", true))),
        );
        assert_eq!(
            fixed.inactive_reason(Some("step-closed")),
            "inactive: step_closed.gain is not fixed"
        );
        assert_eq!(
            fixed.inactive_reason(Some("shaped")),
            "inactive: controller step-closed not selected"
        );
        assert_eq!(
            fixed.activation(Some("shaped")),
            ["params set controller step-closed"]
        );
        assert_eq!(
            fixed.activation(Some("step-closed")),
            ["params set step_closed.gain fixed"]
        );
        let general = described("target_apex_m", ParamKind::Real, &[], None);
        assert_eq!(
            general.inactive_reason(Some("shaped")),
            "inactive: not in the robot's configuration"
        );
        assert!(general.activation(Some("shaped")).is_empty());
    }
}
