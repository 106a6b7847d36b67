//! `dump`: the capture around the last fault to a CSV file and a plot.

use super::common::{print_written, status_of, timing_of};
use anyhow::{bail, Result};
use hopper_link::record::Recording;
use hopper_link::{names, Client};
use hopper_protocol::{DumpInfo, Request, Response, RobotMsg};
use std::time::{Duration, Instant};

pub(crate) fn dump(c: &mut Client, out: &std::path::Path) -> Result<()> {
    let st = status_of(c)?;
    // Nothing else is listening: what came before the capture is dropped.
    c.discard_events();
    let (rec, info) = fetch(c, &mut |_| Ok(()))?;
    let written = rec.write_capture(out, &title(&rec, &info))?;
    println!("{}", summary(&rec, &info, st.faults));
    print_written(&written);
    Ok(())
}

/// The capture around the last fault (or of the latest periods), read
/// from the robot; every other message that comes meanwhile goes to
/// `other` (a recording in progress loses nothing).
pub(crate) fn fetch(
    c: &mut Client,
    other: &mut dyn FnMut(RobotMsg) -> Result<()>,
) -> Result<(Recording, DumpInfo)> {
    let t = timing_of(c)?;
    // A fault latched less than a quarter capture ago is still being
    // captured: ask again until the capture froze (a fresh dump restarts).
    let asked = Instant::now();
    let info = loop {
        let info = match c.request(Request::Dump)? {
            Response::Dump(i) => i,
            r => bail!("unexpected answer {r:?}"),
        };
        sort(c, other)?;
        if info.frozen || info.fault_step == 0 || asked.elapsed() > Duration::from_secs(5) {
            break info;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let mut rec = Recording {
        period_s: f64::from(t.period_s),
        ..Recording::default()
    };
    let mut quiet = Instant::now();
    while rec.records.len() < usize::from(info.records) {
        match c.next_event(Duration::from_millis(200))? {
            // In order, or from an earlier dump: skip those.
            Some(RobotMsg::Captured(r)) if r.seq as usize == rec.records.len() => {
                quiet = Instant::now();
                rec.records.push(r);
            }
            Some(RobotMsg::Captured(_)) => {}
            Some(m) => other(m)?,
            None if quiet.elapsed() > Duration::from_secs(5) => bail!(
                "the dump stopped after {} of {} records",
                rec.records.len(),
                info.records
            ),
            None => {}
        }
    }
    if info.frozen {
        rec.t0_step = Some(info.fault_step);
    }
    Ok((rec, info))
}

/// Records that came before an answer belong to an earlier dump still
/// draining from the robot's queue: dropped; the rest to `other`.
fn sort(c: &mut Client, other: &mut dyn FnMut(RobotMsg) -> Result<()>) -> Result<()> {
    for m in c.take_queued() {
        if !matches!(m, RobotMsg::Captured(_)) {
            other(m)?;
        }
    }
    Ok(())
}

/// The capture plot's title.
pub(crate) fn title(rec: &Recording, info: &DumpInfo) -> String {
    if info.frozen {
        // The faults of the first period after the fault's: what latched.
        let latched = rec
            .records
            .iter()
            .find(|r| r.step.wrapping_sub(info.fault_step) as i32 >= 0 && r.faults != 0)
            .map_or_else(String::new, |r| format!(" ({})", names::faults(r.faults)));
        format!(
            "capture around the fault{latched} at step {} (t = 0 there)",
            info.fault_step
        )
    } else {
        "capture of the latest periods (no fault)".to_string()
    }
}

/// One line on what the capture holds; `latched` the faults latched now.
pub(crate) fn summary(rec: &Recording, info: &DumpInfo, latched: u16) -> String {
    let span_ms = rec.records.len() as f64 * rec.period_s * 1000.0;
    if info.frozen {
        format!(
            "capture: {} records ({span_ms:.1} ms), frozen by the fault at step {}; latched now: {}",
            rec.records.len(),
            info.fault_step,
            names::faults(latched)
        )
    } else {
        format!(
            "capture: {} records ({span_ms:.1} ms) of the latest periods; no fault froze it",
            rec.records.len()
        )
    }
}
