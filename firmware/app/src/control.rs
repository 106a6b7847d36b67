//! What the board and the QEMU applications share: the build-time control
//! rate, the telemetry capture size, and the per-step instruction statistics.

use hopper_control::telemetry::TelemetryRing;

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

/// Records in the telemetry capture buffer (32 bytes each): the last
/// 25.6 ms at 10 kHz, dumped on request.
pub const CAPTURE_LEN: usize = 256;

/// The capture buffer type.
pub type Capture = TelemetryRing<CAPTURE_LEN>;

/// Min / mean / max of a per-step cost (instructions or cycles).
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct StepStats {
    /// Smallest sample.
    pub min: u32,
    /// Largest sample.
    pub max: u32,
    /// Sum of the samples.
    pub sum: u64,
    /// Number of samples.
    pub count: u32,
}

impl Default for StepStats {
    fn default() -> Self {
        Self::new()
    }
}

impl StepStats {
    /// No samples yet.
    pub const fn new() -> Self {
        StepStats {
            min: u32::MAX,
            max: 0,
            sum: 0,
            count: 0,
        }
    }

    /// Adds one sample.
    pub fn add(&mut self, x: u32) {
        self.min = self.min.min(x);
        self.max = self.max.max(x);
        self.sum = self.sum.saturating_add(u64::from(x));
        self.count = self.count.saturating_add(1);
    }

    /// Mean, rounded down (0 without samples).
    pub fn mean(&self) -> u32 {
        if self.count == 0 {
            0
        } else {
            u32::try_from(self.sum / u64::from(self.count)).unwrap_or(u32::MAX)
        }
    }
}
