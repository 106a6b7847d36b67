//! Recordings: telemetry and hop ledgers from the link, written as CSV with
//! units in the headers and plotted like `hopper-sim run` (hop.png); the
//! fault capture (`dump`) with a plot of its own around the fault
//! (capture.png).

use anyhow::{Context, Result};
use hopper_mcap::{field, Channel, Field, Mcap, FAULT_FIELDS, HOP_FIELDS};
use hopper_model::design::LEG_LENGTH_M;
use hopper_plot::{extent, side_legend, LegendKey, Phase, Sample, SIDE_LEGEND_PX};
use hopper_protocol::{Hop, Telemetry};
use plotters::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A telemetry record's fields, in the CSV's column order and the MCAP
/// channel's schema: the one list both read.
const TELEMETRY_FIELDS: [Field; 12] = [
    field(
        "t_s",
        "number",
        "time since the recording's first record, s",
    ),
    field(
        "seq",
        "integer",
        "telemetry sequence number (a gap is a drop)",
    ),
    field("step", "integer", "control period number"),
    field("phase", "string", "the estimator's phase: flight or stance"),
    field("armed", "boolean", "the amplifier enabled"),
    field("faults", "string", "latched faults by name (none)"),
    field("body_height_m", "number", "body height, m"),
    field(
        "toe_height_m",
        "number",
        "toe height (body height less the leg length), m",
    ),
    field(
        "nut_position_m",
        "number",
        "nut position p, m, down from the upper stop",
    ),
    field(
        "spring_force_n",
        "number",
        "spring force from the load cell, N",
    ),
    field(
        "energy_j",
        "number",
        "the firmware's total energy estimate, J",
    ),
    field("command_a", "number", "the commanded motor current, A"),
];

/// One telemetry record as the recording keeps it.
#[derive(Debug, Clone, serde::Serialize)]
struct TelemetryRow {
    t_s: f64,
    seq: u32,
    step: u32,
    phase: &'static str,
    armed: bool,
    faults: String,
    body_height_m: f32,
    toe_height_m: f64,
    nut_position_m: f32,
    spring_force_n: f32,
    energy_j: f32,
    command_a: f32,
}

impl TelemetryRow {
    fn new(t_s: f64, r: &Telemetry) -> Self {
        Self {
            t_s,
            seq: r.seq,
            step: r.step,
            phase: if r.phase == 1 { "stance" } else { "flight" },
            armed: r.armed,
            faults: crate::names::faults(r.faults),
            body_height_m: r.body_height_m,
            toe_height_m: toe_height_m(r),
            nut_position_m: r.nut_position_m,
            spring_force_n: r.spring_force_n,
            energy_j: r.energy_j,
            command_a: r.command_a,
        }
    }

    /// As a CSV row (each column's decimals).
    fn csv(&self) -> [String; 12] {
        [
            format!("{:.6}", self.t_s),
            self.seq.to_string(),
            self.step.to_string(),
            self.phase.to_string(),
            u8::from(self.armed).to_string(),
            self.faults.clone(),
            format!("{:.6}", self.body_height_m),
            format!("{:.6}", self.toe_height_m),
            format!("{:.6}", self.nut_position_m),
            format!("{:.3}", self.spring_force_n),
            format!("{:.4}", self.energy_j),
            format!("{:.4}", self.command_a),
        ]
    }
}

fn record_header() -> [&'static str; 12] {
    TELEMETRY_FIELDS.map(|f| f.name)
}

fn hop_row(h: &Hop) -> [String; 10] {
    [
        h.hop.to_string(),
        format!("{:.5}", h.apex_height_m),
        format!("{:.4}", h.energy_at_touchdown_j),
        format!("{:.4}", h.energy_at_liftoff_j),
        format!("{:.4}", h.stance_work_j),
        format!("{:.5}", h.stance_duration_s),
        format!("{:.3}", h.peak_current_a),
        format!("{:.5}", h.peak_stroke_m),
        format!("{:.4}", h.copper_loss_j),
        format!("{:.4}", h.stance_copper_loss_j),
    ]
}

/// The MCAP recording's channels.
struct McapOut {
    file: Mcap,
    telemetry: Channel,
    hop: Channel,
    fault: Channel,
    parameters: Channel,
}

/// A recording written to disk as it arrives (`telemetry.csv`, `hops.csv`
/// and `telemetry.mcap`), so whatever ends it (the duration, Ctrl-C, the
/// link closing, the robot stopping) leaves every record received in
/// valid files; [`finish`] draws the plot from what was saved.
///
/// The MCAP file (Foxglove, PlotJuggler) has the channels `/telemetry`,
/// `/hop`, `/fault` and `/parameters` (every parameter's value when the
/// recording started, `null` for one the configuration lacks), JSON with
/// JSON schemas, stamped with robot time (the period count times the
/// period).
///
/// [`finish`]: Streamed::finish
pub struct Streamed {
    /// What was received, for the plot and the summary.
    pub rec: Recording,
    dir: PathBuf,
    telemetry: csv::Writer<std::fs::File>,
    hops: csv::Writer<std::fs::File>,
    mcap: McapOut,
    /// Every parameter's value now.
    parameters: BTreeMap<String, Option<f32>>,
    /// Whether they are still to be logged (at the next record's time).
    parameters_due: bool,
    /// The target apex as it was: (time from the first record, s; m), from
    /// the start's value on.
    targets: Vec<(f64, f64)>,
}

impl Streamed {
    /// Creates `dir` (if missing), the two CSV files with their headers and
    /// the MCAP file with its channels; `parameters` are the robot's at the
    /// start (NaN: not in its configuration).
    pub fn create(dir: &Path, period_s: f64, parameters: &[(String, f32)]) -> Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let open = |name: &str| -> Result<csv::Writer<std::fs::File>> {
            let path = dir.join(name);
            csv::Writer::from_path(&path)
                .with_context(|| format!("cannot write {}", path.display()))
        };
        let mut telemetry = open("telemetry.csv")?;
        telemetry.write_record(record_header())?;
        let mut hops = open("hops.csv")?;
        hops.write_record(HOP_FIELDS.map(|f| f.name))?;
        let mut file = Mcap::create(&dir.join("telemetry.mcap")).map_err(anyhow::Error::msg)?;
        let mcap = (|| -> std::result::Result<McapOut, String> {
            Ok(McapOut {
                telemetry: file.channel("/telemetry", "hopper.Telemetry", &TELEMETRY_FIELDS)?,
                hop: file.channel("/hop", "hopper.Hop", &HOP_FIELDS)?,
                fault: file.channel("/fault", "hopper.Fault", &FAULT_FIELDS)?,
                parameters: file.map_channel("/parameters", "hopper.Parameters")?,
                file,
            })
        })()
        .map_err(anyhow::Error::msg)?;
        let mut s = Self {
            rec: Recording {
                period_s,
                ..Recording::default()
            },
            dir: dir.to_path_buf(),
            telemetry,
            hops,
            mcap,
            parameters: parameters
                .iter()
                .map(|(n, v)| (n.clone(), v.is_finite().then_some(*v)))
                .collect(),
            parameters_due: true,
            targets: parameters
                .iter()
                .filter(|(n, v)| n == "target_apex_m" && v.is_finite())
                .map(|(_, v)| (0.0, f64::from(*v)))
                .collect(),
        };
        s.flush()?;
        Ok(s)
    }

    /// Robot time of period `step`, s: the period rounded to a whole
    /// nanosecond first (it travels as an `f32`: 1 ms is 1.00000005 ms),
    /// so the MCAP file's timestamps are whole multiples of it.
    fn robot_time_s(&self, step: u32) -> f64 {
        f64::from(step) * (self.rec.period_s * 1e9).round() * 1e-9
    }

    /// One telemetry record, appended to `telemetry.csv` and the MCAP file.
    pub fn record(&mut self, t: Telemetry) -> Result<()> {
        self.rec.records.push(t);
        let row = TelemetryRow::new(self.rec.t_s(&t), &t);
        self.telemetry.write_record(row.csv())?;
        let time_s = self.robot_time_s(t.step);
        let m = &mut self.mcap;
        if std::mem::take(&mut self.parameters_due) {
            m.file
                .log(m.parameters, time_s, &self.parameters)
                .map_err(anyhow::Error::msg)?;
        }
        m.file
            .log(m.telemetry, time_s, &row)
            .map_err(anyhow::Error::msg)?;
        Ok(())
    }

    /// One hop's ledger, appended to `hops.csv` and the MCAP file (at the
    /// last record's time: the ledger comes as the hop ends).
    pub fn hop(&mut self, h: Hop) -> Result<()> {
        self.telemetry.flush()?;
        self.hops.write_record(hop_row(&h))?;
        self.hops.flush()?;
        let time_s = self
            .rec
            .records
            .last()
            .map_or(0.0, |r| self.robot_time_s(r.step));
        self.mcap
            .file
            .log(self.mcap.hop, time_s, &h)
            .map_err(anyhow::Error::msg)?;
        self.rec.hops.push(h);
        Ok(())
    }

    /// A parameter set while recording: the whole table logged again on
    /// `/parameters` at the last record's time (with the first record, if
    /// none came yet), and a change of the target apex kept for the plot.
    pub fn set(&mut self, name: &str, value: f32) -> Result<()> {
        self.parameters.insert(name.to_string(), Some(value));
        let last = self.rec.records.last().copied();
        if name == "target_apex_m" {
            let t_s = last.map_or(0.0, |r| self.rec.t_s(&r));
            self.targets.push((t_s, f64::from(value)));
        }
        match last {
            Some(r) => {
                let time_s = self.robot_time_s(r.step);
                self.mcap
                    .file
                    .log(self.mcap.parameters, time_s, &self.parameters)
                    .map_err(anyhow::Error::msg)
            }
            None => {
                self.parameters_due = true;
                Ok(())
            }
        }
    }

    /// Faults latched at period `step`.
    pub fn fault(&mut self, step: u32, bits: u16) -> Result<()> {
        self.rec.faults.push((step, bits));
        let msg = serde_json::json!({
            "step": step,
            "bits": bits,
            "faults": crate::names::faults(bits),
        });
        self.mcap
            .file
            .log(self.mcap.fault, self.robot_time_s(step), &msg)
            .map_err(anyhow::Error::msg)
    }

    /// Pushes what is buffered to the files (the MCAP file's open chunk
    /// closed: readable up to here).
    pub fn flush(&mut self) -> Result<()> {
        self.telemetry.flush()?;
        self.hops.flush()?;
        self.mcap.file.flush().map_err(anyhow::Error::msg)?;
        Ok(())
    }

    /// Flushes the files, completes the MCAP file and draws `plot` (PNG)
    /// from what was saved (with at least two records), the target apex as
    /// it was over the recording (`target_apex_m` when the start's
    /// parameters had none); returns the paths written.
    pub fn finish(
        mut self,
        plot: &str,
        title: &str,
        target_apex_m: Option<f64>,
    ) -> Result<(Recording, Vec<PathBuf>)> {
        self.flush()?;
        self.mcap.file.finish().map_err(anyhow::Error::msg)?;
        let mut written = vec![
            self.dir.join("telemetry.csv"),
            self.dir.join("hops.csv"),
            self.dir.join("telemetry.mcap"),
        ];
        if self.rec.records.len() >= 2 {
            let path = self.dir.join(plot);
            // The target as it was while recording; else the one given.
            let targets = if self.targets.is_empty() {
                target_apex_m.map(|t| vec![(0.0, t)]).unwrap_or_default()
            } else {
                self.targets.clone()
            };
            hopper_plot::hop_plot_targets(&self.rec.samples(), title, &targets, &path)
                .map_err(anyhow::Error::msg)?;
            written.push(path);
        }
        Ok((self.rec, written))
    }
}

/// The toe's height above the ground as the thesis defines it: `z - l0`
/// in flight, and on the ground (0) in stance, where the spring shortens
/// the leg (`z - l0` there is the compression, below the ground).
pub fn toe_height_m(r: &Telemetry) -> f64 {
    if r.phase == 1 {
        0.0
    } else {
        (f64::from(r.body_height_m) - LEG_LENGTH_M).max(0.0)
    }
}

/// What a recording holds.
#[derive(Debug, Default, Clone)]
pub struct Recording {
    /// The robot's control period, s.
    pub period_s: f64,
    /// Telemetry records, in arrival order.
    pub records: Vec<Telemetry>,
    /// Hop ledgers.
    pub hops: Vec<Hop>,
    /// Faults latched during the recording: (step, bits).
    pub faults: Vec<(u32, u16)>,
    /// The step of t = 0 (None: the first record's; a dump: the fault's).
    pub t0_step: Option<u32>,
}

impl Recording {
    /// Records missing from the sequence (the robot could not send them,
    /// or the host lost them).
    pub fn dropped(&self) -> u64 {
        self.records
            .windows(2)
            .map(|w| u64::from(w[1].seq.wrapping_sub(w[0].seq).saturating_sub(1)))
            .sum()
    }

    /// The apexes of the hops, m.
    pub fn apexes_m(&self) -> Vec<f64> {
        self.hops
            .iter()
            .map(|h| f64::from(h.apex_height_m))
            .collect()
    }

    /// Time of a record since the first, s.
    fn t_s(&self, r: &Telemetry) -> f64 {
        let first = self
            .t0_step
            .or(self.records.first().map(|f| f.step))
            .unwrap_or(r.step);
        f64::from(r.step.wrapping_sub(first) as i32) * self.period_s
    }

    /// Writes a capture (`dump`) into `dir` (created if missing):
    /// `capture.csv`, the records as [`write`](Self::write) writes them,
    /// and `capture.png`, [`capture_plot`](Self::capture_plot); returns
    /// the paths written.
    pub fn write_capture(&self, dir: &Path, title: &str) -> Result<Vec<PathBuf>> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let mut written = vec![self.write_records(&dir.join("capture.csv"))?];
        if self.records.len() >= 2 {
            let path = dir.join("capture.png");
            self.capture_plot(title, &path)?;
            written.push(path);
        }
        Ok(written)
    }

    /// The records as CSV at `path`, units in the headers.
    fn write_records(&self, path: &Path) -> Result<PathBuf> {
        let mut w = csv::Writer::from_path(path)
            .with_context(|| format!("cannot write {}", path.display()))?;
        w.write_record(record_header())?;
        for r in &self.records {
            w.write_record(TelemetryRow::new(self.t_s(r), r).csv())?;
        }
        w.flush()?;
        Ok(path.to_path_buf())
    }

    /// The time axis of the capture plot, ms: from the first record to the
    /// last, relative to [`t0_step`](Self::t0_step) (negative before a
    /// fault). `None` with fewer than two records.
    pub fn span_ms(&self) -> Option<(f64, f64)> {
        let (first, last) = (self.records.first()?, self.records.last()?);
        let (a, b) = (self.t_s(first) * 1e3, self.t_s(last) * 1e3);
        (a < b).then_some((a, b))
    }

    /// The stance phases among the records, as (start, end) in ms: each
    /// from its first stance record to the record after its last (or the
    /// last record).
    pub fn stance_spans_ms(&self) -> Vec<(f64, f64)> {
        let mut spans = Vec::new();
        let mut start = None;
        for r in &self.records {
            let t = self.t_s(r) * 1e3;
            match (r.phase == 1, start) {
                (true, None) => start = Some(t),
                (false, Some(s)) => {
                    spans.push((s, t));
                    start = None;
                }
                _ => {}
            }
        }
        if let (Some(s), Some(last)) = (start, self.records.last()) {
            spans.push((s, self.t_s(last) * 1e3));
        }
        spans
    }

    /// Draws the capture into a PNG at `path`, titled `title`: toe height,
    /// nut position, spring force, motor current command and energy
    /// against time in ms over the whole capture, stance shaded. With
    /// [`t0_step`](Self::t0_step) set (a capture a fault froze) the time is
    /// relative to the fault, negative before it, and a dashed vertical line
    /// labelled "fault" marks it. Legends stand right of the panels, clear
    /// of the data; non-finite values (a `sensor-nonfinite` fault's) are
    /// gaps in the lines.
    pub fn capture_plot(&self, title: &str, path: &Path) -> Result<()> {
        let (t_first, t_last) = self
            .span_ms()
            .ok_or_else(|| anyhow::anyhow!("not enough records to plot the capture"))?;
        hopper_plot::ensure_font().map_err(anyhow::Error::msg)?;
        type Get = fn(&Telemetry) -> f64;
        let panels: [(&str, &str, Get); 5] = [
            ("Toe height", "toe height [cm]", |r| {
                (f64::from(r.body_height_m) - LEG_LENGTH_M) * 100.0
            }),
            ("Nut position", "nut p [mm]", |r| {
                f64::from(r.nut_position_m) * 1000.0
            }),
            ("Spring force", "spring force [N]", |r| {
                f64::from(r.spring_force_n)
            }),
            ("Motor current command", "command [A]", |r| {
                f64::from(r.command_a)
            }),
            ("Total energy", "energy [J]", |r| f64::from(r.energy_j)),
        ];
        let fault_ms = self
            .t0_step
            .map(|_| 0.0)
            .filter(|t| (t_first..=t_last).contains(t));
        let stance = self.stance_spans_ms();
        let x_desc = if self.t0_step.is_some() {
            "time from the fault [ms]"
        } else {
            "time from the first record [ms]"
        };
        const WIDTH: u32 = 1100;
        let height = 40 + 250 * panels.len() as u32;
        let root = BitMapBackend::new(path, (WIDTH, height)).into_drawing_area();
        let stance_fill = RGBColor(225, 225, 225);
        let res = (|| -> std::result::Result<(), Box<dyn std::error::Error>> {
            root.fill(&WHITE)?;
            let (head, body) = root.split_vertically(40);
            head.titled(title, ("sans-serif", 22))?;
            for (area, (name, ylabel, get)) in
                body.split_evenly((panels.len(), 1)).iter().zip(panels)
            {
                let (area, key) = area.split_horizontally(WIDTH - SIDE_LEGEND_PX);
                let (lo, hi) = extent(self.records.iter().map(get).filter(|v| v.is_finite()));
                let (lo, hi) = if lo <= hi { (lo, hi) } else { (-1.0, 1.0) };
                let pad = ((hi - lo) * 0.05).max(0.5);
                // A band above the data for the fault's label.
                let (lo, hi) = (lo - pad, hi + 3.0 * pad);
                let mut chart = ChartBuilder::on(&area)
                    .caption(name, ("sans-serif", 18))
                    .margin(8)
                    .x_label_area_size(36)
                    .y_label_area_size(70)
                    .build_cartesian_2d(t_first..t_last, lo..hi)?;
                // Stance under the grid and the data.
                chart.draw_series(
                    stance
                        .iter()
                        .map(|&(a, b)| Rectangle::new([(a, lo), (b, hi)], stance_fill.filled())),
                )?;
                chart
                    .configure_mesh()
                    .x_desc(x_desc)
                    .y_desc(ylabel)
                    .x_label_formatter(&|v| tick(*v, 0))
                    .y_label_formatter(&|v| tick(*v, 1))
                    .light_line_style(WHITE.mix(0.0))
                    .draw()?;
                // One line per run of finite values: a NaN breaks the line.
                // One pixel wide: a thicker line grows spikes past the data
                // at the sharp turns of noisy samples (plotters' miter joins).
                let mut run: Vec<(f64, f64)> = Vec::new();
                for r in &self.records {
                    let v = get(r);
                    if v.is_finite() {
                        run.push((self.t_s(r) * 1e3, v));
                    } else if !run.is_empty() {
                        chart.draw_series(LineSeries::new(std::mem::take(&mut run), &BLUE))?;
                    }
                }
                chart.draw_series(LineSeries::new(run, &BLUE))?;
                if let Some(t) = fault_ms {
                    chart.draw_series(DashedLineSeries::new(
                        [(t, lo), (t, hi)],
                        8,
                        6,
                        RED.stroke_width(2),
                    ))?;
                    chart.draw_series(std::iter::once(
                        EmptyElement::at((t, hi))
                            + Text::new(
                                "fault",
                                (5, 2),
                                ("sans-serif", 15).into_font().color(&RED),
                            ),
                    ))?;
                }
                let mut entries = vec![(ylabel.to_string(), LegendKey::Line(BLUE))];
                if fault_ms.is_some() {
                    entries.push(("fault (t = 0)".into(), LegendKey::Dashed(RED)));
                }
                if !stance.is_empty() {
                    entries.push(("stance".into(), LegendKey::Fill(stance_fill)));
                }
                side_legend(&key, &entries)?;
            }
            root.present()?;
            Ok(())
        })();
        res.map_err(|e| anyhow::anyhow!("cannot draw {}: {e}", path.display()))
    }

    /// The records as the simulator's trajectory samples (what the robot
    /// measured and estimated; velocities and torque are not on the wire).
    fn samples(&self) -> Vec<Sample> {
        self.records
            .iter()
            .map(|r| Sample {
                t_s: self.t_s(r),
                phase: if r.phase == 1 {
                    Phase::Stance
                } else {
                    Phase::Flight
                },
                z_m: f64::from(r.body_height_m),
                zd_mps: f64::NAN,
                p_m: f64::from(r.nut_position_m),
                pd_mps: f64::NAN,
                toe_height_m: toe_height_m(r),
                spring_force_n: f64::from(r.spring_force_n),
                torque_nm: f64::NAN,
                energy_j: f64::from(r.energy_j),
                // The telemetry record does not carry the thermal estimate
                // (`status` reads it with its own request).
                winding_c: None,
            })
            .collect()
    }
}

/// An axis label: `v` with `decimals`, and no "-0".
fn tick(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(seq: u32) -> Telemetry {
        Telemetry {
            seq,
            step: seq * 10,
            phase: 0,
            armed: true,
            faults: 0,
            body_height_m: 0.7,
            nut_position_m: 0.0,
            spring_force_n: 0.0,
            energy_j: 50.0,
            command_a: 0.0,
        }
    }

    /// A capture as the robot freezes it: 1,024 records at 10 kHz, the
    /// fault at record 767, stance from record 900 on.
    fn capture() -> Recording {
        let records = (0..1024u32)
            .map(|i| Telemetry {
                seq: i,
                step: 5000 + i,
                phase: u8::from(i >= 900),
                armed: i < 767,
                faults: if i >= 767 { 1 } else { 0 },
                command_a: if i < 767 { 20.0 } else { 0.0 },
                ..rec(i)
            })
            .collect();
        Recording {
            period_s: 1e-4,
            records,
            t0_step: Some(5767),
            ..Recording::default()
        }
    }

    #[test]
    fn a_capture_is_timed_from_its_first_record_relative_to_the_fault() {
        let c = capture();
        let (a, b) = c.span_ms().unwrap_or_else(|| panic!("no span"));
        assert!(
            (a + 76.7).abs() < 1e-9 && (b - 25.6).abs() < 1e-9,
            "{a} {b}"
        );
        let stance = c.stance_spans_ms();
        assert_eq!(stance.len(), 1);
        assert!((stance[0].0 - 13.3).abs() < 1e-9 && (stance[0].1 - 25.6).abs() < 1e-9);
        // Without a fault: from the first record.
        let free = Recording {
            t0_step: None,
            ..capture()
        };
        let (a, b) = free.span_ms().unwrap_or_else(|| panic!("no span"));
        assert!(a.abs() < 1e-12 && (b - 102.3).abs() < 1e-9, "{a} {b}");
        // One record spans nothing: no plot.
        let one = Recording {
            records: capture().records[..1].to_vec(),
            ..capture()
        };
        assert_eq!(one.span_ms(), None);
    }

    #[test]
    fn stance_to_the_end_and_flight_between() {
        let r = Recording {
            period_s: 1e-3,
            records: [0u8, 1, 1, 0, 1]
                .iter()
                .enumerate()
                .map(|(i, &phase)| Telemetry {
                    step: i as u32,
                    phase,
                    ..rec(i as u32)
                })
                .collect(),
            ..Recording::default()
        };
        assert_eq!(r.stance_spans_ms(), [(1.0, 3.0), (4.0, 4.0)]);
    }

    #[test]
    fn the_capture_files_keep_their_columns_and_plot_even_with_nan() {
        let dir = std::env::temp_dir().join(format!("hopper-link-capture-{}", std::process::id()));
        let mut c = capture();
        // A sensor-nonfinite fault's records: gaps, not a failure.
        c.records[770].body_height_m = f32::NAN;
        c.records[771].spring_force_n = f32::INFINITY;
        let written = c
            .write_capture(&dir, "capture around the fault")
            .unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(written, [dir.join("capture.csv"), dir.join("capture.png")]);
        let csv = std::fs::read_to_string(dir.join("capture.csv")).unwrap_or_default();
        let mut lines = csv.lines();
        assert_eq!(
            lines.next(),
            Some("t_s,seq,step,phase,armed,faults,body_height_m,toe_height_m,nut_position_m,spring_force_n,energy_j,command_a")
        );
        assert!(lines
            .next()
            .is_some_and(|l| l.starts_with("-0.076700,0,5000,flight,1,none,")));
        assert_eq!(csv.lines().count(), 1025);
        let png = std::fs::metadata(dir.join("capture.png"))
            .map(|m| m.len())
            .unwrap_or(0);
        assert!(png > 10_000, "{png} bytes");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn axis_labels_have_no_negative_zero() {
        assert_eq!(tick(-0.01, 1), "0.0");
        assert_eq!(tick(-0.0, 0), "0");
        assert_eq!(tick(-10.0, 0), "-10");
    }

    #[test]
    fn gaps_in_the_sequence_are_drops() {
        let r = Recording {
            period_s: 1e-4,
            records: [0, 1, 2, 5, 6, 10].into_iter().map(rec).collect(),
            ..Recording::default()
        };
        assert_eq!(r.dropped(), 5);
        assert!((r.t_s(&r.records[5]) - 0.01).abs() < 1e-12);
    }
}
