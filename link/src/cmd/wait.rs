//! `wait`: the link stays up, heartbeats go on.

use anyhow::Result;
use std::time::Duration;

/// `wait SECONDS`: sleep, at most an hour.
pub(crate) fn wait(seconds: f64) -> Result<()> {
    std::thread::sleep(Duration::from_secs_f64(seconds.clamp(0.0, 3600.0)));
    Ok(())
}
