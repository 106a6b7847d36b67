//! `record`: telemetry and hop ledgers to CSV files and a plot.

use super::common::{get, print_written, timing_of};
use anyhow::{bail, Result};
use hopper_link::record::Recording;
use hopper_link::{names, Client};
use hopper_protocol::{Request, RobotMsg};
use std::io::IsTerminal;
use std::time::{Duration, Instant};

pub(crate) fn record(
    c: &mut Client,
    duration_s: f64,
    rate_hz: f64,
    out: &std::path::Path,
) -> Result<()> {
    if !(duration_s.is_finite() && duration_s > 0.0) {
        bail!("--duration {duration_s} must be a positive number of seconds");
    }
    let t = timing_of(c)?;
    let period = f64::from(t.period_s);
    if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= 1.0 / period + 1e-6) {
        bail!(
            "--rate {rate_hz} must be in (0, {:.0}] Hz (the control rate)",
            1.0 / period
        );
    }
    let every = (1.0 / (rate_hz * period)).round().clamp(1.0, 65535.0) as u16;
    let target = get(c, "target_apex_m").ok().map(f64::from);
    let controllers = names::controller_names(c)?;
    let controller = get(c, names::CONTROLLER)
        .ok()
        .and_then(|v| controllers.get(v as usize).map(String::as_str))
        .unwrap_or("the controller");
    let mut rec = Recording {
        period_s: period,
        ..Recording::default()
    };
    let span = (duration_s / period).round() as u64;
    let bar = indicatif::ProgressBar::new(span);
    if !std::io::stderr().is_terminal() {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    c.discard_events();
    c.expect_ok(Request::Telemetry { every })?;
    // Records before the answer may be from an earlier stream.
    c.discard_queued();
    let mut quiet = Instant::now();
    loop {
        match c.next_event(Duration::from_millis(200))? {
            Some(RobotMsg::Telemetry(t)) => {
                quiet = Instant::now();
                let first = rec.records.first().map_or(t.step, |f| f.step);
                let spanned = u64::from(t.step.wrapping_sub(first));
                rec.records.push(t);
                bar.set_position(spanned.min(span));
                if spanned + u64::from(every) > span {
                    break;
                }
            }
            Some(RobotMsg::Hop(h)) => rec.hops.push(h),
            Some(RobotMsg::Faults { step, bits }) => {
                bar.suspend(|| {
                    println!("fault at step {step}: {}", names::faults(bits));
                });
                rec.faults.push((step, bits));
            }
            Some(RobotMsg::State(s)) => bar.suspend(|| println!("state: {}", names::arm_state(s))),
            Some(_) => {}
            None if quiet.elapsed() > Duration::from_secs(3) => {
                bail!("no telemetry for 3 s: the robot stopped streaming")
            }
            None => {}
        }
    }
    c.expect_ok(Request::Telemetry { every: 0 })?;
    bar.finish_and_clear();
    let title = format!("{controller} on the robot ({})", c.target());
    let written = rec.write(out, ("telemetry.csv", "hop.png"), true, &title, target)?;
    let apexes = rec.apexes_m();
    println!(
        "recorded {:.3} s: {} records at {:.0} Hz, {} dropped; {} hops",
        rec.records.len() as f64 * f64::from(every) * period,
        rec.records.len(),
        1.0 / (f64::from(every) * period),
        rec.dropped(),
        rec.hops.len()
    );
    println!(
        "apexes (m): {}",
        apexes
            .iter()
            .map(|a| format!("{a:.4}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    if let (Some(s), Some(t)) = (hopper_model::metrics::steady_apex(&apexes), target) {
        println!(
            "steady apex: {s:.4} m (target {t:.4} m, {:+.1}%)",
            (s - t) / t * 100.0
        );
    }
    print_written(&written);
    Ok(())
}
