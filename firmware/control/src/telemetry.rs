//! Telemetry: a compact per-step record, the capture that keeps the last
//! of them (frozen around a fault), and the per-hop energy ledger.
//!
//! Nothing here allocates, and the control task never waits on telemetry:
//! the capture overwrites its oldest record, and readers only look.

/// One control step, compact and fixed-size (32 bytes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepRecord {
    /// Control step index since start.
    pub step: u32,
    /// Estimated phase: 0 flight, 1 stance.
    pub phase: u8,
    /// The output went out armed (amplifier enabled); set by the period
    /// runner after arming decided.
    pub armed: bool,
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

/// Records in the firmware's capture (32 bytes each, 32 KiB): 102.4 ms at
/// 10 kHz, most of a hop; frozen around the first fault with 76.8 ms before
/// it and 25.6 ms after. The board, the QEMU image and the virtual robot
/// keep this many.
pub const CAPTURE_LEN: usize = 1024;

/// The capture: the last `N` [`StepRecord`]s, frozen around the first
/// fault, so that a dump shows what led to the fault, not what the ring
/// holds by the time someone asks.
///
/// While no fault is latched it overwrites its oldest record. The period
/// a fault first latches in starts a countdown of `N / 4` more records;
/// then the capture freezes, holding `3N/4` periods before the fault and
/// `N/4` after it, until [`rearm`](Self::rearm) (a successful fault reset).
/// Reading ([`get`](Self::get)) never removes anything, so a dump can be
/// repeated.
#[derive(Debug, Clone)]
pub struct FaultCapture<const N: usize> {
    buf: [StepRecord; N],
    /// Index the next record goes to.
    next: usize,
    len: usize,
    /// Records still to take after the fault (`Some(0)`: frozen).
    remaining: Option<usize>,
    fault_step: u32,
    /// Held by a reader (a dump in progress): nothing is recorded but a
    /// fault and the records after it.
    held: bool,
}

impl<const N: usize> Default for FaultCapture<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FaultCapture<N> {
    /// Records kept after the fault.
    pub const AFTER_FAULT: usize = N / 4;

    /// Empty, recording.
    pub const fn new() -> Self {
        FaultCapture {
            buf: [StepRecord {
                step: 0,
                phase: 0,
                armed: false,
                faults: 0,
                dac_code: 0,
                body_height_m: 0.0,
                nut_position_m: 0.0,
                spring_force_n: 0.0,
                energy_j: 0.0,
                command_a: 0.0,
            }; N],
            next: 0,
            len: 0,
            remaining: None,
            fault_step: 0,
            held: false,
        }
    }

    /// Takes one period's record; `fault_latched` when its period latched
    /// the first fault (`Period::newly_latched` non-empty). Nothing changes
    /// once frozen.
    #[inline]
    pub fn record(&mut self, r: &StepRecord, fault_latched: bool) {
        // Held for a reader, the records stand still, except that a fault
        // is captured anyway: the fault matters more than the dump.
        if self.remaining == Some(0) || (self.held && self.remaining.is_none() && !fault_latched) {
            return;
        }
        if let Some(slot) = self.buf.get_mut(self.next) {
            *slot = *r;
        }
        self.next = if self.next + 1 >= N { 0 } else { self.next + 1 };
        self.len = (self.len + 1).min(N);
        match self.remaining {
            Some(k) => self.remaining = Some(k.saturating_sub(1)),
            None if fault_latched => {
                self.fault_step = r.step;
                self.remaining = Some(Self::AFTER_FAULT);
            }
            None => {}
        }
    }

    /// Whether a fault froze the capture.
    pub fn frozen(&self) -> bool {
        self.remaining == Some(0)
    }

    /// The period the fault that froze (or is freezing) the capture
    /// latched in.
    pub fn fault_step(&self) -> Option<u32> {
        self.remaining.map(|_| self.fault_step)
    }

    /// Records held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether nothing was recorded yet.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Record `i`, oldest first.
    pub fn get(&self, i: usize) -> Option<&StepRecord> {
        self.get_from(self.start(), i)
    }

    /// Where the oldest record is now: the origin of [`get`](Self::get)'s
    /// indexes, which a reader that takes several periods keeps
    /// ([`get_from`](Self::get_from)).
    pub fn start(&self) -> usize {
        // The oldest is at `next` once the buffer wrapped, else at 0.
        if self.len == N {
            self.next
        } else {
            0
        }
    }

    /// Record `i` counted from `start` (an earlier [`start`](Self::start)):
    /// the records a reader began with, also when a fault has been
    /// recorded since.
    pub fn get_from(&self, start: usize, i: usize) -> Option<&StepRecord> {
        if i >= self.len || start >= N {
            return None;
        }
        let j = start + i;
        self.buf.get(if j >= N { j - N } else { j })
    }

    /// Records again (the faults were reset); what it holds stays until
    /// overwritten.
    pub fn rearm(&mut self) {
        self.remaining = None;
    }

    /// Holds (or releases) the records for a reader that takes several
    /// periods (a dump): while held and no fault is being captured, nothing
    /// is recorded, so the records read stay consecutive. A fault latched
    /// while held is still captured (the fault matters more than the dump).
    pub fn hold(&mut self, held: bool) {
        self.held = held;
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
    /// The motor's copper loss over the hop, from the previous apex (or the
    /// first period after a start) to this apex, as the simulator's
    /// per-hop ledger counts it: `int i^2 R(T) dt` of the current the
    /// amplifier was told to drive (0 while disabled), at the thermal
    /// estimate's winding resistance, J: the heat the estimate heats with
    /// (docs/endurance.md).
    pub copper_loss_j: f32,
    /// The part of [`Self::copper_loss_j`] spent in stance, J (the rest is
    /// the flight's, mostly returning the nut).
    pub stance_copper_loss_j: f32,
}

/// Builds [`HopLedger`]s from the estimator's events and per-step data.
#[derive(Clone, Debug, Default)]
pub struct HopLedgerBuilder {
    cur: HopLedger,
    in_stance: bool,
    started: bool,
    hops: u32,
    /// Copper loss since the last apex, before the next touchdown, J.
    falling_copper_j: f32,
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
                copper_loss_j: 0.0,
                stance_copper_loss_j: 0.0,
            },
            in_stance: false,
            started: false,
            hops: 0,
            falling_copper_j: 0.0,
        }
    }

    /// Touchdown with the energy estimate at that instant, J.
    pub fn touchdown(&mut self, energy_j: f32) {
        self.hops = self.hops.saturating_add(1);
        // A stance that ended without an apex (too low a bounce to detect
        // one, a withdrawn touchdown) hands its heat on: a hop's copper runs
        // from the previous booked apex.
        let (open_j, open_stance_j) = if self.started {
            (self.cur.copper_loss_j, self.cur.stance_copper_loss_j)
        } else {
            (0.0, 0.0)
        };
        self.cur = HopLedger {
            hop: self.hops,
            energy_at_touchdown_j: energy_j,
            copper_loss_j: self.falling_copper_j + open_j,
            stance_copper_loss_j: open_stance_j,
            ..HopLedger::default()
        };
        self.falling_copper_j = 0.0;
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

    /// Copper loss the motor took, J (the current the amplifier was told to
    /// drive, at the winding's estimated resistance: what the thermal
    /// estimate heats with), booked to the hop open now. Non-finite or
    /// negative heat is ignored.
    pub fn heat(&mut self, heat_j: f32) {
        if !(0.0..f32::INFINITY).contains(&heat_j) {
            return;
        }
        if !self.started {
            self.falling_copper_j += heat_j;
            return;
        }
        self.cur.copper_loss_j += heat_j;
        if self.in_stance {
            self.cur.stance_copper_loss_j += heat_j;
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

    fn rec(step: u32) -> StepRecord {
        StepRecord {
            step,
            ..StepRecord::default()
        }
    }

    #[test]
    fn capture_keeps_the_latest_and_freezes_around_the_fault() {
        assert_eq!(core::mem::size_of::<StepRecord>(), 32);
        let mut c: FaultCapture<8> = FaultCapture::new();
        assert!(c.is_empty() && c.get(0).is_none());
        for i in 0..5 {
            c.record(&rec(i), false);
        }
        assert_eq!((c.len(), c.get(0).map(|r| r.step)), (5, Some(0)));
        for i in 5..20 {
            c.record(&rec(i), i == 12);
        }
        // Fault at step 12: two more records (8 / 4), then frozen.
        assert!(c.frozen());
        assert_eq!(c.fault_step(), Some(12));
        let steps: heapless::Vec<u32, 8> = (0..c.len())
            .filter_map(|i| c.get(i))
            .map(|r| r.step)
            .collect();
        assert_eq!(steps.as_slice(), &[7, 8, 9, 10, 11, 12, 13, 14]);
        assert!(c.get(8).is_none());
        // A reset rearms: recording resumes, the oldest go first.
        c.rearm();
        assert!(!c.frozen() && c.fault_step().is_none());
        c.record(&rec(100), false);
        assert_eq!(c.get(7).map(|r| r.step), Some(100));
        assert_eq!(c.get(0).map(|r| r.step), Some(8));
        // Held for a reader: nothing moves until released.
        c.hold(true);
        c.record(&rec(101), false);
        assert_eq!(c.get(7).map(|r| r.step), Some(100));
        c.hold(false);
        c.record(&rec(102), false);
        assert_eq!(c.get(7).map(|r| r.step), Some(102));
    }

    /// A fault that latches while a reader holds the capture is captured:
    /// its period and the ones after it go in, and the capture freezes.
    #[test]
    fn a_fault_during_a_dump_is_captured() {
        let mut c: FaultCapture<8> = FaultCapture::new();
        for i in 0..10 {
            c.record(&rec(i), false);
        }
        c.hold(true);
        c.record(&rec(10), false);
        c.record(&rec(11), true);
        assert_eq!(c.fault_step(), Some(11));
        c.record(&rec(12), false);
        c.record(&rec(13), false);
        assert!(c.frozen());
        let steps: heapless::Vec<u32, 8> = (0..c.len())
            .filter_map(|i| c.get(i))
            .map(|r| r.step)
            .collect();
        assert_eq!(steps.as_slice(), &[5, 6, 7, 8, 9, 11, 12, 13]);
        c.hold(false);
        c.record(&rec(14), false);
        assert_eq!(c.get(7).map(|r| r.step), Some(13));
    }

    /// A reader that kept its start reads the records it began with while
    /// a fault is recorded behind it (it reads faster than one a period).
    #[test]
    fn a_reader_keeps_its_records_while_a_fault_is_captured() {
        let mut c: FaultCapture<8> = FaultCapture::new();
        for i in 0..10 {
            c.record(&rec(i), false);
        }
        let start = c.start();
        c.hold(true);
        let mut read = heapless::Vec::<u32, 8>::new();
        let mut next = 0;
        for k in 0..4 {
            // Two records a period, while the fault and its aftermath go in.
            for _ in 0..2 {
                if let Some(r) = c.get_from(start, next) {
                    let _ = read.push(r.step);
                }
                next += 1;
            }
            c.record(&rec(20 + k), k == 0);
        }
        assert_eq!(read.as_slice(), &[2, 3, 4, 5, 6, 7, 8, 9]);
        assert_eq!(c.fault_step(), Some(20));
    }

    #[test]
    fn hop_ledger_accumulates_stance_work() {
        let mut b = HopLedgerBuilder::new();
        assert_eq!(b.apex(0.1), None);
        // Falling before the touchdown: 1 ms of 10 A on 0.3 ohm.
        for _ in 0..10 {
            b.heat(10.0 * 10.0 * 0.3 * 1e-4);
        }
        b.touchdown(70.0);
        for _ in 0..1000 {
            b.step(1e-4, 20.0, 0.5, 100.0, 0.02);
            b.heat(20.0 * 20.0 * 0.3 * 1e-4);
        }
        b.liftoff(72.0);
        b.step(1e-4, -5.0, -0.1, -50.0, 0.01);
        b.heat(5.0 * 5.0 * 0.3 * 1e-4);
        b.heat(f32::NAN);
        b.heat(-1.0);
        let h = b.apex(0.12).unwrap_or_default();
        assert_eq!(h.hop, 1);
        assert!((h.stance_work_j - 5.0).abs() < 1e-3, "{}", h.stance_work_j);
        assert!((h.stance_duration_s - 0.1).abs() < 1e-5);
        assert_eq!(h.peak_current_a, 20.0);
        assert_eq!(h.peak_stroke_m, 0.02);
        assert_eq!(h.energy_at_liftoff_j, 72.0);
        // 0.1 s of 20 A on 0.3 ohm in stance; in flight 1 ms of 10 A
        // falling and 0.1 ms of 5 A rising.
        assert!((h.stance_copper_loss_j - 12.0).abs() < 1e-3);
        let flight_j = 0.03 + 7.5e-4;
        assert!((h.copper_loss_j - h.stance_copper_loss_j - flight_j).abs() < 1e-5);
        assert_eq!(b.apex(0.1), None);
    }

    #[test]
    fn a_stance_without_an_apex_hands_its_heat_to_the_next_hop() {
        let mut b = HopLedgerBuilder::new();
        b.touchdown(70.0);
        b.heat(1.0);
        b.liftoff(70.0);
        b.heat(2.0);
        // A bounce too low for an apex: the next touchdown comes first.
        b.touchdown(70.0);
        b.heat(4.0);
        b.liftoff(70.0);
        b.heat(8.0);
        let h = b.apex(0.01).unwrap_or_default();
        assert_eq!(h.hop, 2);
        assert_eq!(h.copper_loss_j, 15.0);
        assert_eq!(h.stance_copper_loss_j, 5.0);
        // The next hop starts from this apex.
        b.heat(16.0);
        b.touchdown(70.0);
        b.liftoff(70.0);
        assert_eq!(b.apex(0.01).unwrap_or_default().copper_loss_j, 16.0);
    }
}
