//! What `record` shares between the two machines: the telemetry
//! streamed into a recording until its span, the operator's Ctrl-C, or
//! the link or the robot ends it, with its progress bar.

use anyhow::{bail, Result};
use hopper_link::{names, Client};
use hopper_protocol::{Request, RobotMsg};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// A progress bar over `span` periods, drawn on a terminal only.
fn progress(span: u64) -> indicatif::ProgressBar {
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

/// Streams telemetry every `every` periods into `sink` until `span`
/// periods are recorded, the operator's Ctrl-C, or the link or the
/// robot ends it, with a progress bar on a terminal; then stops the
/// stream, unless the link is what ended it. Why it ended early and
/// whether that is a failure (the link or the robot) rather than the
/// operator's choice.
pub(crate) fn stream<S: Sink>(
    c: &mut Client,
    every: u16,
    span: u64,
    sink: &mut S,
) -> Result<Option<(String, bool)>> {
    let bar = progress(span);
    let ended = stream_into(c, every, span, sink, &bar)?;
    if !ended.as_ref().is_some_and(|(_, failed)| *failed) {
        c.expect_ok(Request::Telemetry { every: 0 })?;
    }
    bar.finish_and_clear();
    Ok(ended)
}

/// How a recording that ended early is reported, `saved` saying what was
/// kept: an error when the link or the robot ended it, a line when the
/// operator did.
pub(crate) fn report_end(ended: Option<(String, bool)>, saved: &str) -> Result<()> {
    match ended {
        Some((why, true)) => bail!("the recording ended early: {why} ({saved})"),
        Some((why, false)) => {
            println!("the recording ended early: {why} ({saved})");
            Ok(())
        }
        None => Ok(()),
    }
}

/// [`stream`]'s loop.
fn stream_into<S: Sink>(
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

/// A flag Ctrl-C sets while a recording runs (one handler for the
/// process: a shell's later recordings share it; each clears it first).
fn interrupt_flag() -> Arc<AtomicBool> {
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
