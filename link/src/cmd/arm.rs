//! `arm`, `disarm` and `reset-faults`: the robot's arming.

use super::common::status_of;
use anyhow::{anyhow, bail, Result};
use hopper_link::{names, Client};
use hopper_protocol::{Request, Response, RobotMsg};
use std::time::{Duration, Instant};

/// `arm`: asked again until accepted or `retry` wall seconds passed.
pub(crate) fn arm(c: &mut Client, retry: Option<f64>) -> Result<()> {
    let start = Instant::now();
    loop {
        match c.request(Request::Arm)? {
            Response::Ok => {
                println!("armed");
                return Ok(());
            }
            Response::Refused(why) if start.elapsed().as_secs_f64() < retry.unwrap_or(0.0) => {
                let _ = why;
                std::thread::sleep(Duration::from_millis(50));
            }
            Response::Refused(why) => bail!("arm refused: {why}"),
            r => bail!("unexpected answer {r:?}"),
        }
    }
}

pub(crate) fn disarm(c: &mut Client) -> Result<()> {
    c.expect_ok(Request::Telemetry { every: 1 })?;
    c.discard_events();
    c.expect_ok(Request::Disarm)?;
    let deadline = Instant::now() + Duration::from_secs(3);
    let next = loop {
        match c.next_event(deadline.saturating_duration_since(Instant::now()))? {
            Some(RobotMsg::Telemetry(t)) if !t.armed => break Some(t),
            Some(_) => {}
            None => break None,
        }
    };
    c.expect_ok(Request::Telemetry { every: 0 })?;
    let t = next.ok_or_else(|| anyhow!("no disarmed telemetry record within 3 s"))?;
    println!(
        "disarmed; next record: step {}, armed {}, command {:.3} A",
        t.step, t.armed, t.command_a
    );
    if t.command_a != 0.0 {
        bail!("the record after the disarm commands {} A", t.command_a);
    }
    Ok(())
}

/// `reset-faults`: clear the latched faults whose cause is gone.
pub(crate) fn reset_faults(c: &mut Client) -> Result<()> {
    let r = c.request(Request::ResetFaults)?;
    let st = status_of(c)?;
    match r {
        Response::Ok => {
            println!("faults reset; latched now: {}", names::faults(st.faults));
            Ok(())
        }
        Response::Refused(why) => bail!(
            "reset refused: {why}; still latched: {}",
            names::faults(st.faults)
        ),
        r => bail!("unexpected answer {r:?}"),
    }
}
