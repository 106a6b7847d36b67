//! What the board and the QEMU applications share: the build-time control
//! rate and overrun limit, the telemetry capture size, the log queue and
//! the controller bank.

use hopper_control::hopper::{Hopper, HopperConfig};
use hopper_control::runner::{PeriodRunner, RunnerError, Timing};
use hopper_control::telemetry::{FaultCapture, CAPTURE_LEN};

/// Parses a decimal `u32` at compile time; `default` when absent or malformed
/// (a malformed value then fails the range assert below instead of panicking).
pub const fn parse_u32(s: Option<&str>, default: u32) -> u32 {
    let Some(s) = s else {
        return default;
    };
    let b = s.as_bytes();
    if b.is_empty() {
        return 0;
    }
    let mut i = 0;
    let mut v: u32 = 0;
    while i < b.len() {
        let d = b[i];
        if d < b'0' || d > b'9' {
            return 0;
        }
        v = match v.checked_mul(10) {
            Some(x) => match x.checked_add((d - b'0') as u32) {
                Some(y) => y,
                None => return 0,
            },
            None => return 0,
        };
        i += 1;
    }
    v
}

/// Control loop rate, Hz: 10 kHz unless the build sets `HOPPER_CONTROL_HZ`
/// (e.g. `HOPPER_CONTROL_HZ=5000 cargo build ...`), in 100..=20_000.
pub const CONTROL_HZ: u32 = parse_u32(option_env!("HOPPER_CONTROL_HZ"), 10_000);

const _: () = assert!(
    CONTROL_HZ >= 100 && CONTROL_HZ <= 20_000,
    "HOPPER_CONTROL_HZ must be a whole number of Hz in 100..=20000"
);

/// Missed control deadlines in a row after which the firmware goes safe
/// (latches `Fault::Overrun`): 3 unless the build sets `HOPPER_OVERRUN_LIMIT`
/// (1..=1000). One late period is tolerated (the next one catches up); three
/// in a row mean the loop cannot keep its rate.
pub const OVERRUN_LIMIT: u32 = parse_u32(option_env!("HOPPER_OVERRUN_LIMIT"), 3);

const _: () = assert!(
    OVERRUN_LIMIT >= 1 && OVERRUN_LIMIT <= 1000,
    "HOPPER_OVERRUN_LIMIT must be in 1..=1000"
);

/// Control period, s.
#[allow(clippy::cast_precision_loss)] // CONTROL_HZ <= 20_000 is exact in f32.
pub const CONTROL_PERIOD_S: f32 = 1.0 / CONTROL_HZ as f32;

/// The capture buffer type (`hopper_control::telemetry::CAPTURE_LEN`
/// records), dumped on request (the link's `dump`, the dump button).
pub type Capture = FaultCapture<CAPTURE_LEN>;

/// The runner's pacing: [`CONTROL_PERIOD_S`] and [`OVERRUN_LIMIT`].
pub const TIMING: Timing = Timing {
    period_s: CONTROL_PERIOD_S,
    overrun_limit: OVERRUN_LIMIT,
    max_jitter_s: hopper_control::runner::DEFAULT_MAX_JITTER_S,
};

/// Log items the control task can queue for the logger before one is
/// dropped (and counted).
pub const LOG_CAPACITY: usize = 16;

/// A controller slot of the bank: a new controller built by the link task
/// goes in by exchanging two of these at a period boundary, not by
/// copying 1.2 KB in the control interrupt.
pub type Slot = &'static mut Hopper;

/// The bank: the running controller and the link task's spares
/// (`hopper_control::link::SPARES`).
pub type Bank = [Option<Hopper>; 1 + hopper_control::link::SPARES];

/// A period runner on `cfg` in the bank's first slot, and the spare slots
/// (copies of it until the link task fills them).
pub fn runner_in_bank(
    bank: &'static mut Bank,
    cfg: HopperConfig,
    timing: Timing,
) -> Result<(PeriodRunner<Slot>, [Slot; 2]), RunnerError> {
    let h = Hopper::new(cfg).map_err(RunnerError::Config)?;
    let [a, b, c] = bank;
    let spares = [b.insert(h.clone()), c.insert(h.clone())];
    let runner = PeriodRunner::in_slot(cfg, timing, a.insert(h))?;
    Ok((runner, spares))
}
