//! `flood` and `garbage`: load the link with requests and noise.

use super::common::{cost_lines, cost_of, cost_unit, status_of, timing_of, wire_name};
use anyhow::{bail, Result};
use hopper_link::{names, Client};
use hopper_protocol::{HostMsg, Request, Response, RobotMsg};
use std::time::{Duration, Instant};

pub(crate) fn flood(c: &mut Client, seconds: f64) -> Result<()> {
    let n_params = match c.request(Request::ParamCount)? {
        Response::ParamCount(n) => n,
        r => bail!("unexpected answer {r:?}"),
    };
    // (Also starts the robot's window of `isr_max_recent`.)
    let _ = cost_of(c)?;
    let before = status_of(c)?;
    let t = timing_of(c)?;
    let missed_before = t.missed;
    let periods = (seconds / f64::from(t.period_s)).round() as u32;
    let mut now = before.periods;
    let apex = wire_name("target_apex_m")?;
    let start = Instant::now();
    let (mut sent, mut answered, mut refused_sets, mut garbage) = (0u64, 0u64, 0u64, 0u64);
    let mut index = 0u16;
    let mut id = 40_000u16;
    let mut x: u64 = 0x2545_F491_4F6C_DD1D;
    while now.wrapping_sub(before.periods) < periods {
        // One burst: 24 requests answered without a command to the control
        // period, and 64 bytes of noise.
        let mut bytes = Vec::new();
        let mut ids = Vec::new();
        for k in 0..24u16 {
            let req = match k % 6 {
                0 | 1 => {
                    index = (index + 1) % n_params.max(1);
                    Request::ParamInfo { index }
                }
                2 => Request::Status,
                3 => Request::ParamGet { name: apex.clone() },
                4 => Request::ParamSet {
                    name: apex.clone(),
                    value: 2.0,
                },
                _ if k == 23 => Request::Dump,
                _ => Request::Timing,
            };
            id = id.wrapping_add(1).max(40_000);
            ids.push(id);
            bytes.extend(hopper_link::frame(&HostMsg::Request { id, req })?);
        }
        for _ in 0..64 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            bytes.push((x >> 24) as u8);
        }
        bytes.push(0);
        garbage += 64;
        c.send_raw(&bytes)?;
        sent += ids.len() as u64;
        let deadline = Instant::now() + Duration::from_secs(3);
        let mut left = ids.len();
        while left > 0 {
            match c.next_event(deadline.saturating_duration_since(Instant::now()))? {
                Some(RobotMsg::Response { id: got, resp }) if ids.contains(&got) => {
                    left -= 1;
                    answered += 1;
                    if let Response::Status(s) = &resp {
                        now = s.periods;
                    }
                    if let (Some(4), Response::Refused(_)) =
                        (ids.iter().position(|i| *i == got).map(|p| p % 6), &resp)
                    {
                        refused_sets += 1;
                    }
                }
                Some(_) => {}
                None => bail!(
                    "{left} of a burst's {} requests unanswered within 3 s",
                    ids.len()
                ),
            }
        }
        c.discard_events();
    }
    let wall = start.elapsed().as_secs_f64();
    let after = status_of(c)?;
    let missed = timing_of(c)?.missed.saturating_sub(missed_before);
    println!(
        "flood: {seconds} s of robot time ({} periods, {wall:.1} s wall), {sent} requests ({:.0} per robot s), {answered} answered, {refused_sets} out-of-range sets refused, {garbage} bytes of garbage",
        after.periods.wrapping_sub(before.periods),
        sent as f64 / seconds
    );
    println!(
        "after the flood: {}, faults {}, missed deadlines {missed} during it",
        names::arm_state(after.arm),
        names::faults(after.faults)
    );
    match cost_of(c)? {
        Some(k) => {
            println!(
                "during the flood: control interrupt max {} {}",
                k.isr_max_recent,
                cost_unit(&k)
            );
            for l in cost_lines(&k) {
                println!("{l}");
            }
        }
        None => println!("control interrupt: not reported by this firmware"),
    }
    Ok(())
}

/// `garbage`: `bytes` random bytes (a noisy line), then a frame delimiter.
pub(crate) fn garbage(c: &mut Client, bytes: usize) -> Result<()> {
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    let junk: Vec<u8> = (0..bytes)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect();
    c.send_raw(&junk)?;
    c.send_raw(&[0])?;
    println!("sent {bytes} random bytes and a delimiter");
    Ok(())
}
