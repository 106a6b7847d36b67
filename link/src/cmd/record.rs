//! `record`: telemetry, hop ledgers and faults to CSV and MCAP files as
//! they arrive, and a plot of what was saved.

use super::common::{get, print_written, timing_of};
use anyhow::{bail, Result};
use hopper_link::record::Streamed;
use hopper_link::{names, Client};
use hopper_protocol::{Request, Response, RobotMsg};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
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
    let bar = progress(span);
    let ended = stream(c, every, span, &mut Vertical(&mut out_files), &bar)?;
    // Stop the stream, unless the link is what ended the recording.
    if !ended.as_ref().is_some_and(|(_, failed)| *failed) {
        c.expect_ok(Request::Telemetry { every: 0 })?;
    }
    bar.finish_and_clear();
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
    match ended {
        Some((why, failed)) => {
            let saved = format!(
                "{:.3} s of {duration_s} s saved in {}",
                rec.records.len() as f64 * f64::from(every) * period,
                out.display()
            );
            if failed {
                bail!("the recording ended early: {why} ({saved})")
            }
            println!("the recording ended early: {why} ({saved})");
            Ok(())
        }
        None => Ok(()),
    }
}

/// A progress bar over `span` periods, drawn on a terminal only.
pub(crate) fn progress(span: u64) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(span);
    if !std::io::stderr().is_terminal() {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar
}

/// Where a recording's messages go.
pub(crate) trait Sink {
    /// The period number of `m` if it is one of this recording's records.
    fn step(m: &RobotMsg) -> Option<u32>;
    /// Takes a message: a record (after [`Sink::step`] named it), or
    /// another the recording keeps (a hop, a fault).
    fn take(&mut self, m: RobotMsg, bar: &indicatif::ProgressBar) -> Result<()>;
    /// What came so far, on disk.
    fn flush(&mut self) -> Result<()>;
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

/// Streams telemetry every `every` periods into `sink` until `span`
/// periods are recorded, the operator's Ctrl-C, or the link or the
/// robot ends it: why it ended early and whether that is a failure (the
/// link or the robot) rather than the operator's choice.
pub(crate) fn stream<S: Sink>(
    c: &mut Client,
    every: u16,
    span: u64,
    sink: &mut S,
    bar: &indicatif::ProgressBar,
) -> Result<Option<(String, bool)>> {
    let interrupted = interrupt_flag();
    c.discard_events();
    c.expect_ok(Request::Telemetry { every })?;
    // Records before the answer may be from an earlier stream.
    c.discard_queued();
    let mut quiet = Instant::now();
    let (mut first, mut last): (Option<u32>, Option<u32>) = (None, None);
    loop {
        if interrupted.swap(false, Ordering::Relaxed) {
            return Ok(Some(("interrupted (Ctrl-C)".into(), false)));
        }
        let event = match c.next_event(Duration::from_millis(200)) {
            Ok(e) => e,
            Err(e) => return Ok(Some((format!("{e:#}"), true))),
        };
        let Some(m) = event else {
            if quiet.elapsed() > Duration::from_secs(3) {
                return Ok(Some((
                    "no telemetry for 3 s: the robot stopped streaming (a reset, or its link timed out)".into(),
                    true,
                )));
            }
            // Idle: what came so far is on disk.
            sink.flush()?;
            continue;
        };
        if let RobotMsg::State(s) = m {
            bar.suspend(|| println!("state: {}", names::arm_state(s)));
            continue;
        }
        let Some(step) = S::step(&m) else {
            sink.take(m, bar)?;
            continue;
        };
        quiet = Instant::now();
        if let Some(l) = last.filter(|&l| step < l) {
            return Ok(Some((
                format!("the robot restarted (its period count went back from {l} to {step})"),
                true,
            )));
        }
        sink.take(m, bar)?;
        last = Some(step);
        let spanned = u64::from(step.wrapping_sub(*first.get_or_insert(step)));
        bar.set_position(spanned.min(span));
        if spanned + u64::from(every) > span {
            return Ok(None);
        }
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

/// A flag Ctrl-C sets while a recording runs (one handler for the
/// process: a shell's later recordings share it; each clears it first).
pub(crate) fn interrupt_flag() -> Arc<AtomicBool> {
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    let flag = FLAG.get_or_init(|| {
        let f = Arc::new(AtomicBool::new(false));
        let g = f.clone();
        // Without a handler (another library took the signal), Ctrl-C
        // kills the process as before: the files hold what was flushed.
        let _ = ctrlc::set_handler(move || g.store(true, Ordering::Relaxed));
        f
    });
    flag.store(false, Ordering::Relaxed);
    flag.clone()
}
