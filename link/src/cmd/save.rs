//! `save`: the calibration to the robot's flash.

use super::common::{flag, stored_line, stored_of};
use anyhow::{bail, Result};
use hopper_link::Client;
use hopper_protocol::{vocab::Refusal, Request, Response};
use std::time::{Duration, Instant};

/// `save`: the calibration to flash, and how it went.
pub(crate) fn save(c: &mut Client) -> Result<()> {
    println!("{}", run(c)?);
    Ok(())
}

/// `save`, what happened as one line.
pub(crate) fn run(c: &mut Client) -> Result<String> {
    // `busy`: a change (a routine's results, a set) is still being
    // installed, a few periods at most: asked again for up to 1 s.
    let deadline = Instant::now() + Duration::from_secs(1);
    loop {
        match c.request(Request::Save)? {
            Response::Ok => break,
            Response::Refused(why) if why == Refusal::Busy && Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(10));
            }
            Response::Refused(why) => bail!("save refused: {why}{}", hint(why.refusal())),
            r => bail!("unexpected answer {r:?}"),
        }
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        std::thread::sleep(Duration::from_millis(50));
        let s = stored_of(c)?;
        match s.save {
            1 if Instant::now() < deadline => continue,
            1 => bail!("save: still pending after 5 s"),
            2 => {
                return Ok(format!(
                    "saved: {} calibration parameters to flash (they load at the next boot)",
                    s.saved_count
                ));
            }
            4 => {
                return Ok(
                    "saved: the robot restarts to write its flash (home it again after)".into(),
                );
            }
            _ => {
                let require_tare = flag(c, "arming.require_tare");
                bail!("save failed: {}", stored_line(&s, require_tare))
            }
        }
    }
}

/// What to do about a refusal only the board's flash gives.
fn hint(why: Option<Refusal>) -> &'static str {
    match why {
        Some(Refusal::HardwareWatchdogOption) => {
            ": the board's option bytes start its watchdog at reset (WDG_SW = 0), whose reset would cut the 1-2 s sector erase; set WDG_SW to 1 (docs/board.md, \"Saving to flash\"), then save again"
        }
        Some(Refusal::SupplyLow) => {
            ": the board's supply is below 2.8 V (its voltage detector); a sector erase needs 2.7-3.6 V: check the supply, then save again"
        }
        _ => "",
    }
}
