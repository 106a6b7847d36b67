//! The hardware deadman on the amplifier enable: what software cannot
//! switch off. The enable pin is a timer's output in one-pulse mode
//! (docs/board.md, "Hardware deadman on AMP_EN"): the output is high only
//! while the timer counts, every control period that drives the motor
//! restarts the count ([`Deadman::set`]), and the count stops by itself
//! [`WINDOW_PERIODS`] periods after the last restart. So the amplifier
//! drops within that window of the control interrupt stopping, whatever
//! the core does: a lockup, a debugger halt (the timer keeps counting), a
//! handler that hangs. A period that does not drive the motor forces the
//! output low at once ([`force_off`]).
//!
//! The board's register writes are here, once, as [`Deadman`] over the
//! timer's registers ([`TimerRegs`]: one method, one register write), so
//! that the same call sequence runs on the board (the pin map implements
//! [`TimerRegs`] for its timer) and, in this module's tests, against
//! [`Gpt`], a register-level model of a general-purpose timer as RM0090
//! describes it (CNT, ARR, CCR, CR1's CEN and OPM, CCMRx's OCxM, EGR's UG,
//! CCER; the output computed from them). The tests check after every
//! single write, as a halt (a breakpoint) between any two would leave it,
//! that the output is high only while the counter runs and that it falls
//! within `ARR` ticks: a halted core drops the enable (DBGMCU's freeze bits
//! cleared at boot keep the timer counting through a halt).
//!
//! The order that gives this: the counter runs before the channel leaves
//! forced-inactive (an enable starts the count, then PWM mode 2); a
//! retrigger starts the counter before it moves `CNT` back; a disable
//! forces the channel inactive, then stops the counter, then clears `CNT`
//! (a stopped counter left at `CNT >= CCR` would drive the output high the
//! moment PWM mode 2 returns).

/// The timer's tick, Hz (1 us).
pub const TICK_HZ: u32 = 1_000_000;

/// Control periods the output stays high after the last retrigger.
pub const WINDOW_PERIODS: u32 = 3;

/// The compare value: the output is high while `CNT >= CCR`, so the
/// stopped counter (`CNT = 0`) holds it low.
pub const COMPARE: u16 = 1;

/// The prescaler register value that makes a `timer_hz` clock tick at
/// [`TICK_HZ`] (`PSC + 1` divides).
pub fn prescaler(timer_hz: u32) -> u16 {
    u16::try_from((timer_hz / TICK_HZ).saturating_sub(1)).unwrap_or(u16::MAX)
}

/// The auto-reload value: [`WINDOW_PERIODS`] control periods of ticks (at
/// least 2: the output must rise for one tick at the slowest rate).
pub fn window_ticks(control_hz: u32) -> u16 {
    let ticks = WINDOW_PERIODS.saturating_mul(TICK_HZ) / control_hz.max(1);
    u16::try_from(ticks.max(2)).unwrap_or(u16::MAX)
}

/// The channel's output-compare mode (CCMRx's OCxM) the deadman uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OcMode {
    /// `0b100`: OCxREF forced low.
    ForceInactive,
    /// `0b111`, PWM mode 2 (upcounting): OCxREF high while `CNT >= CCR`.
    Pwm2,
}

/// The deadman timer's registers, one write a method (a general-purpose
/// timer, RM0090 section 18; 16-bit on both pin maps' deadman timers).
/// The pin map implements it for its timer; [`Gpt`] models it.
pub trait TimerRegs {
    /// CR1: one-pulse mode `opm`, counter enable `cen` (every other bit 0).
    fn write_cr1(&mut self, opm: bool, cen: bool);
    /// CR1's CEN: whether the counter runs (OPM clears it at the update).
    fn counter_enabled(&self) -> bool;
    /// PSC (loaded at the next update event).
    fn write_psc(&mut self, psc: u16);
    /// ARR, without preload.
    fn write_arr(&mut self, arr: u16);
    /// The channel's CCR.
    fn write_ccr(&mut self, ccr: u16);
    /// The channel's CCMRx field: output, no preload, mode `mode`.
    fn write_ocm(&mut self, mode: OcMode);
    /// EGR's UG: an update event (the counter to 0, the prescaler loaded).
    fn generate_update(&mut self);
    /// SR's UIF cleared.
    fn clear_update_flag(&mut self);
    /// CNT.
    fn write_cnt(&mut self, cnt: u16);
    /// CCER: the channel's output enabled, active high.
    fn enable_output(&mut self);
    /// Whether the pin reads low, where it can be read back.
    fn pin_reads_low(&self) -> Option<bool> {
        None
    }
}

/// The window lapsed between two enabled periods: the amplifier went off
/// by itself, and stays off ([`Deadman::set`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lapsed;

/// Sets the timer up: stopped, one-pulse, ticking at the prescaled rate,
/// the window `arr` ticks, the channel forced inactive and enabled, the
/// counter at 0. The output is low throughout.
pub fn setup<T: TimerRegs>(t: &mut T, psc: u16, arr: u16) {
    t.write_ocm(OcMode::ForceInactive);
    t.write_cr1(true, false);
    t.write_psc(psc);
    t.write_arr(arr);
    t.write_ccr(COMPARE);
    // Load the prescaler (an update event, with the counter stopped).
    t.generate_update();
    t.clear_update_flag();
    t.write_cnt(0);
    t.enable_output();
}

/// The enable off at once, by writes alone (what a disable and every
/// fault path do): the channel forced inactive first (the output low
/// whatever the counter does), then the counter stopped and cleared, so
/// that nothing of it is left to drive the output when PWM mode 2 returns.
pub fn force_off<T: TimerRegs>(t: &mut T) {
    t.write_ocm(OcMode::ForceInactive);
    t.write_cr1(true, false);
    t.write_cnt(0);
}

/// The amplifier enable through the deadman timer: every enabled period
/// restarts the window, a disabled one forces the output off.
#[derive(Debug)]
pub struct Deadman<T> {
    timer: T,
    /// Whether the channel is in PWM mode 2 (not forced inactive).
    running: bool,
}

impl<T: TimerRegs> Deadman<T> {
    /// The timer set up ([`setup`]) with the window of [`WINDOW_PERIODS`]
    /// periods at `control_hz`, its clock at `timer_hz`; the output low.
    pub fn new(mut timer: T, timer_hz: u32, control_hz: u32) -> Self {
        setup(&mut timer, prescaler(timer_hz), window_ticks(control_hz));
        Self::resume(timer)
    }

    /// A timer [`setup`] already set up (and forced off since): the image
    /// that takes it over from the one that set it up.
    pub fn resume(timer: T) -> Self {
        Self {
            timer,
            running: false,
        }
    }

    /// Enabled: the window starts again (high for [`WINDOW_PERIODS`] more
    /// periods unless retriggered); disabled: forced off at once.
    ///
    /// An enabled period after the window lapsed (the control interrupt
    /// stopped for that long: a halt, a stall) gets [`Lapsed`] and leaves
    /// the output off: the state the amplifier would resume on is stale.
    pub fn set(&mut self, on: bool) -> Result<(), Lapsed> {
        if !on {
            force_off(&mut self.timer);
            self.running = false;
            return Ok(());
        }
        if self.running && !self.timer.counter_enabled() {
            force_off(&mut self.timer);
            self.running = false;
            return Err(Lapsed);
        }
        // The counter runs before CNT moves back to the compare, and both
        // before the channel can drive high.
        self.timer.write_cr1(true, true);
        self.timer.write_cnt(COMPARE);
        if !self.running {
            self.timer.write_ocm(OcMode::Pwm2);
            self.running = true;
        }
        Ok(())
    }
}

impl<T: TimerRegs> crate::hal::AmpEnable for Deadman<T> {
    type Error = Lapsed;

    fn set(&mut self, on: bool) -> Result<(), Lapsed> {
        Deadman::set(self, on)
    }

    fn reads_off(&mut self) -> Option<bool> {
        self.timer.pin_reads_low()
    }
}

/// A general-purpose timer's registers and output as RM0090 describes
/// them (upcounting, 16-bit), for the tests of the board's sequences.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Gpt {
    /// CNT.
    pub cnt: u16,
    /// ARR.
    pub arr: u16,
    /// The channel's CCR.
    pub ccr: u16,
    /// CR1.CEN.
    pub cen: bool,
    /// CR1.OPM.
    pub opm: bool,
    /// The channel's OCxM (`None`: frozen, its reset value).
    pub ocm: Option<OcMode>,
    /// CCER's CCxE.
    pub output_enabled: bool,
    /// Register writes so far.
    pub writes: u32,
    /// The first write after which the output was high with the counter
    /// stopped, or high for longer than ARR ticks: (its number, the
    /// register). A halt right after it would hold the enable high.
    pub broken: Option<(u32, &'static str)>,
}

impl Default for Gpt {
    /// As after reset: every register 0 (ARR 0xFFFF).
    fn default() -> Self {
        Self {
            cnt: 0,
            arr: u16::MAX,
            ccr: 0,
            cen: false,
            opm: false,
            ocm: None,
            output_enabled: false,
            writes: 0,
            broken: None,
        }
    }
}

impl Gpt {
    /// One register write done: counted, and the output checked as a
    /// halt right after it would leave it ([`Gpt::broken`]).
    fn wrote(&mut self, register: &'static str) {
        self.writes += 1;
        if self.broken.is_some() || !self.output() {
            return;
        }
        let falls = self
            .ticks_until_low()
            .is_some_and(|n| n <= u32::from(self.arr));
        if !(self.cen && falls) {
            self.broken = Some((self.writes, register));
        }
    }

    /// The pin: OCxREF through the enabled, active-high channel.
    pub fn output(&self) -> bool {
        let reference = match self.ocm {
            Some(OcMode::Pwm2) => self.cnt >= self.ccr,
            Some(OcMode::ForceInactive) | None => false,
        };
        self.output_enabled && reference
    }

    /// One tick of the prescaled clock: the counter up to ARR, then the
    /// update event (to 0; in one-pulse mode, stopped). From above ARR it
    /// counts on to the top and wraps.
    pub fn tick(&mut self) {
        if !self.cen {
            return;
        }
        if self.cnt == self.arr {
            self.cnt = 0;
            if self.opm {
                self.cen = false;
            }
        } else {
            self.cnt = self.cnt.wrapping_add(1);
        }
    }

    /// Ticks until the output falls with nothing written (`None`: never).
    pub fn ticks_until_low(&self) -> Option<u32> {
        let mut t = *self;
        for n in 0..=u32::from(u16::MAX) + 1 {
            if !t.output() {
                return Some(n);
            }
            if !t.cen {
                return None;
            }
            t.tick();
        }
        None
    }
}

impl TimerRegs for Gpt {
    fn write_cr1(&mut self, opm: bool, cen: bool) {
        self.opm = opm;
        self.cen = cen;
        self.wrote("CR1");
    }
    fn counter_enabled(&self) -> bool {
        self.cen
    }
    fn write_psc(&mut self, _psc: u16) {
        self.wrote("PSC");
    }
    fn write_arr(&mut self, arr: u16) {
        self.arr = arr;
        self.wrote("ARR");
    }
    fn write_ccr(&mut self, ccr: u16) {
        self.ccr = ccr;
        self.wrote("CCR");
    }
    fn write_ocm(&mut self, mode: OcMode) {
        self.ocm = Some(mode);
        self.wrote("OCxM");
    }
    fn generate_update(&mut self) {
        self.cnt = 0;
        if self.opm {
            self.cen = false;
        }
        self.wrote("UG");
    }
    fn clear_update_flag(&mut self) {
        self.wrote("UIF");
    }
    fn write_cnt(&mut self, cnt: u16) {
        self.cnt = cnt;
        self.wrote("CNT");
    }
    fn enable_output(&mut self) {
        self.output_enabled = true;
        self.wrote("CCER");
    }
    fn pin_reads_low(&self) -> Option<bool> {
        Some(!self.output())
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    const CONTROL_HZ: u32 = 10_000;
    const TIMER_HZ: u32 = 84_000_000;
    const TICKS_PER_PERIOD: u32 = TICK_HZ / CONTROL_HZ;

    fn deadman() -> Deadman<Gpt> {
        Deadman::new(Gpt::default(), TIMER_HZ, CONTROL_HZ)
    }

    /// `n` ticks of the timer's clock.
    fn tick(t: &mut Gpt, n: u32) {
        for _ in 0..n {
            t.tick();
        }
    }

    #[test]
    fn the_board_clock_ticks_at_a_microsecond_and_the_window_is_three_periods() {
        // 168 MHz core: APB1 timers at 84 MHz.
        assert_eq!(prescaler(84_000_000), 83);
        // The HSI fallback: 16 MHz.
        assert_eq!(prescaler(16_000_000), 15);
        assert_eq!(window_ticks(CONTROL_HZ), 300);
        assert_eq!(window_ticks(1), u16::MAX);
        assert_eq!(window_ticks(20_000_000), 2);
    }

    /// Enable, disable part-way through a window, enable again, lapse,
    /// the fault entry's writes: the output is never high with the
    /// counter stopped, after any single write.
    #[test]
    fn every_write_of_every_sequence_leaves_a_high_output_running_and_falling_within_the_window() {
        let mut d = deadman();
        assert!(!d.timer.output(), "low after setup");
        // Enabled for some periods, then disabled 150 ticks into a window:
        // the counter must not be left where PWM mode 2 reads it high.
        for _ in 0..5 {
            d.set(true).unwrap();
            tick(&mut d.timer, TICKS_PER_PERIOD);
        }
        tick(&mut d.timer, 50);
        d.set(false).unwrap();
        assert!(!d.timer.output());
        tick(&mut d.timer, 1_000);
        // Enabled again: checked after each of its writes.
        d.set(true).unwrap();
        assert!(d.timer.output());
        // The periods stop: low within the window, and the next enabled
        // period finds it lapsed and keeps it off.
        tick(&mut d.timer, u32::from(window_ticks(CONTROL_HZ)));
        assert!(!d.timer.output());
        assert_eq!(d.set(true), Err(Lapsed));
        assert!(!d.timer.output());
        // Enabled again, then the fault entry's writes mid-window.
        d.set(false).unwrap();
        d.set(true).unwrap();
        tick(&mut d.timer, 120);
        force_off(&mut d.timer);
        assert!(!d.timer.output());
        assert!(!d.timer.cen);
        assert_eq!(d.timer.ocm, Some(OcMode::ForceInactive));
        assert_eq!(d.timer.broken, None);
    }

    /// Retriggered every period (jittering by up to a quarter period) the
    /// output never drops; once the periods stop it drops within the
    /// window, and stays low; a disabled period drops it at once.
    #[test]
    fn the_enable_holds_while_retriggered_and_drops_within_the_window() {
        let arr = window_ticks(CONTROL_HZ);
        let mut d = deadman();
        for k in 0..10_000u32 {
            d.set(true).unwrap();
            assert!(d.timer.output());
            // A period of 100 us, +- 25 us.
            let jitter = (k * 7919) % 51;
            tick(&mut d.timer, TICKS_PER_PERIOD + jitter - 25);
            assert!(d.timer.output(), "dropped while retriggered, period {k}");
        }
        // The control interrupt stops: low after at most the window.
        let mut high_for = 0;
        while d.timer.output() {
            tick(&mut d.timer, 1);
            high_for += 1;
            assert!(high_for <= u32::from(arr), "still high");
        }
        assert!(high_for <= u32::from(arr) - TICKS_PER_PERIOD + 25);
        for _ in 0..1_000 {
            tick(&mut d.timer, TICKS_PER_PERIOD);
            assert!(!d.timer.output(), "rose again without a retrigger");
        }
        // Enabled again (after the lapse is reported), then disabled: low
        // at once, and it stays low.
        assert_eq!(d.set(true), Err(Lapsed));
        d.set(true).unwrap();
        assert!(d.timer.output());
        d.set(false).unwrap();
        assert!(!d.timer.output());
        tick(&mut d.timer, 1);
        assert!(!d.timer.output());
        assert_eq!(d.timer.broken, None);
    }

    /// Whatever the periods do, the output is high only within the window
    /// after a retrigger, and no write leaves it high with the counter
    /// stopped.
    #[test]
    fn the_output_is_high_only_within_a_window_of_a_retrigger() {
        use proptest::prelude::*;
        proptest!(|(steps in proptest::collection::vec((any::<bool>(), 0u32..1_000), 1..200))| {
            let arr = window_ticks(CONTROL_HZ);
            let mut d = deadman();
            let mut lapsed = false;
            for (enable, ticks) in steps {
                let r = d.set(enable);
                // Ticks since the last retrigger (a disabled or lapsed
                // period ends it).
                let mut since = (enable && r.is_ok()).then_some(0u32);
                lapsed |= r.is_err();
                for _ in 0..ticks {
                    tick(&mut d.timer, 1);
                    since = since.map(|s| s + 1);
                    let in_window = since.is_some_and(|s| s < u32::from(arr));
                    prop_assert_eq!(d.timer.output(), in_window);
                }
            }
            let _ = lapsed;
            prop_assert_eq!(d.timer.broken, None);
        });
    }
}
