//! `record` of the planar machine: its telemetry records into
//! `planar.csv` (units in the header) as they arrive, and a plot of the
//! speed against its command, the pitch and the hip's height
//! (`planar.png`).

use super::common::print_written;
use super::status::planar_fault;
use super::stream::{progress, stream, Sink};
use anyhow::{bail, Context, Result};
use hopper_link::Client;
use hopper_protocol::{PlanarTelemetry, Request, RobotMsg};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// The CSV's columns, units in the names.
const HEADER: [&str; 13] = [
    "t_s",
    "x_m",
    "z_m",
    "pitch_rad",
    "leg_angle_rad",
    "leg_length_m",
    "stance",
    "speed_mps",
    "speed_command_mps",
    "hip_current_a",
    "leg_current_a",
    "armed",
    "guard",
];

/// Records `duration_s` of robot time, a record every `every` periods of
/// `period_s`, into `out`.
pub(crate) fn record(
    c: &mut Client,
    duration_s: f64,
    every: u16,
    period_s: f64,
    out: &Path,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let csv_path = out.join("planar.csv");
    let mut csv = csv::Writer::from_path(&csv_path)
        .with_context(|| format!("cannot write {}", csv_path.display()))?;
    csv.write_record(HEADER)?;
    let span = (duration_s / period_s).round() as u64;
    let bar = progress(span);
    let mut sink = Planar {
        csv,
        records: Vec::new(),
        dropped: 0,
        period_s,
    };
    let ended = stream(c, every, span, &mut sink, &bar)?;
    let Planar {
        mut csv,
        records,
        dropped,
        ..
    } = sink;
    if !ended.as_ref().is_some_and(|(_, failed)| *failed) {
        c.expect_ok(Request::Telemetry { every: 0 })?;
    }
    bar.finish_and_clear();
    csv.flush()?;
    let mut written = vec![csv_path];
    if records.len() >= 2 {
        let png = out.join("planar.png");
        plot(&records, period_s, &png, &c.target().to_string())
            .map_err(|e| anyhow::anyhow!("cannot draw {}: {e}", png.display()))?;
        written.push(png);
    }
    let seconds = records.len() as f64 * f64::from(every) * period_s;
    println!(
        "recorded {seconds:.3} s of the planar machine: {} records at {:.0} Hz, {dropped} dropped",
        records.len(),
        1.0 / (f64::from(every) * period_s),
    );
    print_written(&written);
    match ended {
        Some((why, failed)) => {
            let saved = format!(
                "{seconds:.3} s of {duration_s} s saved in {}",
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

/// The planar machine's records into the CSV as they come.
struct Planar {
    csv: csv::Writer<std::fs::File>,
    records: Vec<PlanarTelemetry>,
    /// Records the sequence numbers skip.
    dropped: u64,
    period_s: f64,
}

impl Sink for Planar {
    fn step(m: &RobotMsg) -> Option<u32> {
        match m {
            RobotMsg::Planar(t) => Some(t.step),
            _ => None,
        }
    }

    fn take(&mut self, m: RobotMsg, _: &indicatif::ProgressBar) -> Result<()> {
        if let RobotMsg::Planar(t) = m {
            let last = self.records.last().map(|l| l.seq);
            self.dropped += u64::from(hopper_link::seq_gap(last, t.seq));
            self.csv.write_record(row(&t, self.period_s))?;
            self.records.push(t);
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        Ok(self.csv.flush()?)
    }
}

/// One record as the CSV's row.
fn row(t: &PlanarTelemetry, period_s: f64) -> [String; 13] {
    [
        format!("{:.4}", f64::from(t.step) * period_s),
        t.x_m.to_string(),
        t.z_m.to_string(),
        t.pitch_rad.to_string(),
        t.leg_angle_rad.to_string(),
        t.leg_length_m.to_string(),
        u8::from(t.stance).to_string(),
        t.speed_mps.to_string(),
        t.speed_command_mps.to_string(),
        t.hip_current_a.to_string(),
        t.leg_current_a.to_string(),
        u8::from(t.armed).to_string(),
        planar_fault(t.fault),
    ]
}

/// The speed against its command, the pitch and the hip's height over
/// the recording, one panel each.
fn plot(
    records: &[PlanarTelemetry],
    period_s: f64,
    png: &PathBuf,
    robot: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    hopper_plot::ensure_font()?;
    let t0 = f64::from(records[0].step) * period_s;
    let t = |r: &PlanarTelemetry| f64::from(r.step) * period_s - t0;
    let t_hi = records.last().map_or(1.0, t).max(1e-3);
    let root = BitMapBackend::new(png, (1000, 820)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(
        &format!("the planar machine on the robot ({robot})"),
        ("sans-serif", 20),
    )?;
    let panels = root.split_evenly((3, 1));
    let blue = RGBColor(21, 101, 192);
    let grey = RGBColor(120, 120, 120);
    let series = |f: fn(&PlanarTelemetry) -> f64| -> Vec<(f64, f64)> {
        records.iter().map(|r| (t(r), f(r))).collect()
    };
    let speed = series(|r| f64::from(r.speed_mps));
    let command = series(|r| f64::from(r.speed_command_mps));
    let (lo, hi) = hopper_plot::extent(speed.iter().chain(&command).map(|p| p.1));
    let mut ch = hopper_plot::time_chart(&panels[0], t_hi, lo, hi, "speed [m/s]")?;
    ch.draw_series(LineSeries::new(speed, blue.stroke_width(2)))?
        .label("speed (estimate)")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], blue.stroke_width(2)));
    ch.draw_series(DashedLineSeries::new(command, 6, 4, grey.stroke_width(2)))?
        .label("command")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], grey.stroke_width(2)));
    ch.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    let pitch = series(|r| f64::from(r.pitch_rad).to_degrees());
    let (lo, hi) = hopper_plot::extent(pitch.iter().map(|p| p.1));
    let mut ch = hopper_plot::time_chart(&panels[1], t_hi, lo, hi, "pitch [deg]")?;
    ch.draw_series(LineSeries::new(pitch, RED.stroke_width(2)))?;
    let z = series(|r| f64::from(r.z_m));
    let (lo, hi) = hopper_plot::extent(z.iter().map(|p| p.1));
    let mut ch = hopper_plot::time_chart(&panels[2], t_hi, lo, hi, "hip height [m]")?;
    ch.draw_series(LineSeries::new(z, BLACK.stroke_width(1)))?;
    root.present()?;
    Ok(())
}
