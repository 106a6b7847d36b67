//! Helpers of several commands: parameter reads, the robot's status and
//! timing, the saved calibration, the real-time cost, and the list of the
//! files written.

use anyhow::{anyhow, bail, Result};
use hopper_link::Client;
use hopper_protocol::{CostStats, Name, Request, Response, TimingStats};
use std::path::PathBuf;

pub(crate) fn wire_name(name: &str) -> Result<Name> {
    let mut n = Name::new();
    n.push_str(name)
        .map_err(|_| anyhow!("parameter name `{name}` is too long"))?;
    Ok(n)
}

pub(crate) fn get(c: &mut Client, name: &str) -> Result<f32> {
    read_param(c, name)?.map_err(|why| anyhow!("get {name}: {why}"))
}

/// A parameter's value, or the robot's reason for refusing to read it (a
/// name it does not know, or one its configuration lacks); `Err` only when
/// the link failed.
pub(crate) fn read_param(c: &mut Client, name: &str) -> Result<std::result::Result<f32, String>> {
    match c.request(Request::ParamGet {
        name: wire_name(name)?,
    })? {
        Response::Value(v) => Ok(Ok(v)),
        Response::Refused(why) => Ok(Err(why.to_string())),
        r => bail!("unexpected answer {r:?}"),
    }
}

pub(crate) fn status_of(c: &mut Client) -> Result<hopper_protocol::Status> {
    match c.request(Request::Status)? {
        Response::Status(s) => Ok(s),
        r => bail!("unexpected answer {r:?}"),
    }
}

/// A flag parameter, if the robot has it.
pub(crate) fn flag(c: &mut Client, name: &str) -> Option<bool> {
    get(c, name).ok().map(|v| v != 0.0)
}

/// Whether the robot is the planar machine: it has no bring-up routines
/// (its answer to their report is `not-on-this-machine`).
pub(crate) fn is_planar(c: &mut Client) -> Result<bool> {
    Ok(matches!(
        c.request(Request::CalibrationReport)?,
        Response::Refused(why)
            if why.refusal() == Some(hopper_protocol::vocab::Refusal::NotThisMachine)
    ))
}

pub(crate) fn timing_of(c: &mut Client) -> Result<TimingStats> {
    match c.request(Request::Timing)? {
        Response::Timing(t) => Ok(t),
        r => bail!("unexpected answer {r:?}"),
    }
}

pub(crate) fn stored_of(c: &mut Client) -> Result<hopper_protocol::StoredInfo> {
    match c.request(Request::Stored)? {
        Response::Stored(s) => Ok(s),
        r => bail!("unexpected answer {r:?}"),
    }
}

/// The saved calibration's state in words; `require_tare`: whether the
/// robot's arming waits for a tare (`arming.require_tare`; `None`: unknown).
pub(crate) fn stored_line(s: &hopper_protocol::StoredInfo, require_tare: Option<bool>) -> String {
    let defaults = match require_tare {
        Some(true) => "the defaults (tare before arming: arming.require_tare is 1)",
        Some(false) => "the defaults",
        None => "the defaults (tare before arming if arming.require_tare is 1)",
    };
    let refused = || {
        hopper_protocol::vocab::LoadError::from_code(s.boot_error)
            .map_or("unknown", hopper_protocol::vocab::LoadError::name)
    };
    // What this boot loaded, said alone when nothing was saved since.
    let boot = match s.boot {
        0 => "no flash store on this robot".to_string(),
        1 => format!("nothing saved: {defaults}"),
        2 => format!("loaded from flash at boot ({} parameters)", s.entries),
        _ => format!(
            "the saved record was refused at boot ({}): {defaults}",
            refused()
        ),
    };
    // A save since boot is the state now; the boot's record comes after.
    let at_boot = match s.boot {
        0 => "no flash store on this robot".to_string(),
        1 => "nothing was saved at boot".to_string(),
        2 => format!("{} parameters were loaded at boot", s.entries),
        _ => format!("the record was refused at boot ({})", refused()),
    };
    match s.save {
        0 => boot,
        1 => format!("a save is pending; {at_boot}"),
        2 => format!(
            "saved since boot ({} parameters: they load at the next boot); {at_boot}",
            s.saved_count
        ),
        3 => format!("the last save FAILED; {boot}"),
        _ => format!("saved: written to flash at the next restart; {at_boot}"),
    }
}

/// What the robot's real-time work cost, if its firmware reports it.
pub(crate) fn cost_of(c: &mut Client) -> Result<Option<CostStats>> {
    match c.request(Request::Cost) {
        Ok(Response::Cost(k)) => Ok(Some(k)),
        Ok(r) => bail!("unexpected answer {r:?}"),
        // An older firmware does not know the request.
        Err(_) => Ok(None),
    }
}

/// The counter's unit for people.
pub(crate) fn cost_unit(k: &CostStats) -> &'static str {
    if k.counter_hz > 0 {
        "cycles"
    } else {
        "instructions (QEMU; 0 on the host simulator)"
    }
}

/// The `timing:` line: what paces the periods, the last late one and why,
/// and the bytes the serial line lost.
fn timing_line(k: &CostStats) -> String {
    use hopper_protocol::vocab::{LateCause, Pacing};
    let pacing = Pacing::from_code(k.pacing)
        .map_or_else(|| format!("code {}", k.pacing), |p| p.name().to_string());
    let late = if k.late_period == hopper_protocol::NO_LATE_PERIOD {
        "no period late".to_string()
    } else {
        let how = match LateCause::from_code(k.late_cause) {
            Some(LateCause::Start) => format!(
                "started {:.1} us {}",
                f64::from(k.late_jitter_s.abs()) * 1e6,
                if k.late_jitter_s < 0.0 {
                    "early"
                } else {
                    "late"
                }
            ),
            Some(c) => c.name().to_string(),
            None => format!("late (code {})", k.late_cause),
        };
        format!(
            "last late period {}: {how}, {} serial interrupts from the period before it to the one after",
            k.late_period, k.late_serial
        )
    };
    format!(
        "timing: periods paced by {pacing}; {late}; serial line: {} bytes lost (USART overrun or a full receive queue)",
        k.serial_lost
    )
}

/// The `control interrupt:`, `serial interrupt:`, `link task:` and
/// `timing:` lines of `status` and `flood`.
pub(crate) fn cost_lines(k: &CostStats) -> [String; 4] {
    let us = |n: u32| {
        if k.counter_hz > 0 {
            format!(" = {:.1} us", f64::from(n) * 1e6 / f64::from(k.counter_hz))
        } else {
            String::new()
        }
    };
    [
        format!(
            "control interrupt: mean {} max {}{} {} (entry to exit: read, step, write, publish, at most one command); start jitter max {:.1} us",
            k.isr_mean,
            k.isr_max,
            us(k.isr_max),
            cost_unit(k),
            f64::from(k.max_jitter_s) * 1e6
        ),
        format!(
            "serial interrupt: max {}{} per interrupt, {} so far (preempts the control interrupt; on the board one byte each way an interrupt, about 18 a period at 921,600 baud; QEMU, with no baud rate, moves many in one)",
            k.serial_max,
            us(k.serial_max),
            k.serial_count
        ),
        format!(
            "link task: mean {} max {} per period, below the control interrupt (decode, answer, encode, build sets); {} period notes dropped",
            k.link_mean, k.link_max, k.notes_dropped
        ),
        timing_line(k),
    ]
}

pub(crate) fn print_written(paths: &[PathBuf]) {
    println!(
        "wrote {}",
        paths
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_saved_calibration_line_says_tare_only_when_required() {
        let nothing = hopper_protocol::StoredInfo {
            boot: 1,
            boot_error: 0,
            entries: 0,
            save: 0,
            saved_count: 9,
        };
        assert_eq!(
            stored_line(&nothing, Some(false)),
            "nothing saved: the defaults"
        );
        assert_eq!(
            stored_line(&nothing, Some(true)),
            "nothing saved: the defaults (tare before arming: arming.require_tare is 1)"
        );
        // After a save the line says that, not also "nothing saved".
        let saved = hopper_protocol::StoredInfo {
            save: 2,
            saved_count: 27,
            ..nothing
        };
        let line = stored_line(&saved, Some(true));
        assert_eq!(
            line,
            "saved since boot (27 parameters: they load at the next boot); nothing was saved at boot"
        );
        assert!(!line.contains("nothing saved:"), "{line}");
    }
}
