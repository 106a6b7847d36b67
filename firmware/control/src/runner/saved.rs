//! The saved calibration in the runner ([`crate::persist`]'s record): the
//! record read from flash at boot and applied, what was found there, and
//! the record of the calibration in use, for saving.

use super::{HopperSlot, PeriodRunner};

impl<H: HopperSlot> PeriodRunner<H> {
    /// At boot, before the first period: the saved calibration record read
    /// from flash (`None`: the store holds none). A record that checks
    /// out is applied (every entry range-checked, the whole configuration
    /// validated) and counts as the calibration `arming.require_tare`
    /// asks for; a refused one changes nothing.
    pub fn load_calibration(&mut self, record: Option<&[u8]>) {
        use crate::persist::{decode, AtBoot, LoadError};
        self.at_boot = match record {
            None => AtBoot::NothingSaved,
            Some(r) => match decode(r, self.hopper.config()) {
                Ok(cfg) => match self.rebuild(cfg) {
                    Ok(()) => {
                        // Only a record with the tare's offsets stands for one.
                        if crate::persist::has_offsets(r) {
                            self.arming.note_tared();
                        }
                        AtBoot::Loaded(r.get(6).copied().unwrap_or(0))
                    }
                    Err(_) => AtBoot::Refused(LoadError::Refused("configuration")),
                },
                Err(e) => AtBoot::Refused(e),
            },
        };
    }

    /// What was found in flash at boot.
    pub fn calibration_at_boot(&self) -> crate::persist::AtBoot {
        self.at_boot
    }

    /// The record of the calibration in use, for saving; its length.
    pub fn calibration_record(&self, out: &mut [u8; crate::persist::MAX_RECORD]) -> usize {
        crate::persist::encode(self.hopper.config(), out)
    }
}
