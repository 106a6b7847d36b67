//! `record` of the planar machine: its telemetry records into
//! `planar.csv` (units in the header) as they arrive, and a plot of the
//! speed against its command, the pitch and the hip's height
//! (`planar.png`).

use super::common::print_written;
use super::status::planar_fault;
use super::stream::{report_end, stream, Sink};
use anyhow::{Context, Result};
use hopper_link::Client;
use hopper_protocol::{PlanarTelemetry, RobotMsg};
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
    let mut files = PlanarFiles::create(out, period_s)?;
    let span = (duration_s / period_s).round() as u64;
    let ended = stream(c, every, span, &mut files)?;
    let title = format!("the planar machine on the robot ({})", c.target());
    let (records, dropped, written) = files.finish(&title)?;
    let seconds = records as f64 * f64::from(every) * period_s;
    println!(
        "recorded {seconds:.3} s of the planar machine: {records} records at {:.0} Hz, {dropped} dropped",
        1.0 / (f64::from(every) * period_s),
    );
    print_written(&written);
    let saved = format!(
        "{seconds:.3} s of {duration_s} s saved in {}",
        out.display()
    );
    report_end(ended, &saved)
}

/// The planar machine's records into `planar.csv` as they come, and
/// their plot at the end: `record`'s and the cockpit's.
pub(crate) struct PlanarFiles {
    dir: PathBuf,
    csv: csv::Writer<std::fs::File>,
    records: Vec<PlanarTelemetry>,
    /// Records the sequence numbers skip.
    dropped: u64,
    period_s: f64,
}

impl PlanarFiles {
    /// `dir` (created if missing) with `planar.csv`'s header written, for
    /// a machine whose control period is `period_s`.
    pub(crate) fn create(dir: &Path, period_s: f64) -> Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let path = dir.join("planar.csv");
        let mut csv = csv::Writer::from_path(&path)
            .with_context(|| format!("cannot write {}", path.display()))?;
        csv.write_record(HEADER)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            csv,
            records: Vec::new(),
            dropped: 0,
            period_s,
        })
    }

    /// One record, written.
    pub(crate) fn record(&mut self, t: PlanarTelemetry) -> Result<()> {
        let last = self.records.last().map(|l| l.seq);
        self.dropped += u64::from(hopper_link::seq_gap(last, t.seq));
        self.csv.write_record(row(&t, self.period_s))?;
        self.records.push(t);
        Ok(())
    }

    /// The folder.
    pub(crate) fn dir(&self) -> &Path {
        &self.dir
    }

    /// The CSV completed and, from two records on, the plot titled
    /// `title` drawn: the records, the ones the sequence skipped, and
    /// the files written.
    pub(crate) fn finish(mut self, title: &str) -> Result<(usize, u64, Vec<PathBuf>)> {
        self.csv.flush()?;
        let mut written = vec![self.dir.join("planar.csv")];
        if self.records.len() >= 2 {
            let png = self.dir.join("planar.png");
            plot(&self.records, self.period_s, &png, title)
                .map_err(|e| anyhow::anyhow!("cannot draw {}: {e}", png.display()))?;
            written.push(png);
        }
        Ok((self.records.len(), self.dropped, written))
    }
}

impl Sink for PlanarFiles {
    fn step(m: &RobotMsg) -> Option<u32> {
        match m {
            RobotMsg::Planar(t) => Some(t.step),
            _ => None,
        }
    }

    fn take(&mut self, m: RobotMsg, _: &indicatif::ProgressBar) -> Result<()> {
        match m {
            RobotMsg::Planar(t) => self.record(t),
            _ => Ok(()),
        }
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
    png: &Path,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    hopper_plot::ensure_font()?;
    let t0 = f64::from(records[0].step) * period_s;
    let t = |r: &PlanarTelemetry| f64::from(r.step) * period_s - t0;
    let t_hi = records.last().map_or(1.0, t).max(1e-3);
    let root = BitMapBackend::new(png, (1000, 820)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 20))?;
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
