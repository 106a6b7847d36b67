//! The hardware deadman on the amplifier enable: what software cannot
//! switch off. The enable pin is a timer's output in one-pulse mode
//! (docs/board.md, "Hardware deadman on AMP_EN"): the output is high only
//! while the timer counts, every control period that drives the motor
//! restarts the count ([`Write::Retrigger`]), and the count stops by itself
//! [`WINDOW_PERIODS`] periods after the last restart. So the amplifier
//! drops within that window of the control interrupt stopping, whatever
//! the core does: a lockup, a debugger halt (the timer keeps counting), a
//! handler that hangs. A period that does not drive the motor forces the
//! output low at once ([`Write::ForceLow`]).
//!
//! The board programs the timer from [`prescaler`] and [`window_ticks`];
//! [`OnePulse`] is the timer as RM0090 describes it (upcounting, one-pulse
//! mode, PWM mode 2 with the compare at 1), so the retrigger logic is
//! tested here, on the host.

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

/// What a control period writes to the timer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Write {
    /// The amplifier enabled this period: `CNT = COMPARE`, PWM mode 2, the
    /// counter started (the window starts again).
    Retrigger,
    /// Disabled: the output forced low (OC3M = force inactive), the
    /// counter stopped.
    ForceLow,
}

/// The period's write for the enable it decided.
pub fn write_for(enable: bool) -> Write {
    if enable {
        Write::Retrigger
    } else {
        Write::ForceLow
    }
}

/// The timer, upcounting in one-pulse mode: counts from `CNT` to `ARR`,
/// then the update event returns it to 0 and stops it. Its output, in PWM
/// mode 2 with the compare at [`COMPARE`], is high while the counter is at
/// or beyond the compare; forced low, it is low.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OnePulse {
    cnt: u32,
    arr: u32,
    running: bool,
    forced_low: bool,
}

impl OnePulse {
    /// As `init` leaves it: stopped, forced low, the window `arr` ticks.
    pub fn new(arr: u16) -> Self {
        Self {
            cnt: 0,
            arr: u32::from(arr),
            running: false,
            forced_low: true,
        }
    }

    /// A period's write.
    pub fn apply(&mut self, w: Write) {
        match w {
            Write::Retrigger => {
                self.forced_low = false;
                self.cnt = u32::from(COMPARE);
                self.running = true;
            }
            Write::ForceLow => {
                self.forced_low = true;
                self.running = false;
            }
        }
    }

    /// `ticks` of the timer's clock.
    pub fn advance(&mut self, ticks: u32) {
        if !self.running {
            return;
        }
        let to_update = self.arr.saturating_sub(self.cnt);
        if ticks > to_update {
            // The update event: back to 0 and stopped (OPM).
            self.cnt = 0;
            self.running = false;
        } else {
            self.cnt += ticks;
        }
    }

    /// The pin: high (the amplifier enabled) or low.
    pub fn output(&self) -> bool {
        !self.forced_low && self.cnt >= u32::from(COMPARE)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    const CONTROL_HZ: u32 = 10_000;
    const TICKS_PER_PERIOD: u32 = TICK_HZ / CONTROL_HZ;

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

    /// Retriggered every period (jittering by up to a quarter period) the
    /// output never drops; once the periods stop it drops within the
    /// window, and stays low; a disabled period drops it at once.
    #[test]
    fn the_enable_holds_while_retriggered_and_drops_within_the_window() {
        let arr = window_ticks(CONTROL_HZ);
        let mut t = OnePulse::new(arr);
        assert!(!t.output(), "low from init");
        for k in 0..10_000u32 {
            t.apply(write_for(true));
            assert!(t.output());
            // A period of 100 us, +- 25 us.
            let jitter = (k * 7919) % 51;
            t.advance(TICKS_PER_PERIOD + jitter - 25);
            assert!(t.output(), "dropped while retriggered, period {k}");
        }
        // The control interrupt stops: low after at most the window.
        let mut high_for = 0;
        while t.output() {
            t.advance(1);
            high_for += 1;
            assert!(high_for <= u32::from(arr), "still high");
        }
        assert!(high_for <= u32::from(arr) - TICKS_PER_PERIOD + 25);
        for _ in 0..1_000 {
            t.advance(TICKS_PER_PERIOD);
            assert!(!t.output(), "rose again without a retrigger");
        }
        // Enabled again, then disabled: low at once, and it stays low.
        t.apply(write_for(true));
        assert!(t.output());
        t.apply(write_for(false));
        assert!(!t.output());
        t.advance(1);
        assert!(!t.output());
    }

    /// Whatever the periods do, the output is high only within the window
    /// after a retrigger.
    #[test]
    fn the_output_is_high_only_within_a_window_of_a_retrigger() {
        use proptest::prelude::*;
        proptest!(|(steps in proptest::collection::vec((any::<bool>(), 0u32..1_000), 1..200))| {
            let arr = window_ticks(CONTROL_HZ);
            let mut t = OnePulse::new(arr);
            for (enable, ticks) in steps {
                t.apply(write_for(enable));
                // Ticks since the last retrigger (a disabled period ends it).
                let mut since = enable.then_some(0u32);
                for _ in 0..ticks {
                    t.advance(1);
                    since = since.map(|s| s + 1);
                    let in_window = since.is_some_and(|s| s < u32::from(arr));
                    prop_assert_eq!(t.output(), in_window);
                }
            }
        });
    }
}
