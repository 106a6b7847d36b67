//! What the board found at boot (issue 18): why the MCU reset, whether the
//! brown-out reset is on, whether the core runs on the clock its profile
//! names. The board fills a [`BootReport`] in `init`; the link reports it
//! (`hopper-link status`), and arming refuses while the clock fell back or
//! the brown-out reset is off ([`BootReport::refusal`]).
//!
//! The simulator and the QEMU images have no such hardware: they run with
//! [`BootReport::NOT_A_BOARD`] (a power-on reset, everything as configured).

use crate::arming::ArmRefusal;

/// One reset cause of RCC_CSR (RM0090 section 7.3.21), in its flag order
/// from bit 25.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum ResetCause {
    /// BORRSTF: the supply fell below the brown-out level.
    BrownOut = 0,
    /// PINRSTF: the NRST pin (the reset button, a debugger).
    Pin = 1,
    /// PORRSTF: power-on or power-down.
    PowerOn = 2,
    /// SFTRSTF: software (`SCB::sys_reset`, a debugger's reset).
    Software = 3,
    /// IWDGRSTF: the independent watchdog (the control task stopped).
    IndependentWatchdog = 4,
    /// WWDGRSTF: the window watchdog (unused here).
    WindowWatchdog = 5,
    /// LPWRRSTF: low-power management.
    LowPower = 6,
}

impl ResetCause {
    /// Every cause, in bit order.
    pub const ALL: [ResetCause; 7] = [
        ResetCause::BrownOut,
        ResetCause::Pin,
        ResetCause::PowerOn,
        ResetCause::Software,
        ResetCause::IndependentWatchdog,
        ResetCause::WindowWatchdog,
        ResetCause::LowPower,
    ];

    /// Kebab-case name, as the link prints it.
    pub const fn name(self) -> &'static str {
        match self {
            ResetCause::BrownOut => "brown-out",
            ResetCause::Pin => "pin",
            ResetCause::PowerOn => "power-on",
            ResetCause::Software => "software",
            ResetCause::IndependentWatchdog => "watchdog",
            ResetCause::WindowWatchdog => "window-watchdog",
            ResetCause::LowPower => "low-power",
        }
    }
}

/// The reset flags, one bit per [`ResetCause`] (a reset often sets
/// several: a power-on also sets the pin flag).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ResetCauses(pub u8);

impl ResetCauses {
    /// From the RCC_CSR value read at boot (flags in bits 25..=31).
    pub const fn from_rcc_csr(csr: u32) -> Self {
        Self(((csr >> 25) & 0x7F) as u8)
    }

    /// Whether `cause` is among them.
    pub const fn contains(self, cause: ResetCause) -> bool {
        self.0 & (1 << cause as u8) != 0
    }

    /// The causes, in bit order.
    pub fn iter(self) -> impl Iterator<Item = ResetCause> {
        ResetCause::ALL
            .into_iter()
            .filter(move |c| self.contains(*c))
    }
}

/// What the board found at boot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BootReport {
    /// Why the MCU reset.
    pub resets: ResetCauses,
    /// The brown-out reset is on (FLASH_OPTCR.BOR_LEV is not `0b11`, the
    /// factory setting "off"): a sagging supply resets the MCU, with the
    /// amplifier disabled, instead of running it out of specification.
    pub brown_out_reset_on: bool,
    /// The core clock is the one the clock profile names (the PLL from the
    /// crystal); `false` when it fell back to the HSI.
    pub clock_as_configured: bool,
    /// The core clock running, Hz.
    pub sysclk_hz: u32,
}

impl BootReport {
    /// Not a board (the simulator, the QEMU images): a power-on reset,
    /// everything as configured, 168 MHz.
    pub const NOT_A_BOARD: BootReport = BootReport {
        resets: ResetCauses(1 << ResetCause::PowerOn as u8),
        brown_out_reset_on: true,
        clock_as_configured: true,
        sysclk_hz: 168_000_000,
    };

    /// FLASH_OPTCR's BOR_LEV field (bits 3:2) means "on" unless it is `0b11`.
    pub const fn brown_out_reset_on_from_optcr(optcr: u32) -> bool {
        (optcr >> 2) & 0b11 != 0b11
    }

    /// Why arming must be refused, if it must: the clock first (every
    /// timing, the watchdog's excepted, would be off), then the brown-out
    /// reset.
    pub const fn refusal(&self) -> Option<ArmRefusal> {
        if !self.clock_as_configured {
            Some(ArmRefusal::ClockFallback)
        } else if !self.brown_out_reset_on {
            Some(ArmRefusal::BrownOutResetOff)
        } else {
            None
        }
    }
}

impl Default for BootReport {
    fn default() -> Self {
        Self::NOT_A_BOARD
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rcc_csr_flags_map_to_causes() {
        // A power-on sets PORRSTF and PINRSTF (reset value 0x0E00_0000).
        let r = ResetCauses::from_rcc_csr(0x0E00_0000);
        let names: heapless::Vec<&str, 7> = r.iter().map(ResetCause::name).collect();
        assert_eq!(names.as_slice(), ["brown-out", "pin", "power-on"]);
        // IWDGRSTF alone (bit 29), LSION (bit 0) ignored.
        let r = ResetCauses::from_rcc_csr((1 << 29) | 1);
        assert!(r.contains(ResetCause::IndependentWatchdog));
        assert_eq!(r.iter().count(), 1);
        assert_eq!(ResetCauses::from_rcc_csr(0xFFFF_FFFF).0, 0x7F);
    }

    #[test]
    fn bor_level_three_is_off() {
        assert!(!BootReport::brown_out_reset_on_from_optcr(0x0FFF_AAEC));
        assert!(BootReport::brown_out_reset_on_from_optcr(0x0FFF_AAE0));
        assert!(BootReport::brown_out_reset_on_from_optcr(0b1000));
    }

    #[test]
    fn a_fallback_clock_or_no_brown_out_reset_refuses_arming() {
        assert_eq!(BootReport::NOT_A_BOARD.refusal(), None);
        let hsi = BootReport {
            clock_as_configured: false,
            sysclk_hz: 16_000_000,
            ..BootReport::NOT_A_BOARD
        };
        assert_eq!(hsi.refusal(), Some(ArmRefusal::ClockFallback));
        let no_bor = BootReport {
            brown_out_reset_on: false,
            ..BootReport::NOT_A_BOARD
        };
        assert_eq!(no_bor.refusal(), Some(ArmRefusal::BrownOutResetOff));
    }
}
