//! Telemetry: a compact per-step record pushed into a fixed-size ring the
//! application drains at low priority, and the per-hop energy ledger.
//!
//! Nothing here allocates; the ring overwrites its oldest record when the
//! reader falls behind and counts what it dropped, so the control step never
//! waits on telemetry.

use heapless::Deque;

/// One control step, compact and fixed-size (32 bytes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepRecord {
    /// Control step index since start.
    pub step: u32,
    /// Estimated phase: 0 flight, 1 stance.
    pub phase: u8,
    /// Latched fault bits (0: none).
    pub faults: u16,
    /// DAC code written this step.
    pub dac_code: u16,
    /// Body height coordinate `z`, m.
    pub body_height_m: f32,
    /// Nut displacement `p`, m.
    pub nut_position_m: f32,
    /// Spring force from the load cell, N.
    pub spring_force_n: f32,
    /// Estimated total energy, J.
    pub energy_j: f32,
    /// Current command after the supervisor, A.
    pub command_a: f32,
}

/// Fixed-capacity ring of [`StepRecord`]s; the oldest is dropped when full.
#[derive(Debug)]
pub struct TelemetryRing<const N: usize> {
    buf: Deque<StepRecord, N>,
    dropped: u32,
}

impl<const N: usize> Default for TelemetryRing<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> TelemetryRing<N> {
    /// An empty ring.
    pub const fn new() -> Self {
        TelemetryRing {
            buf: Deque::new(),
            dropped: 0,
        }
    }

    /// Append a record, dropping (and counting) the oldest if full.
    pub fn push(&mut self, r: StepRecord) {
        if self.buf.is_full() {
            let _ = self.buf.pop_front();
            self.dropped = self.dropped.saturating_add(1);
        }
        // Cannot fail: there is room after the pop above (or N == 0, where
        // the record is simply lost and counted).
        if self.buf.push_back(r).is_err() {
            self.dropped = self.dropped.saturating_add(1);
        }
    }

    /// Take the oldest record.
    pub fn pop(&mut self) -> Option<StepRecord> {
        self.buf.pop_front()
    }

    /// Records waiting.
    pub fn len(&self) -> usize {
        self.buf.len()
    }

    /// Whether no record is waiting.
    pub fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    /// Records overwritten before they were read.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }
}

/// Energy bookkeeping of one hop: a stance and the flight up to its apex.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct HopLedger {
    /// Hop number (1 = first stance).
    pub hop: u32,
    /// Toe apex height after this stance, m.
    pub apex_height_m: f32,
    /// Estimated energy just after touchdown, J.
    pub energy_at_touchdown_j: f32,
    /// Estimated energy just after liftoff, J.
    pub energy_at_liftoff_j: f32,
    /// Actuator work done on the mechanism during stance,
    /// `int tau_cmd * theta_dot dt`, J.
    pub stance_work_j: f32,
    /// Stance duration, s.
    pub stance_duration_s: f32,
    /// Largest |current command| over the hop, A.
    pub peak_current_a: f32,
    /// Largest nut displacement over the hop, m.
    pub peak_stroke_m: f32,
}

/// Builds [`HopLedger`]s from the estimator's events and per-step data.
#[derive(Clone, Debug, Default)]
pub struct HopLedgerBuilder {
    cur: HopLedger,
    in_stance: bool,
    started: bool,
    hops: u32,
}

impl HopLedgerBuilder {
    /// A builder waiting for the first touchdown.
    pub const fn new() -> Self {
        HopLedgerBuilder {
            cur: HopLedger {
                hop: 0,
                apex_height_m: 0.0,
                energy_at_touchdown_j: 0.0,
                energy_at_liftoff_j: 0.0,
                stance_work_j: 0.0,
                stance_duration_s: 0.0,
                peak_current_a: 0.0,
                peak_stroke_m: 0.0,
            },
            in_stance: false,
            started: false,
            hops: 0,
        }
    }

    /// Touchdown with the energy estimate at that instant, J.
    pub fn touchdown(&mut self, energy_j: f32) {
        self.hops = self.hops.saturating_add(1);
        self.cur = HopLedger {
            hop: self.hops,
            energy_at_touchdown_j: energy_j,
            ..HopLedger::default()
        };
        self.in_stance = true;
        self.started = true;
    }

    /// Liftoff with the energy estimate at that instant, J.
    pub fn liftoff(&mut self, energy_j: f32) {
        if self.in_stance {
            self.cur.energy_at_liftoff_j = energy_j;
            self.in_stance = false;
        }
    }

    /// Per-step data: time step (s), current command (A), motor torque (N m)
    /// and speed (rad/s), nut displacement (m). Non-finite values are ignored.
    pub fn step(
        &mut self,
        dt_s: f32,
        command_a: f32,
        torque_nm: f32,
        motor_speed_rad_s: f32,
        nut_m: f32,
    ) {
        if !self.started {
            return;
        }
        // A NaN never replaces the peak (`x > peak` is false for it).
        let current_a = libm::fabsf(command_a);
        if current_a > self.cur.peak_current_a && current_a.is_finite() {
            self.cur.peak_current_a = current_a;
        }
        if nut_m > self.cur.peak_stroke_m && nut_m.is_finite() {
            self.cur.peak_stroke_m = nut_m;
        }
        if self.in_stance {
            let power_w = torque_nm * motor_speed_rad_s;
            if power_w.is_finite() && dt_s.is_finite() {
                self.cur.stance_work_j += power_w * dt_s;
                self.cur.stance_duration_s += dt_s;
            }
        }
    }

    /// Flight apex: completes and returns the hop's ledger (None before the
    /// first touchdown or during stance).
    pub fn apex(&mut self, toe_height_m: f32) -> Option<HopLedger> {
        if !self.started || self.in_stance {
            return None;
        }
        self.started = false;
        self.cur.apex_height_m = toe_height_m;
        Some(self.cur)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_drops_oldest_and_counts() {
        let mut r: TelemetryRing<3> = TelemetryRing::new();
        for i in 0..5 {
            r.push(StepRecord {
                step: i,
                ..StepRecord::default()
            });
        }
        assert_eq!(r.len(), 3);
        assert_eq!(r.dropped(), 2);
        assert_eq!(r.pop().map(|x| x.step), Some(2));
        assert_eq!(core::mem::size_of::<StepRecord>(), 32);
    }

    #[test]
    fn hop_ledger_accumulates_stance_work() {
        let mut b = HopLedgerBuilder::new();
        assert_eq!(b.apex(0.1), None);
        b.touchdown(70.0);
        for _ in 0..1000 {
            b.step(1e-4, 20.0, 0.5, 100.0, 0.02);
        }
        b.liftoff(72.0);
        b.step(1e-4, -5.0, -0.1, -50.0, 0.01);
        let h = b.apex(0.12).unwrap_or_default();
        assert_eq!(h.hop, 1);
        assert!((h.stance_work_j - 5.0).abs() < 1e-3, "{}", h.stance_work_j);
        assert!((h.stance_duration_s - 0.1).abs() < 1e-5);
        assert_eq!(h.peak_current_a, 20.0);
        assert_eq!(h.peak_stroke_m, 0.02);
        assert_eq!(h.energy_at_liftoff_j, 72.0);
        assert_eq!(b.apex(0.1), None);
    }
}
