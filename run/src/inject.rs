//! Fault injection: `hopper-sim run --inject KIND@TIME`.
//!
//! Each [`InjectKind`] breaks one thing in the simulated hardware (or, for `nan`, in
//! the converted measurements, through the control crate's
//! `fault-injection` hook; for `overrun`, through the report the RTIC
//! application makes) from the first control period that starts at `TIME`
//! on. [`crate::controller::FirmwareController`] applies them, so the CLI
//! and the tests (`tests/tests/fault_injection.rs`) share one code path.
//! What the supervisor latches for each, and how fast: `docs/safety.md`.

use std::fmt;

/// Counts an `encoder-jump` adds to the motor encoder (a glitch of 500
/// counts, 1.25 mm of nut: far beyond the 64 counts a period can move).
pub const ENCODER_JUMP_COUNTS: u32 = 500;

/// Extra noise of a `noise-burst` on both ADC channels, codes (1 sigma):
/// 200 N on the load cell, 11.7 mm on the potentiometer.
pub const NOISE_BURST_SIGMA_CODES: u16 = 400;

/// How long a `noise-burst` lasts, s.
pub const NOISE_BURST_DURATION_S: f64 = 0.01;

/// What to break.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InjectKind {
    /// The motor encoder counter jumps by [`ENCODER_JUMP_COUNTS`] (and stays shifted).
    EncoderJump,
    /// The motor encoder counter stops at the value it last read.
    EncoderFrozen,
    /// The load-cell ADC sticks at the code it last read.
    LoadcellStuck,
    /// The load-cell ADC reads its top rail (full scale).
    LoadcellSaturated,
    /// The potentiometer wiper is open: its ADC reads the bottom rail, code 0.
    PotOpen,
    /// The converted spring force is NaN (a broken conversion or memory fault).
    Nan,
    /// [`NOISE_BURST_SIGMA_CODES`] of noise on both ADCs for [`NOISE_BURST_DURATION_S`].
    NoiseBurst,
    /// The e-stop input reads pressed (and stays pressed).
    Estop,
    /// The amplifier's fault output is asserted (and stays asserted).
    AmpFault,
    /// Every DAC write fails from then on.
    DacError,
    /// One control period overran; the application reports it.
    Overrun,
}

impl InjectKind {
    /// Every kind, in the order of [`INJECT_KINDS`].
    pub const ALL: [InjectKind; 11] = [
        InjectKind::EncoderJump,
        InjectKind::EncoderFrozen,
        InjectKind::LoadcellStuck,
        InjectKind::LoadcellSaturated,
        InjectKind::PotOpen,
        InjectKind::Nan,
        InjectKind::NoiseBurst,
        InjectKind::Estop,
        InjectKind::AmpFault,
        InjectKind::DacError,
        InjectKind::Overrun,
    ];

    /// The name `--inject` takes.
    pub const fn name(self) -> &'static str {
        match self {
            InjectKind::EncoderJump => "encoder-jump",
            InjectKind::EncoderFrozen => "encoder-frozen",
            InjectKind::LoadcellStuck => "loadcell-stuck",
            InjectKind::LoadcellSaturated => "loadcell-saturated",
            InjectKind::PotOpen => "pot-open",
            InjectKind::Nan => "nan",
            InjectKind::NoiseBurst => "noise-burst",
            InjectKind::Estop => "estop",
            InjectKind::AmpFault => "amp-fault",
            InjectKind::DacError => "dac-error",
            InjectKind::Overrun => "overrun",
        }
    }

    /// The kind named `name`.
    pub fn from_name(name: &str) -> Option<InjectKind> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// The supervisor fault(s) ([`hopper_control::supervisor::Fault::name`])
    /// that detect this kind; the first is the one expected, the others may
    /// latch first or as well (see `docs/safety.md`).
    pub const fn detected_as(self) -> &'static [&'static str] {
        match self {
            InjectKind::EncoderJump => &["encoder-jump"],
            // At speed away from the stops at once; else once the nut has
            // moved off the frozen reading.
            InjectKind::EncoderFrozen => &["encoder-frozen", "sensor-disagree"],
            InjectKind::LoadcellStuck => &["sensor-disagree"],
            InjectKind::LoadcellSaturated => &["sensor-range"],
            InjectKind::PotOpen => &["sensor-range"],
            InjectKind::Nan => &["sensor-nonfinite"],
            // A burst sample lands outside its channel's range or off the
            // spring model; either latches.
            InjectKind::NoiseBurst => &["sensor-disagree", "sensor-range"],
            InjectKind::Estop => &["estop"],
            InjectKind::AmpFault => &["amp-fault"],
            InjectKind::DacError => &["dac-error"],
            InjectKind::Overrun => &["overrun"],
        }
    }
}

/// The names `--inject` accepts.
pub const INJECT_KINDS: [&str; 11] = {
    let mut names = [""; 11];
    let mut i = 0;
    while i < 11 {
        names[i] = InjectKind::ALL[i].name();
        i += 1;
    }
    names
};

/// One fault to inject: what, and from when.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Injection {
    /// What breaks.
    pub kind: InjectKind,
    /// Simulated time from which it is broken, s (>= 0).
    pub time_s: f64,
}

impl Injection {
    /// Parses `KIND@TIME` (`estop@0.5`). The error names the accepted kinds.
    pub fn parse(spec: &str) -> Result<Injection, String> {
        let usage = || {
            format!(
                "bad fault injection `{spec}`: expected KIND@TIME with TIME in seconds (>= 0) and KIND one of {}",
                INJECT_KINDS.join(", ")
            )
        };
        let Some((kind, time)) = spec.trim().split_once('@') else {
            return Err(usage());
        };
        let Some(kind) = InjectKind::from_name(kind.trim()) else {
            return Err(format!(
                "unknown fault kind `{}` in `{spec}`: expected one of {}",
                kind.trim(),
                INJECT_KINDS.join(", ")
            ));
        };
        match time.trim().parse::<f64>() {
            Ok(t) if t.is_finite() && t >= 0.0 => Ok(Injection { kind, time_s: t }),
            _ => Err(usage()),
        }
    }
}

impl fmt::Display for Injection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}@{}", self.kind.name(), self.time_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_kind_and_rejects_bad_specs() {
        for k in InjectKind::ALL {
            let i = Injection::parse(&format!("{}@0.25", k.name())).unwrap();
            assert_eq!((i.kind, i.time_s), (k, 0.25));
            assert!(!k.detected_as().is_empty());
        }
        for bad in [
            "estop",
            "estop@",
            "estop@-1",
            "estop@nan",
            "estop@inf",
            "boom@1",
        ] {
            let e = Injection::parse(bad).unwrap_err();
            assert!(e.contains("encoder-jump") && e.contains("overrun"), "{e}");
        }
        assert!(Injection::parse("boom@1").unwrap_err().contains("`boom`"));
    }
}
