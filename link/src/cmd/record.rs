//! `record`: telemetry, hop ledgers and faults to CSV and MCAP files as
//! they arrive, and a plot of what was saved.

use super::common::{get, print_written, timing_of};
use super::stream::{report_end, stream, Sink};
use anyhow::{bail, Result};
use hopper_link::record::Streamed;
use hopper_link::{names, Client};
use hopper_protocol::{Request, Response, RobotMsg};

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
    if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= (1.0 + 1e-6) / period) {
        bail!(
            "--rate {rate_hz} must be in (0, {:.0}] Hz (the control rate)",
            1.0 / period
        );
    }
    let every = (1.0 / (rate_hz * period)).round().clamp(1.0, 65535.0) as u16;
    if super::common::is_planar(c)? {
        return super::record_planar::record(c, duration_s, every, period, out);
    }
    let target = get(c, "target_apex_m").ok().map(f64::from);
    let controllers = names::controller_names(c)?;
    let controller = get(c, names::CONTROLLER)
        .ok()
        .and_then(|v| controllers.get(v as usize).map(String::as_str))
        .unwrap_or("the controller");
    let parameters = all_parameters(c)?;
    let mut out_files = Streamed::create(out, period, &parameters)?;
    let span = (duration_s / period).round() as u64;
    let ended = stream(c, every, span, &mut Vertical(&mut out_files))?;
    let title = format!("{controller} on the robot ({})", c.target());
    let (rec, written) = out_files.finish("hop.png", &title, target)?;
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
        if apexes.is_empty() {
            "none".to_string()
        } else {
            apexes
                .iter()
                .map(|a| format!("{a:.4}"))
                .collect::<Vec<_>>()
                .join(" ")
        }
    );
    if let (Some(s), Some(t)) = (hopper_model::metrics::steady_apex(&apexes), target) {
        println!(
            "steady apex: {s:.4} m (target {t:.4} m, {:+.1}%)",
            (s - t) / t * 100.0
        );
    }
    print_written(&written);
    let saved = format!(
        "{:.3} s of {duration_s} s saved in {}",
        rec.records.len() as f64 * f64::from(every) * period,
        out.display()
    );
    report_end(ended, &saved)
}

/// The vertical hopper's records, hops and faults into its files.
struct Vertical<'a>(&'a mut Streamed);

impl Sink for Vertical<'_> {
    fn step(m: &RobotMsg) -> Option<u32> {
        match m {
            RobotMsg::Telemetry(t) => Some(t.step),
            _ => None,
        }
    }

    fn take(&mut self, m: RobotMsg, bar: &indicatif::ProgressBar) -> Result<()> {
        match m {
            RobotMsg::Telemetry(t) => self.0.record(t),
            RobotMsg::Hop(h) => self.0.hop(h),
            RobotMsg::Faults { step, bits } => {
                bar.suspend(|| {
                    println!("fault at step {step}: {}", names::faults(bits));
                });
                self.0.fault(step, bits)
            }
            _ => Ok(()),
        }
    }

    fn flush(&mut self) -> Result<()> {
        self.0.flush()
    }
}

/// Every parameter's name and value (NaN: not in the robot's
/// configuration), for the recording's `/parameters`.
pub(crate) fn all_parameters(c: &mut Client) -> Result<Vec<(String, f32)>> {
    let n = match c.request(Request::ParamCount)? {
        Response::ParamCount(n) => n,
        r => bail!("unexpected answer {r:?}"),
    };
    (0..n)
        .map(|index| match c.request(Request::ParamInfo { index })? {
            Response::ParamInfo(p) => Ok((p.name.as_str().to_string(), p.value)),
            r => bail!("parameter {index}: unexpected answer {r:?}"),
        })
        .collect()
}
