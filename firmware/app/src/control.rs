//! What the board and the QEMU applications share: the build-time control
//! rate and overrun limit, the telemetry capture size, the log queue and
//! the controller bank.

use hopper_control::hopper::{Hopper, HopperConfig};
use hopper_control::runner::{PeriodRunner, RunnerError, Timing};
use hopper_control::telemetry::{FaultCapture, CAPTURE_LEN};

// `CONTROL_HZ` and `OVERRUN_LIMIT`, from the build's environment, checked
// by the build script.
include!(concat!(env!("OUT_DIR"), "/build_config.rs"));

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
/// (`hopper_robot_link::SPARES`).
pub type Bank = [Option<Hopper>; 1 + hopper_robot_link::SPARES];

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

/// The capture through an RTIC lock, as the control loop and the link task
/// reach it (`hopper_robot_link::Shared`): the link task copies a record or
/// flips a flag under it, a few dozen cycles of the control priority.
pub struct Locked<M>(pub M);

impl<M: rtic::Mutex<T = &'static mut Capture>> hopper_robot_link::Shared<Capture> for Locked<M> {
    fn with<R>(&mut self, f: impl FnOnce(&mut Capture) -> R) -> R {
        self.0.lock(|c| f(c))
    }
}
