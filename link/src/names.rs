//! Names for the wire's codes, from the firmware's own definitions.

use hopper_control::link::disarm_reason;
use hopper_control::supervisor::Fault;
use hopper_protocol::ArmState;

/// The latched faults by name (`none` when empty), comma-separated.
pub fn faults(bits: u16) -> String {
    if bits == 0 {
        return "none".into();
    }
    let mut names: Vec<&str> = Fault::ALL
        .iter()
        .filter(|f| bits & f.bit() != 0)
        .map(|f| f.name())
        .collect();
    let known = Fault::ALL.iter().fold(0u16, |a, f| a | f.bit());
    let unknown = bits & !known;
    let extra = format!("unknown bits {unknown:#06x}");
    if unknown != 0 {
        names.push(&extra);
    }
    names.join(",")
}

/// The arming state as the firmware names it: `armed`, `disarmed (boot)`, ...
pub fn arm_state(s: ArmState) -> String {
    match s {
        ArmState::Armed => "armed".into(),
        ArmState::Disarmed(code) => match disarm_reason(code) {
            Some(r) => format!("disarmed ({})", r.name()),
            None => format!("disarmed (reason {code})"),
        },
    }
}

/// What a disarm reason means and what to do about it (the README's table).
pub fn advice(s: ArmState) -> &'static str {
    use hopper_control::arming::DisarmReason as R;
    match s {
        ArmState::Armed => "the amplifier is enabled and the controller drives the motor",
        ArmState::Disarmed(code) => match disarm_reason(code) {
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
}
