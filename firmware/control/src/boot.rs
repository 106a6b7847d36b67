//! What the board found at boot: why the MCU reset, whether the
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
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr, strum::VariantArray)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[strum(serialize_all = "kebab-case")]
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
    #[strum(serialize = "watchdog")]
    IndependentWatchdog = 4,
    /// WWDGRSTF: the window watchdog (unused here).
    WindowWatchdog = 5,
    /// LPWRRSTF: low-power management.
    LowPower = 6,
}

impl ResetCause {
    /// Every cause, in bit order.
    pub const ALL: &'static [ResetCause] = <ResetCause as strum::VariantArray>::VARIANTS;

    /// Kebab-case name, as the link prints it.
    pub fn name(self) -> &'static str {
        self.into()
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
            .iter()
            .copied()
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
    /// The crystal the clock profile names, Hz (0: no crystal, not a board).
    pub hse_expected_hz: u32,
    /// The crystal as measured against the internal oscillator at boot, Hz
    /// ([`Crystal`]; 0: not measured: the crystal did not start, or no
    /// board).
    pub hse_measured_hz: u32,
}

/// The crystal measured against the internal 16 MHz RC oscillator (HSI,
/// factory-trimmed to 1% at 25 C, within 4% over temperature: DS8626): a
/// timer clocked from the HSI captures every `edges`-th edge of the
/// crystal's frequency divided by `divider` (the F405 routes HSE/RTCPRE to
/// TIM11's channel 1), `ticks` timer counts apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Crystal {
    /// The timer's clock, Hz (the HSI).
    pub timer_hz: u32,
    /// The crystal's frequency divider before the capture (RTCPRE).
    pub divider: u32,
    /// Edges per capture (the capture prescaler).
    pub edges: u32,
}

impl Crystal {
    /// How far the measured crystal may be from the profile's, as a
    /// fraction: the HSI's 4% over temperature and a count of quantisation
    /// (1.2% at 8 MHz), with margin; the boards' crystals (8, 12, 16, 25
    /// MHz) are at least a third apart.
    pub const TOLERANCE: f32 = 0.1;

    /// The crystal's frequency from the timer counts between two captures,
    /// Hz (0 for no counts).
    pub const fn hz_from_ticks(&self, ticks: u32) -> u32 {
        if ticks == 0 {
            return 0;
        }
        let hz = self.timer_hz as u64 * self.divider as u64 * self.edges as u64 / ticks as u64;
        if hz > u32::MAX as u64 {
            u32::MAX
        } else {
            hz as u32
        }
    }

    /// Whether `measured_hz` is the `expected_hz` crystal, within
    /// [`Self::TOLERANCE`].
    pub fn matches(measured_hz: u32, expected_hz: u32) -> bool {
        let (m, e) = (measured_hz as f32, expected_hz as f32);
        expected_hz > 0 && (m - e).abs() <= Self::TOLERANCE * e
    }
}

impl BootReport {
    /// Not a board (the simulator, the QEMU images): a power-on reset,
    /// everything as configured, 168 MHz.
    pub const NOT_A_BOARD: BootReport = BootReport {
        resets: ResetCauses(1 << ResetCause::PowerOn as u8),
        brown_out_reset_on: true,
        clock_as_configured: true,
        sysclk_hz: 168_000_000,
        hse_expected_hz: 0,
        hse_measured_hz: 0,
    };

    /// Whether the crystal was measured and is not the profile's.
    pub fn crystal_mismatch(&self) -> bool {
        self.hse_measured_hz != 0 && !Crystal::matches(self.hse_measured_hz, self.hse_expected_hz)
    }

    /// FLASH_OPTCR's BOR_LEV field (bits 3:2) means "on" unless it is `0b11`.
    pub const fn brown_out_reset_on_from_optcr(optcr: u32) -> bool {
        (optcr >> 2) & 0b11 != 0b11
    }

    /// Why arming must be refused, if it must: the crystal (a board built
    /// for another crystal: the board then stays on the HSI rather than
    /// run the PLL too fast), the clock (every timing, the watchdog's
    /// excepted, would be off), then the brown-out reset.
    pub fn refusal(&self) -> Option<ArmRefusal> {
        if self.crystal_mismatch() {
            Some(ArmRefusal::CrystalMismatch)
        } else if !self.clock_as_configured {
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

    /// The capture arithmetic and the tolerance: an 8 MHz crystal on the
    /// 8 MHz profile passes with the HSI 4% off either way, a 12 MHz one
    /// (a Feather with the default build) does not, and refuses arming.
    #[test]
    fn the_crystal_is_told_from_another_one() {
        // HSE / 8 (RTCPRE), every 8th edge, counted at 16 MHz.
        let c = Crystal {
            timer_hz: 16_000_000,
            divider: 8,
            edges: 8,
        };
        assert_eq!(c.hz_from_ticks(128), 8_000_000);
        assert_eq!(c.hz_from_ticks(85), 12_047_058);
        assert_eq!(c.hz_from_ticks(0), 0);
        // The HSI 4% fast counts 4% more ticks: the crystal reads 4% low.
        let fast = c.hz_from_ticks(133);
        assert!(Crystal::matches(fast, 8_000_000), "{fast}");
        assert!(Crystal::matches(c.hz_from_ticks(123), 8_000_000));
        assert!(!Crystal::matches(c.hz_from_ticks(85), 8_000_000));
        assert!(!Crystal::matches(c.hz_from_ticks(128), 12_000_000));
        assert!(!Crystal::matches(8_000_000, 0));
        let wrong = BootReport {
            hse_expected_hz: 8_000_000,
            hse_measured_hz: 12_047_058,
            clock_as_configured: false,
            sysclk_hz: 16_000_000,
            ..BootReport::NOT_A_BOARD
        };
        assert_eq!(wrong.refusal(), Some(ArmRefusal::CrystalMismatch));
        let right = BootReport {
            hse_expected_hz: 8_000_000,
            hse_measured_hz: 7_950_000,
            ..BootReport::NOT_A_BOARD
        };
        assert_eq!(right.refusal(), None);
        // Not measured (no crystal start, or no board): not a mismatch.
        assert!(!BootReport::NOT_A_BOARD.crystal_mismatch());
    }
}
