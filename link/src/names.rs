//! Names for the wire's codes (the protocol's vocabulary) and the
//! parameters' values and owners (the firmware's parameter table).

use hopper_control::hopper::HopperConfig;
use hopper_control::params::{self, Kind, Param, CONTROLLER, CONTROLLER_NAMES};
use hopper_protocol::vocab::{DisarmReason, Fault};
use hopper_protocol::ArmState;

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

/// What a disarm reason means and what to do about it (the README's table).
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

/// A parameter's value as the operator types it: a choice by its name
/// (`shaped`), anything else as the number (a choice index the table does
/// not name, from a newer firmware, stays a number).
pub fn param_value(name: &str, v: f32) -> String {
    match params::find(name).map(|p| p.kind) {
        Some(Kind::Choice(names)) if v >= 0.0 && v == v.trunc() => names
            .get(v as usize)
            .map_or_else(|| format!("{v}"), |n| (*n).to_string()),
        _ => format!("{v}"),
    }
}

/// What a parameter needs to be part of the configuration: a controller,
/// and possibly a value of one of that controller's choices
/// (`step_closed.min_compression_m` only exists with `step_closed.gain`
/// normalised, `step_closed.kp_m_per_j` only with it fixed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Owner {
    /// The controller, an index of [`CONTROLLER_NAMES`].
    pub controller: usize,
    /// The choice of that controller and the value it must have.
    pub choice: Option<(&'static Param, usize)>,
}

/// The configuration of controller `index` at its defaults.
fn with_controller(index: usize) -> Option<HopperConfig> {
    let mut cfg = HopperConfig::default();
    params::set(&mut cfg, CONTROLLER.name, index as f32).ok()?;
    Some(cfg)
}

/// The choices (other than the controller) that `cfg` has, with their
/// number of values.
fn choices_of(cfg: &HopperConfig) -> impl Iterator<Item = (&'static Param, usize)> + '_ {
    params::TABLE.iter().copied().filter_map(|q| match q.kind {
        Kind::Choice(values) if q.name != CONTROLLER.name && params::get(cfg, q.name).is_ok() => {
            Some((q, values.len()))
        }
        _ => None,
    })
}

/// Whether `p` is in `cfg` with choice `q` set to `v` (from its defaults).
fn readable_with(cfg: &HopperConfig, q: &Param, v: usize, p: &Param) -> bool {
    let mut c = *cfg;
    params::set(&mut c, q.name, v as f32).is_ok() && params::get(&c, p.name).is_ok()
}

/// Which controller (and choice) parameter `name` belongs to; `None` for a
/// parameter of every configuration (`target_apex_m`, `arming.*`) or one
/// this hopper-link does not know. Found by trying the firmware's own
/// configurations rather than from the names, so a new controller or
/// choice needs no change here.
pub fn owner(name: &str) -> Option<Owner> {
    let p = params::find(name)?;
    let configs: Vec<HopperConfig> = (0..CONTROLLER_NAMES.len())
        .filter_map(with_controller)
        .collect();
    // Readable in some variant of a configuration: at its defaults, or
    // with one of its choices switched.
    let has = |cfg: &HopperConfig| {
        params::get(cfg, p.name).is_ok()
            || choices_of(cfg).any(|(q, n)| (0..n).any(|v| readable_with(cfg, q, v, p)))
    };
    let owners: Vec<usize> = (0..configs.len()).filter(|&i| has(&configs[i])).collect();
    if owners.len() == configs.len() {
        return None;
    }
    let controller = *owners.first()?;
    let cfg = configs.get(controller)?;
    // A choice of the controller that some of its values leave `p` out of.
    let choice = choices_of(cfg).find_map(|(q, n)| {
        let with: Vec<usize> = (0..n).filter(|&v| readable_with(cfg, q, v, p)).collect();
        (!with.is_empty() && with.len() < n).then(|| (q, with[0]))
    });
    Some(Owner { controller, choice })
}

/// Why parameter `name` is not in the robot's configuration (the robot
/// reports no value for it), given the selected controller's index if
/// known: `inactive: controller energy not selected`.
pub fn inactive_reason(name: &str, selected: Option<usize>) -> String {
    let controller = |i: usize| CONTROLLER_NAMES.get(i).copied().unwrap_or("?");
    let choice = |(q, v): (&Param, usize)| format!("{} {}", q.name, param_value(q.name, v as f32));
    match owner(name) {
        Some(Owner {
            controller: i,
            choice: Some((q, v)),
        }) if selected == Some(i) => format!(
            "inactive: {} is not {}",
            q.name,
            param_value(q.name, v as f32)
        ),
        // Selecting the controller starts it from its defaults: name the
        // choice only when its default is not the one needed.
        Some(Owner {
            controller: i,
            choice: Some((q, v)),
        }) if q.default != v as f32 => format!(
            "inactive: controller {} with {} not selected",
            controller(i),
            choice((q, v))
        ),
        Some(Owner { controller: i, .. }) => {
            format!("inactive: controller {} not selected", controller(i))
        }
        None => "inactive: not in the robot's configuration".into(),
    }
}

/// The commands that make parameter `name` active, given the selected
/// controller's index if known (empty when it has no owner).
pub fn activation(name: &str, selected: Option<usize>) -> Vec<String> {
    let Some(o) = owner(name) else {
        return Vec::new();
    };
    let mut steps = Vec::new();
    let switch = selected != Some(o.controller);
    if switch {
        let c = CONTROLLER_NAMES.get(o.controller).copied().unwrap_or("?");
        steps.push(format!("params set controller {c}"));
    }
    if let Some((q, v)) = o.choice {
        if !switch || q.default != v as f32 {
            steps.push(format!(
                "params set {} {}",
                q.name,
                param_value(q.name, v as f32)
            ));
        }
    }
    steps
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn choices_are_shown_by_name() {
        assert_eq!(param_value("controller", 8.0), "shaped");
        assert_eq!(param_value("controller", 5.0), "energy-apex");
        assert_eq!(param_value("step_closed.gain", 1.0), "normalised");
        // Beyond the names (a newer firmware) or not whole: the number.
        assert_eq!(param_value("controller", 42.0), "42");
        assert_eq!(param_value("controller", 0.5), "0.5");
        assert_eq!(param_value("target_apex_m", 0.12), "0.12");
        assert_eq!(param_value("no.such", 3.0), "3");
    }

    #[test]
    fn parameters_belong_to_their_controllers() {
        let index = |n: &str| CONTROLLER_NAMES.iter().position(|c| *c == n);
        let of = |name: &str| owner(name).map(|o| o.controller);
        assert_eq!(of("energy.gain_nm_per_j"), index("energy"));
        assert_eq!(of("constant_torque.torque_nm"), index("open-torque"));
        assert_eq!(of("shaped.switch_fraction"), index("shaped"));
        assert_eq!(of("energy_apex.measure"), index("energy-apex"));
        // Every configuration has these, and an unknown name has no owner.
        for general in [
            "controller",
            "target_apex_m",
            "arming.require_tare",
            "no.such",
        ] {
            assert_eq!(owner(general), None, "{general}");
        }
        // Only with the non-default choice.
        let o = owner("step_closed.min_compression_m");
        assert_eq!(o.map(|o| o.controller), index("step-closed"));
        assert_eq!(
            o.and_then(|o| o.choice).map(|(q, v)| (q.name, v)),
            Some(("step_closed.gain", 1))
        );
    }

    #[test]
    fn inactive_parameters_say_what_would_activate_them() {
        let shaped = CONTROLLER_NAMES.iter().position(|c| *c == "shaped");
        let step_closed = CONTROLLER_NAMES.iter().position(|c| *c == "step-closed");
        assert_eq!(
            inactive_reason("energy.gain_nm_per_j", shaped),
            "inactive: controller energy not selected"
        );
        assert_eq!(
            inactive_reason("step_closed.min_compression_m", step_closed),
            "inactive: step_closed.gain is not normalised"
        );
        assert_eq!(
            inactive_reason("step_closed.min_compression_m", shaped),
            "inactive: controller step-closed with step_closed.gain normalised not selected"
        );
        assert_eq!(
            inactive_reason("step_closed.kp_m_per_j", step_closed),
            "inactive: step_closed.gain is not fixed"
        );
        // Selecting step-closed starts it with the fixed gain.
        assert_eq!(
            inactive_reason("step_closed.kp_m_per_j", shaped),
            "inactive: controller step-closed not selected"
        );
        assert_eq!(
            inactive_reason("no.such", shaped),
            "inactive: not in the robot's configuration"
        );
        assert_eq!(
            activation("step_closed.min_compression_m", shaped),
            [
                "params set controller step-closed",
                "params set step_closed.gain normalised"
            ]
        );
        assert_eq!(
            activation("step_closed.kp_m_per_j", shaped),
            ["params set controller step-closed"]
        );
        assert_eq!(
            activation("step_closed.kp_m_per_j", step_closed),
            ["params set step_closed.gain fixed"]
        );
        assert!(activation("target_apex_m", shaped).is_empty());
    }

    /// Every table parameter that some controller's configuration lacks
    /// has an owner: none would be reported as "not in the robot's
    /// configuration".
    #[test]
    fn every_controller_parameter_has_an_owner() {
        for i in 0..CONTROLLER_NAMES.len() {
            let cfg = with_controller(i).unwrap_or_else(|| panic!("controller {i}"));
            for p in params::TABLE {
                if params::get(&cfg, p.name).is_err() {
                    assert!(owner(p.name).is_some(), "{}", p.name);
                }
            }
        }
    }
}
