//! `status`: state, faults, sensors, link counts and timing, and what
//! arming needs on this robot.

use super::common::{cost_lines, cost_of, flag, get, status_of, stored_line, stored_of, timing_of};
use anyhow::{anyhow, bail, Result};
use hopper_link::{names, Client};
use hopper_protocol::{
    PlanarTelemetry, Request, Response, RobotMsg, Status, Telemetry, ThermalStatus,
};
use std::time::{Duration, Instant};

pub(crate) fn status(c: &mut Client) -> Result<()> {
    let s = status_of(c)?;
    let t = timing_of(c)?;
    let period = f64::from(t.period_s);
    let r = match one_record(c)? {
        Record::Vertical(r) => r,
        Record::Planar(r) => return planar_status(c, &s, period, &r),
    };
    println!(
        "state: {}: {}",
        names::arm_state(s.arm),
        names::advice(s.arm)
    );
    println!("faults: {}", names::faults(s.faults));
    println!(
        "sensors: body height {:.4} m, nut {:.2} mm, spring force {:.1} N, energy {:.2} J, command {:.2} A, phase {}",
        r.body_height_m,
        r.nut_position_m * 1000.0,
        r.spring_force_n,
        r.energy_j,
        r.command_a,
        if r.phase == 1 { "stance" } else { "flight" }
    );
    println!(
        "periods: {} ({:.3} s at {:.0} Hz), missed deadlines {}",
        s.periods,
        f64::from(s.periods) * period,
        1.0 / period,
        t.missed
    );
    link_line(c, &s);
    let l = match c.request(Request::LinkCounts)? {
        Response::LinkCounts(l) => l,
        r => bail!("unexpected answer {r:?}"),
    };
    let (h, hc) = (c.stats(), c.counts());
    println!(
        "link losses: robot got {} bad CRC, {} bad COBS, {} too long, {} unknown message; serial overrun {}, framing {}, noise {}, queue full {}; repeated requests answered from memory {} ({} while in flight), applied twice {}",
        l.bad_crc,
        l.bad_cobs,
        l.too_long,
        l.unknown_message,
        l.serial_overrun,
        l.serial_framing,
        l.serial_noise,
        l.serial_full,
        l.repeats_answered,
        l.repeats_in_flight,
        l.applied_twice
    );
    println!(
        "link losses: host got {} bad CRC, {} bad COBS, {} too long, {} unknown message; {} requests, {} sent again ({} answered after), {} failed; {} telemetry records missing",
        h.bad_crc,
        h.bad_cobs,
        h.too_long,
        h.bad_message,
        hc.requests,
        hc.retries,
        hc.answered_after_retry,
        hc.failed,
        hc.telemetry_gaps
    );
    if s.last_apex_m.is_finite() {
        println!("last apex: {:.4} m", s.last_apex_m);
    } else {
        println!("last apex: none yet");
    }
    let b = match c.request(Request::Boot)? {
        Response::Boot(b) => b,
        r => bail!("unexpected answer {r:?}"),
    };
    let resets: Vec<&str> = hopper_protocol::vocab::ResetCause::in_set(b.resets)
        .map(hopper_protocol::vocab::ResetCause::name)
        .collect();
    println!(
        "boot: reset by {}; core clock {:.0} MHz{}; brown-out reset {}",
        if resets.is_empty() {
            "nothing recorded".to_string()
        } else {
            resets.join(", ")
        },
        f64::from(b.sysclk_hz) / 1e6,
        if b.clock_as_configured {
            " as configured"
        } else {
            ", NOT the configured clock (arming refused: clock-fallback)"
        },
        if b.brown_out_reset_on {
            "on"
        } else {
            "OFF (arming refused: brown-out-reset-off; set BOR_LEV in the option bytes, docs/safety.md)"
        }
    );
    match c.request(Request::Crystal)? {
        Response::Crystal(x) if x.expected_hz == 0 => {}
        Response::Crystal(x) => println!(
            "crystal: {}; the profile names {:.3} MHz{}",
            if x.measured_hz == 0 {
                "not measured (it did not start)".to_string()
            } else {
                format!(
                    "{:.3} MHz measured against the internal oscillator",
                    f64::from(x.measured_hz) / 1e6
                )
            },
            f64::from(x.expected_hz) / 1e6,
            if x.measured_hz != 0 && !x.matches {
                " (arming refused: crystal-not-the-profiles: build for this board's crystal, docs/board.md)"
            } else {
                ""
            }
        ),
        r => bail!("unexpected answer {r:?}"),
    }
    let arming = ArmingParams::read(c);
    println!(
        "calibration: {}",
        stored_line(&stored_of(c)?, arming.require_tare)
    );
    println!("arming: {}", arming.requirements());
    match c.request(Request::ThermalBoot) {
        Ok(Response::ThermalBoot(b)) => println!(
            "motor estimate at boot: winding {:.1} C ({})",
            b.winding_c,
            if b.assumed_hot {
                "assumed hot, at the derating temperature: nothing of the motor's heat survives a reset or a power cycle on this robot"
            } else {
                "ambient: a simulated motor, cold at start"
            }
        ),
        Ok(r) => bail!("unexpected answer {r:?}"),
        // An older firmware does not know the request.
        Err(_) => {}
    }
    let m = thermal_of(c)?;
    println!(
        "motor (estimated): winding {:.1} C, housing {:.1} C; current limit {:.0}% (derates from {:.0} C, trips at {:.0} C{})",
        m.winding_c,
        m.housing_c,
        m.limit_scale * 100.0,
        m.derate_c,
        m.trip_c,
        if m.protect { "" } else { "; protection off" }
    );
    println!(
        "cost per period (robot counter ticks: board cycles, QEMU instructions, simulator 0): control step mean {} max {}, link mean {} max {}",
        t.step_mean, t.step_max, t.link_mean, t.link_max
    );
    match cost_of(c)? {
        Some(k) => {
            for l in cost_lines(&k) {
                println!("{l}");
            }
        }
        None => println!("control interrupt: not reported by this firmware"),
    }
    Ok(())
}

/// The `arming.*` parameters of the robot that decide what arming needs
/// (`None`: the robot did not say; its firmware may lack the parameter).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct ArmingParams {
    link_timeout_s: Option<f32>,
    untethered: Option<bool>,
    home_tolerance_m: Option<f32>,
    still_velocity_mps: Option<f32>,
    require_tare: Option<bool>,
    require_home: Option<bool>,
}

impl ArmingParams {
    fn read(c: &mut Client) -> Self {
        Self {
            link_timeout_s: get(c, "arming.link_timeout_s").ok(),
            untethered: flag(c, "arming.untethered"),
            home_tolerance_m: get(c, "arming.home_tolerance_m").ok(),
            still_velocity_mps: get(c, "arming.still_velocity_mps").ok(),
            require_tare: flag(c, "arming.require_tare"),
            require_home: flag(c, "arming.require_home"),
        }
    }

    /// What an arm request needs on this robot, in the order the robot
    /// checks (`arming::Arming::refusal`), the boot checks aside (the
    /// `boot:` and `crystal:` lines say when those refuse).
    fn requirements(&self) -> String {
        let mut needs = vec![
            "no latched fault".to_string(),
            "the e-stop released".to_string(),
            "no bring-up routine running".to_string(),
        ];
        let mut not = Vec::new();
        match self.require_home {
            Some(true) => needs.push(
                "the nut homed since boot (`calibrate direction`, `calibrate home`; arming.require_home is 1)"
                    .to_string(),
            ),
            Some(false) => not.push("homing (arming.require_home is 0)"),
            None => {}
        }
        match self.require_tare {
            Some(true) => needs.push(
                "a tare since boot or a saved calibration loaded at boot (`calibrate tare`; arming.require_tare is 1)"
                    .to_string(),
            ),
            Some(false) => not.push("a tare (arming.require_tare is 0)"),
            None => {}
        }
        match (self.untethered, self.link_timeout_s) {
            (Some(true), _) => not.push("the link (arming.untethered is 1)"),
            (_, Some(t)) => needs.push(format!("the link up (a frame from the host within {t} s)")),
            (_, None) => needs.push("the link up".to_string()),
        }
        needs.push("plausible sensors".to_string());
        needs.push(match self.home_tolerance_m {
            Some(m) => format!("the nut within {:.1} mm of its upper stop", m * 1000.0),
            None => "the nut at its upper stop".to_string(),
        });
        needs.push(match self.still_velocity_mps {
            Some(v) => format!("nut and body slower than {v} m/s"),
            None => "nut and body still".to_string(),
        });
        let mut line = format!("needs {}", needs.join(", "));
        if !not.is_empty() {
            line += &format!("; not required: {}", not.join(", "));
        }
        line
    }
}

fn thermal_of(c: &mut Client) -> Result<ThermalStatus> {
    match c.request(Request::Thermal)? {
        Response::Thermal(t) => Ok(t),
        r => bail!("unexpected answer {r:?}"),
    }
}

/// The link's counts, both ends.
fn link_line(c: &Client, s: &Status) {
    println!(
        "link: {} frames in, {} bad; {} telemetry records not sent; host got {} frames, {} bad",
        s.frames_ok,
        s.frames_bad,
        s.telemetry_dropped,
        c.stats().ok,
        c.stats().bad()
    );
}

/// One record of the robot's telemetry, of either machine.
pub(crate) enum Record {
    /// The vertical hopper's.
    Vertical(Telemetry),
    /// The planar machine's.
    Planar(PlanarTelemetry),
}

/// One telemetry record now (telemetry is switched on for it, then off).
pub(crate) fn one_record(c: &mut Client) -> Result<Record> {
    // Every 100th period: any line carries that. Records queued before
    // the answer may be stale (an earlier stream): only later ones count.
    c.expect_ok(Request::Telemetry { every: 100 })?;
    c.discard_queued();
    let deadline = Instant::now() + Duration::from_secs(3);
    let found = loop {
        match c.next_event(deadline.saturating_duration_since(Instant::now()))? {
            Some(RobotMsg::Telemetry(t)) => break Some(Record::Vertical(t)),
            Some(RobotMsg::Planar(t)) => break Some(Record::Planar(t)),
            Some(_) => {}
            None => break None,
        }
    };
    c.expect_ok(Request::Telemetry { every: 0 })?;
    found.ok_or_else(|| anyhow!("no telemetry record within 3 s"))
}

/// The planar guard's latch by name (`none` for nothing).
pub(crate) fn planar_fault(code: u8) -> String {
    match code {
        0 => "none".to_string(),
        c => hopper_protocol::vocab::PlanarFault::from_code(c)
            .map_or_else(|| format!("planar fault {c}"), |f| f.name().to_string()),
    }
}

/// `status` of the planar machine: its state, what its guard latched,
/// the machine as its firmware estimates it, and the link's counts.
fn planar_status(c: &mut Client, s: &Status, period_s: f64, r: &PlanarTelemetry) -> Result<()> {
    println!(
        "state: {}: {}",
        names::arm_state(s.arm),
        names::advice(s.arm)
    );
    println!(
        "faults: {}; the planar machine's guard: {}",
        names::faults(s.faults),
        planar_fault(r.fault)
    );
    println!(
        "planar machine: hip at x {:.3} m, height {:.4} m, pitch {:.2} deg, leg {:.2} deg and {:.4} m, {}; speed {:.3} m/s (command {:.2}); hip {:.2} A, leg {:.2} A",
        r.x_m,
        r.z_m,
        r.pitch_rad.to_degrees(),
        r.leg_angle_rad.to_degrees(),
        r.leg_length_m,
        if r.stance { "stance" } else { "flight" },
        r.speed_mps,
        r.speed_command_mps,
        r.hip_current_a,
        r.leg_current_a
    );
    println!(
        "periods: {} ({:.3} s at {:.0} Hz)",
        s.periods,
        f64::from(s.periods) * period_s,
        1.0 / period_s
    );
    link_line(c, s);
    if s.last_apex_m.is_finite() {
        println!("last apex: {:.4} m", s.last_apex_m);
    } else {
        println!("last apex: none yet");
    }
    if let Response::Thermal(th) = c.request(Request::Thermal)? {
        println!(
            "motors: the hotter winding at {:.1} C (derates at {:.0} C, trips at {:.0} C), its current limit at {:.0}%",
            th.winding_c,
            th.derate_c,
            th.trip_c,
            100.0 * th.limit_scale
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arming_requirements_follow_the_robots_parameters() {
        let mut a = ArmingParams {
            link_timeout_s: Some(0.2),
            untethered: Some(false),
            home_tolerance_m: Some(0.001),
            still_velocity_mps: Some(0.05),
            require_tare: Some(false),
            require_home: Some(false),
        };
        let line = a.requirements();
        assert!(
            line.contains("the nut within 1.0 mm of its upper stop"),
            "{line}"
        );
        assert!(
            line.contains("a frame from the host within 0.2 s"),
            "{line}"
        );
        assert!(
            line.ends_with(
                "not required: homing (arming.require_home is 0), a tare (arming.require_tare is 0)"
            ),
            "{line}"
        );
        assert!(
            !line.contains("needs a tare") && !line.contains("tare since boot"),
            "{line}"
        );
        a.require_tare = Some(true);
        a.require_home = Some(true);
        a.untethered = Some(true);
        let line = a.requirements();
        assert!(line.contains("a tare since boot"), "{line}");
        assert!(line.contains("the nut homed since boot"), "{line}");
        assert!(
            line.contains("not required: the link (arming.untethered is 1)"),
            "{line}"
        );
        // A robot that does not say: neither claimed.
        let line = ArmingParams::default().requirements();
        assert!(!line.contains("tare") && !line.contains("homed"), "{line}");
    }
}
