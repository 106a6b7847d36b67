//! `arm`, `disarm` and `reset-faults`: the robot's arming.

use super::common::status_of;
use anyhow::{anyhow, bail, Result};
use hopper_link::{names, Client};
use hopper_protocol::{Request, Response, RobotMsg};
use std::time::{Duration, Instant};

/// `request`, asked again every 50 ms while the robot refuses it and
/// fewer than `retry` wall seconds have passed (none: asked once). The
/// robot's last answer.
fn request_until_accepted(
    c: &mut Client,
    request: Request,
    retry: Option<f64>,
) -> Result<Response> {
    let start = Instant::now();
    loop {
        match c.request(request.clone())? {
            Response::Refused(_) if start.elapsed().as_secs_f64() < retry.unwrap_or(0.0) => {
                std::thread::sleep(Duration::from_millis(50));
            }
            r => return Ok(r),
        }
    }
}

/// `arm`: asked again until accepted or `retry` wall seconds passed.
pub(crate) fn arm(c: &mut Client, retry: Option<f64>) -> Result<()> {
    match request_until_accepted(c, Request::Arm, retry)? {
        Response::Ok => {
            println!("armed");
            Ok(())
        }
        Response::Refused(why) => bail!("arm refused: {why}{}", next_step(why.refusal())),
        r => bail!("unexpected answer {r:?}"),
    }
}

/// What to do about an arm refusal, in the operator's terms (`""` when
/// the reason says it all).
pub(crate) fn next_step(why: Option<hopper_protocol::vocab::Refusal>) -> &'static str {
    use hopper_protocol::vocab::Refusal as R;
    match why {
        Some(R::Faulted) => ": reset the faults once their cause is gone (`reset-faults`, the cockpit's Reset faults)",
        Some(R::EstopPressed) => ": release the e-stop",
        Some(R::LinkDown) => ": no frame from this host reached the robot in time: check the cable and the baud rate",
        Some(R::SensorsImplausible) => ": a sensor reads out of range: `calibrate sensors` says which",
        Some(R::NutNotHome) => ": drive the nut to its upper stop first (`calibrate home`)",
        Some(R::Moving) => ": wait until the body and the nut are still",
        Some(R::NotCalibrated) => ": tare first (`calibrate tare`, on the hoist with the toe free), or save a calibration and restart",
        Some(R::NotHomed) => ": home the nut first (`calibrate direction`, then `calibrate home`, on the hoist)",
        Some(R::DirectionReversed) => ": the direction check failed: swap the motor's leads or the encoder's A and B, then `calibrate direction` again",
        Some(R::Calibrating) => ": a bring-up routine is running: wait until it ends",
        Some(R::ClockFallback | R::CrystalMismatch) => ": the core clock is not the profile's (docs/board.md, \"Clock profiles\")",
        Some(R::BrownOutResetOff) => ": set the brown-out reset in the option bytes (docs/board.md, \"What AMP_EN and the DAC do through each reset cause\")",
        _ => "",
    }
}

pub(crate) fn disarm(c: &mut Client) -> Result<()> {
    c.expect_ok(Request::Telemetry { every: 1 })?;
    c.discard_events();
    c.expect_ok(Request::Disarm)?;
    let deadline = Instant::now() + Duration::from_secs(3);
    // The first record disarmed, and what its amplifiers are told.
    let next = loop {
        match c.next_event(deadline.saturating_duration_since(Instant::now()))? {
            Some(RobotMsg::Telemetry(t)) if !t.armed => {
                break Some((
                    t.step,
                    format!("command {:.3} A", t.command_a),
                    t.command_a == 0.0,
                ))
            }
            Some(RobotMsg::Planar(t)) if !t.armed => {
                break Some((
                    t.step,
                    format!("hip {:.3} A, leg {:.3} A", t.hip_current_a, t.leg_current_a),
                    t.hip_current_a == 0.0 && t.leg_current_a == 0.0,
                ))
            }
            Some(_) => {}
            None => break None,
        }
    };
    c.expect_ok(Request::Telemetry { every: 0 })?;
    let (step, told, zero) =
        next.ok_or_else(|| anyhow!("no disarmed telemetry record within 3 s"))?;
    println!("disarmed; next record: step {step}, armed false, {told}");
    if !zero {
        bail!("the record after the disarm still drives the motor: {told}");
    }
    Ok(())
}

/// `reset-faults`: clear the latched faults whose cause is gone, asked
/// again until accepted or `retry` wall seconds passed (a cause ends in
/// the robot's time: an e-stop's release is debounced there).
pub(crate) fn reset_faults(c: &mut Client, retry: Option<f64>) -> Result<()> {
    let r = request_until_accepted(c, Request::ResetFaults, retry)?;
    let st = status_of(c)?;
    match r {
        Response::Ok => {
            println!("faults reset; latched now: {}", names::faults(st.faults));
            Ok(())
        }
        Response::Refused(why) => {
            // The planar machine's posture faults have no bit: its
            // telemetry names them.
            let planar = match super::status::one_record(c) {
                Ok(super::status::Record::Planar(t)) => format!(
                    "; the planar machine's guard: {}",
                    super::status::planar_fault(t.fault)
                ),
                _ => String::new(),
            };
            bail!(
                "reset refused: {why}; still latched: {}{planar}",
                names::faults(st.faults)
            )
        }
        r => bail!("unexpected answer {r:?}"),
    }
}
