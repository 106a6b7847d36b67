//! `silence`: stop the heartbeats and time the robot's disarm by link loss.

use super::common::{get, status_of, timing_of};
use anyhow::{anyhow, bail, Result};
use hopper_link::{names, Client};
use hopper_protocol::{ArmState, Request, RobotMsg};
use std::time::{Duration, Instant};

pub(crate) fn silence(c: &mut Client, max_s: f64) -> Result<()> {
    if status_of(c)?.arm != ArmState::Armed {
        bail!("the robot is not armed: arm it first");
    }
    let timeout_s = get(c, "arming.link_timeout_s")?;
    let t = timing_of(c)?;
    let period = f64::from(t.period_s);
    let every = ((0.001 / period).round() as u16).max(1);
    c.expect_ok(Request::Telemetry { every })?;
    // Heartbeats off, then one last frame of our own: a status request,
    // whose answer gives the period the robot received it in. From there
    // to the first disarmed record is the robot's own quiet time, exactly
    // (the host's lag does not enter).
    c.set_heartbeats(false);
    std::thread::sleep(2 * hopper_link::HEARTBEAT);
    // Sent once: a repeat would be a later last frame than the answer's.
    let from = match c.request_once(Request::Status)? {
        hopper_protocol::Response::Status(s) => s.periods,
        r => bail!("unexpected answer {r:?}"),
    };
    c.discard_queued();
    let start = Instant::now();
    let mut disarmed_at = None;
    let mut reason = None;
    while start.elapsed().as_secs_f64() < max_s {
        match c.next_event(Duration::from_millis(100))? {
            // Only records after the last frame (wrapping comparison).
            Some(RobotMsg::Telemetry(r))
                if !r.armed && disarmed_at.is_none() && (r.step.wrapping_sub(from) as i32) >= 0 =>
            {
                disarmed_at = Some(r.step)
            }
            Some(RobotMsg::State(s @ ArmState::Disarmed(_))) => reason = Some(s),
            _ => {}
        }
        if disarmed_at.is_some() && reason.is_some() {
            break;
        }
    }
    c.set_heartbeats(true);
    c.expect_ok(Request::Telemetry { every: 0 })?;
    let at =
        disarmed_at.ok_or_else(|| anyhow!("still armed {max_s} s after the heartbeats stopped"))?;
    let quiet_s = f64::from(at.wrapping_sub(from)) * period;
    println!(
        "{} {quiet_s:.4} s of robot time after the robot received the host's last frame (link timeout {timeout_s:.3} s)",
        reason.map_or("disarmed".to_string(), names::arm_state)
    );
    if reason != Some(ArmState::Disarmed(5)) {
        bail!("disarmed for another reason: {:?}", reason);
    }
    Ok(())
}
