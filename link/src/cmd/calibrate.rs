//! `calibrate ROUTINE`: a bring-up routine on the robot and what it found.

use super::common::{get, timing_of};
use anyhow::{bail, Result};
use hopper_link::Client;
use hopper_protocol::{Request, Response};
use std::fmt::Write as _;
use std::time::{Duration, Instant};

/// What to do about a routine's refusal, where the reason alone does not
/// say (the bring-up order of docs/bring-up.md).
fn next_step(r: hopper_protocol::vocab::Refusal) -> Option<&'static str> {
    use hopper_protocol::vocab::Refusal as R;
    Some(match r {
        R::LegLoaded => {
            "the leg carries the robot; hang it on the hoist with the toe free (`mount hoist` on a simulated robot), then run it again"
        }
        R::NotOnGround => {
            "the toe is off the ground; stand the robot on its toe with the hoist slack (`mount release` on a simulated robot), then run it again"
        }
        R::EstopPressed => "release the e-stop, then `reset-faults`",
        R::Faulted => "read `status`, fix the cause, then `reset-faults`",
        _ => return None,
    })
}

pub(crate) fn calibrate(c: &mut Client, routine: &str, seconds: f32) -> Result<()> {
    let mut out = String::new();
    let result = run(c, routine, seconds, &mut out);
    print!("{out}");
    result
}

/// `calibrate ROUTINE`, what it found written to `out` (also when it
/// fails: the results say why).
pub(crate) fn run(c: &mut Client, routine: &str, seconds: f32, out: &mut String) -> Result<()> {
    let mut s = start(c, routine, seconds)?;
    loop {
        std::thread::sleep(Duration::from_millis(100));
        if poll(c, &mut s, out)?.is_some() {
            return Ok(());
        }
    }
}

/// A routine the robot accepted: what [`poll`] reports it against.
pub(crate) struct Started {
    routine: String,
    /// The load cell's and potentiometer's offsets before, codes.
    was: (f32, f32),
    lc_gain: f32,
    pot_gain: f32,
    rate: f32,
    limit_s: f32,
    clock: RobotClock,
}

/// How long a routine has run on the robot's own clock, its control
/// periods: a robot may run slower than the wall (a traced QEMU image
/// runs about 1/8 of real time, slower still on a loaded machine), and a
/// routine's length is robot time.
struct RobotClock {
    period_s: f64,
    start: u32,
    /// The last period count read and when it was read.
    last: (u32, Instant),
}

/// Wall time without a new period count before the host gives up on a
/// robot that answers but no longer runs its periods. The robot reports
/// its count every 100 periods (10 ms on a board, about 0.13 s on the
/// traced QEMU image): 10 s allows a robot 1,000 times slower than real
/// time.
const STALL_S: f64 = 10.0;

impl RobotClock {
    fn start(c: &mut Client) -> Result<Self> {
        let t = timing_of(c)?;
        Ok(Self {
            period_s: f64::from(t.period_s),
            start: t.periods,
            last: (t.periods, Instant::now()),
        })
    }

    /// Robot seconds since the start; an error when the periods stopped.
    fn elapsed_s(&mut self, c: &mut Client) -> Result<f64> {
        let now = timing_of(c)?.periods;
        let (last, at) = self.last;
        if now != last {
            self.last = (now, Instant::now());
        } else if at.elapsed().as_secs_f64() > STALL_S {
            bail!(
                "the robot's control periods stopped at period {now} ({STALL_S:.0} s without one): read `status`"
            );
        }
        Ok(f64::from(now.wrapping_sub(self.start)) * self.period_s)
    }
}

/// Starts `routine` on the robot (refused with the reason and the step to
/// take).
pub(crate) fn start(c: &mut Client, routine: &str, seconds: f32) -> Result<Started> {
    use hopper_protocol::vocab::Routine;
    let r = Routine::ALL
        .iter()
        .copied()
        .find(|r| r.name() == routine)
        .unwrap_or(Routine::SensorCheck);
    let code = r.code();
    // A robot without bring-up routines (the planar machine) says so
    // before its calibration parameters are read.
    if super::common::is_planar(c)? {
        bail!(
            "calibrate {routine} refused: {}",
            hopper_protocol::vocab::Refusal::NotThisMachine.name()
        );
    }
    let was = (
        get(c, "calibration.loadcell_offset_code")?,
        get(c, "calibration.pot_offset_code")?,
    );
    let lc_gain = get(c, "calibration.loadcell_gain_n_per_code")?;
    let pot_gain = get(c, "calibration.pot_gain_m_per_code")?;
    let rate = get(c, "supervisor.spring_rate_n_per_m")?;
    let clock = RobotClock::start(c)?;
    match c.request(Request::Calibrate {
        routine: code,
        seconds,
    })? {
        Response::Ok => {}
        Response::Refused(why) => match why.refusal().and_then(next_step) {
            Some(step) => bail!("calibrate {routine} refused: {why}: {step}"),
            None => bail!("calibrate {routine} refused: {why}"),
        },
        r => bail!("unexpected answer {r:?}"),
    }
    // The measuring routines take `seconds` of robot time; the driving ones
    // as long as their moves (homing across the whole stroke: 12 s of
    // robot time).
    let limit_s = if r.drives_motor() {
        60.0
    } else {
        seconds * 20.0 + 5.0
    };
    Ok(Started {
        routine: routine.to_string(),
        was,
        lc_gain,
        pot_gain,
        rate,
        limit_s,
        clock,
    })
}

/// `None` while the routine runs; once it ended, what it found written to
/// `out` (an error if it did not pass).
pub(crate) fn poll(c: &mut Client, s: &mut Started, out: &mut String) -> Result<Option<()>> {
    use hopper_protocol::vocab::{CalState, Routine};
    let Started {
        routine,
        was,
        lc_gain,
        pot_gain,
        rate,
        limit_s,
        clock,
    } = s;
    let (routine, was, lc_gain, pot_gain, rate) =
        (routine.as_str(), *was, *lc_gain, *pot_gain, *rate);
    let r = match c.request(Request::CalibrationReport)? {
        Response::Calibration(r) => r,
        r => bail!("unexpected answer {r:?}"),
    };
    if r.state == CalState::Running.code() {
        if clock.elapsed_s(c)? > f64::from(*limit_s) {
            bail!("calibrate {routine}: still running after {limit_s:.0} s of robot time");
        }
        return Ok(None);
    }
    let state = CalState::from_code(r.state).map_or("unknown", CalState::name);
    let _ = writeln!(
        out,
        "calibrate {routine}: {state}: {} samples; encoders moved by {} (motor) and {} (height) counts",
        r.samples, r.motor_span_counts, r.height_span_counts
    );
    let _ = writeln!(
        out,
        "load cell: mean {:.2} codes, noise {:.2} codes ({:.2} N)",
        r.loadcell_mean_code,
        r.loadcell_std_code,
        r.loadcell_std_code * lc_gain
    );
    let _ = writeln!(
        out,
        "potentiometer: mean {:.2} codes, noise {:.2} codes ({:.3} mm)",
        r.pot_mean_code,
        r.pot_std_code,
        r.pot_std_code * pot_gain * 1000.0
    );
    let b = match c.request(Request::BringupResults)? {
        Response::BringupResults(b) => b,
        r => bail!("unexpected answer {r:?}"),
    };
    print_results(out, routine, &b, r.state == CalState::Done as u8);
    if routine == Routine::Weight.name() {
        let w = match c.request(Request::Weighing)? {
            Response::Weighing(w) => w,
            r => bail!("unexpected answer {r:?}"),
        };
        print_weighing(out, &w);
    }
    if r.state != CalState::Done as u8 {
        bail!("calibrate {routine} {state}");
    }
    if routine == Routine::Weight.name() {
        let _ = writeln!(
        out,
            "weight: calibration.loadcell_gain_n_per_code {lc_gain:.5} -> {:.5} N/code, supervisor.spring_rate_n_per_m {rate:.0} -> {:.0} N/m (applied)",
            get(c, "calibration.loadcell_gain_n_per_code")?,
            get(c, "supervisor.spring_rate_n_per_m")?
        );
    }
    if r.loadcell_offset_code.is_finite() {
        let _ = writeln!(
        out,
            "tare: calibration.loadcell_offset_code {:.2} -> {:.2} codes ({:+.2} N), calibration.pot_offset_code {:.2} -> {:.2} codes ({:+.3} mm) (applied)",
            was.0,
            r.loadcell_offset_code,
            (r.loadcell_offset_code - was.0) * lc_gain,
            was.1,
            r.pot_offset_code,
            (r.pot_offset_code - was.1) * pot_gain * 1000.0
        );
    }
    Ok(Some(()))
}

/// What a motor-driving or height routine found, one line each.
fn print_results(out: &mut String, routine: &str, b: &hopper_protocol::BringupResults, done: bool) {
    let applied = if done { "applied" } else { "not applied" };
    if b.peak_current_a > 0.0 {
        let _ = writeln!(out, "current: up to {:.2} A", b.peak_current_a);
    }
    if b.nut_travel_m.is_finite() && routine == "direction" {
        let _ = writeln!(
            out,
            "direction: a pulse down moved the nut {:+.3} mm and the load cell {:+.2} N",
            b.nut_travel_m * 1000.0,
            b.force_change_n
        );
    }
    if b.nut_offset_m.is_finite() && routine == "home" {
        let _ = writeln!(
        out,
            "home: the upper stop was at {:+.3} mm in the motor encoder's frame; zeroed there ({applied})",
            b.nut_offset_m * 1000.0
        );
    }
    if b.spring_rate_n_per_m.is_finite() {
        let _ = writeln!(
        out,
            "spring: rate {:.0} N/m, force at zero compression {:+.2} N, fit RMS {:.2} N over {} points spanning {:.2} mm (1 sigma); supervisor.spring_rate_n_per_m ({applied})",
            b.spring_rate_n_per_m,
            b.spring_intercept_n,
            b.fit_rms_n,
            b.fit_points,
            b.fit_span_m * 1000.0
        );
    }
    if b.height_offset_m.is_finite() {
        let _ = writeln!(
            out,
            "height: the body height corrected by {:+.3} mm ({applied})",
            b.height_offset_m * 1000.0
        );
    }
}

/// What the weighing found, one line.
fn print_weighing(out: &mut String, w: &hopper_protocol::WeighingInfo) {
    if w.weight_n.is_finite() {
        let _ = writeln!(
        out,
            "weight: the robot weighs {:.2} N as the load cell reads it, {:.2} N as configured: the load cell reads {:+.2}%; stance friction {:.2} N; the body rose {:.2} mm",
            w.weight_n,
            w.configured_weight_n,
            (w.weight_n / w.configured_weight_n - 1.0) * 100.0,
            w.friction_n,
            w.body_rise_m * 1000.0
        );
    }
}
