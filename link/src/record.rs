//! Recordings: telemetry and hop ledgers from the link, written as CSV with
//! units in the headers and plotted like `hopper-sim run` (hop.png).

use anyhow::{Context, Result};
use hopper_control::model::design::LEG_LENGTH_M;
use hopper_plant::Mode;
use hopper_protocol::{Hop, Telemetry};
use std::path::{Path, PathBuf};

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

    /// Writes the records as `files.0` (CSV) and their plot as `files.1`
    /// (PNG) into `dir` (created if missing), and the hop ledgers as
    /// `hops.csv` when `hops` is set; returns the paths written. `title`
    /// heads the plot; `target_apex_m` draws the target.
    pub fn write(
        &self,
        dir: &Path,
        files: (&str, &str),
        hops: bool,
        title: &str,
        target_apex_m: Option<f64>,
    ) -> Result<Vec<PathBuf>> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let mut written = Vec::new();
        let path = dir.join(files.0);
        let mut w = csv::Writer::from_path(&path)
            .with_context(|| format!("cannot write {}", path.display()))?;
        w.write_record([
            "t_s",
            "seq",
            "step",
            "phase",
            "armed",
            "faults",
            "body_height_m",
            "toe_height_m",
            "nut_position_m",
            "spring_force_n",
            "energy_j",
            "command_a",
        ])?;
        for r in &self.records {
            w.write_record([
                format!("{:.6}", self.t_s(r)),
                r.seq.to_string(),
                r.step.to_string(),
                if r.phase == 1 { "stance" } else { "flight" }.to_string(),
                u8::from(r.armed).to_string(),
                crate::names::faults(r.faults),
                format!("{:.6}", r.body_height_m),
                format!("{:.6}", f64::from(r.body_height_m) - LEG_LENGTH_M),
                format!("{:.6}", r.nut_position_m),
                format!("{:.3}", r.spring_force_n),
                format!("{:.4}", r.energy_j),
                format!("{:.4}", r.command_a),
            ])?;
        }
        w.flush()?;
        written.push(path);
        if hops {
            written.push(self.write_hops(dir)?);
        }
        if self.records.len() >= 2 {
            let path = dir.join(files.1);
            hal_sim::plot::hop_plot(&self.samples(), title, target_apex_m, &path)
                .map_err(anyhow::Error::msg)?;
            written.push(path);
        }
        Ok(written)
    }

    /// `hops.csv`: one hop ledger a row.
    fn write_hops(&self, dir: &Path) -> Result<PathBuf> {
        let path = dir.join("hops.csv");
        let mut w = csv::Writer::from_path(&path)
            .with_context(|| format!("cannot write {}", path.display()))?;
        w.write_record([
            "hop",
            "apex_height_m",
            "energy_at_touchdown_j",
            "energy_at_liftoff_j",
            "stance_work_j",
            "stance_duration_s",
            "peak_current_a",
            "peak_stroke_m",
        ])?;
        for h in &self.hops {
            w.write_record([
                h.hop.to_string(),
                format!("{:.5}", h.apex_height_m),
                format!("{:.4}", h.energy_at_touchdown_j),
                format!("{:.4}", h.energy_at_liftoff_j),
                format!("{:.4}", h.stance_work_j),
                format!("{:.5}", h.stance_duration_s),
                format!("{:.3}", h.peak_current_a),
                format!("{:.5}", h.peak_stroke_m),
            ])?;
        }
        w.flush()?;
        Ok(path)
    }

    /// The records as the simulator's trajectory samples (what the robot
    /// measured and estimated; velocities and torque are not on the wire).
    fn samples(&self) -> Vec<hal_sim::run::Sample> {
        self.records
            .iter()
            .map(|r| hal_sim::run::Sample {
                t_s: self.t_s(r),
                phase: if r.phase == 1 {
                    Mode::Stance
                } else {
                    Mode::Flight
                },
                z_m: f64::from(r.body_height_m),
                zd_mps: f64::NAN,
                p_m: f64::from(r.nut_position_m),
                pd_mps: f64::NAN,
                toe_height_m: f64::from(r.body_height_m) - LEG_LENGTH_M,
                spring_force_n: f64::from(r.spring_force_n),
                torque_nm: f64::NAN,
                energy_j: f64::from(r.energy_j),
            })
            .collect()
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
