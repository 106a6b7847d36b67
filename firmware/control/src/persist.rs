//! The saved calibration: what `hopper-link save` keeps in
//! flash and the firmware loads at boot, as one self-checking record.
//!
//! What is saved is the machine's own constants, every parameter of
//! [`SAVED`]: the `model.*` table entries (masses, screw, spring, motor),
//! the `calibration.*` ones (the tare's offsets, the sensors' gains and
//! directions, the DAC's zero) and the spring's rate and preload the spring
//! sweep finds. Not saved: the encoders' zeros (homing
//! and the height zero are per boot: the encoders are incremental), the
//! controller and its gains (chosen per run).
//!
//! The record: `"HCAL"`, the format [`VERSION`] (u16), the entry count
//! (u8), then per entry the FNV-1a hash of the parameter's name (u32) and
//! its value (f32), all little-endian, then the CRC-16/XMODEM of all that.
//! Names rather than table indices: a firmware whose table gained or lost
//! a parameter still reads an older record, and an entry it does not know
//! refuses the whole record (nothing half-applied). Loading sets every
//! entry through [`crate::params::set`], so each value is range-checked
//! like a link's set, and the whole configuration is validated before
//! anything changes.

use crate::hopper::HopperConfig;
use crate::params::{self, Param};

/// CRC-16/XMODEM of `bytes`: the record's check (the link's frames use the
/// same check; the record is not a frame, so it computes its own).
fn crc16(bytes: &[u8]) -> u16 {
    const CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_XMODEM);
    CRC.checksum(bytes)
}

/// The record's format version.
pub const VERSION: u16 = 1;
const MAGIC: [u8; 4] = *b"HCAL";
const HEADER: usize = 4 + 2 + 1;
const ENTRY: usize = 4 + 4;

/// The saved parameters besides the machine's constants: every
/// `calibration.*` entry of the table but the height encoder's origin (a
/// zero, per boot), and the spring's rate and preload.
const CALIBRATION: [&Param; 13] = [
    &params::CAL_MOTOR_COUNTS_PER_REV,
    &params::CAL_MOTOR_POSITIVE_DOWN,
    &params::CAL_HEIGHT_COUNTS_PER_REV,
    &params::CAL_HEIGHT_POSITIVE_UP,
    &params::CAL_PULLEY_RADIUS,
    &params::CAL_LOADCELL_GAIN,
    &params::CAL_LOADCELL_OFFSET,
    &params::CAL_POT_GAIN,
    &params::CAL_POT_OFFSET,
    &params::CAL_DAC_ZERO,
    &params::CAL_DAC_AMPS,
    &params::SUP_SPRING_RATE,
    &params::SUP_SPRING_PRELOAD,
];

/// How many parameters are saved.
const SAVED_COUNT: usize = params::MACHINE.len() + CALIBRATION.len();

/// The saved parameters: the machine's constants ([`params::MACHINE`],
/// first, so an entry that follows the model and was set apart is applied
/// after it), then [`CALIBRATION`] (a test checks the list against the
/// table). A robot file holds exactly these.
#[allow(clippy::indexing_slicing)] // Evaluated at compile time: in bounds.
pub const SAVED: [&Param; SAVED_COUNT] = {
    let mut out = [CALIBRATION[0]; SAVED_COUNT];
    let mut i = 0;
    while i < params::MACHINE.len() {
        out[i] = params::MACHINE[i];
        i += 1;
    }
    let mut j = 0;
    while j < CALIBRATION.len() {
        out[i + j] = CALIBRATION[j];
        j += 1;
    }
    out
};

/// Their keys, computed at compile time ([`name_hash`]): a save in the
/// control task's link service costs no hashing and no table search.
#[allow(clippy::indexing_slicing)] // Evaluated at compile time: `i < SAVED_COUNT`.
const KEYS: [u32; SAVED_COUNT] = {
    let mut k = [0u32; SAVED_COUNT];
    let mut i = 0;
    while i < SAVED_COUNT {
        k[i] = name_hash(SAVED[i].name);
        i += 1;
    }
    k
};

/// How many parameters are saved.
pub const fn saved_count() -> usize {
    SAVED.len()
}

/// The largest record, bytes.
pub const MAX_RECORD: usize = HEADER + MAX_ENTRIES * ENTRY + 2;

/// The most entries a record holds: room for a few more than are saved
/// (a later firmware's record, read by this one, is refused by entry).
const MAX_ENTRIES: usize = 32;

/// The FNV-1a hash of a parameter's name: its key in the record.
#[allow(clippy::indexing_slicing)] // `i < b.len()`; a const fn has no iterators.
pub const fn name_hash(name: &str) -> u32 {
    let b = name.as_bytes();
    let mut h: u32 = 0x811c_9dc5;
    let mut i = 0;
    while i < b.len() {
        h = (h ^ b[i] as u32).wrapping_mul(0x0100_0193);
        i += 1;
    }
    h
}

/// Copies `bytes` into `out` at `at` (false when they do not fit).
fn put(out: &mut [u8], at: usize, bytes: &[u8]) -> bool {
    match out.get_mut(at..at + bytes.len()) {
        Some(d) => {
            d.copy_from_slice(bytes);
            true
        }
        None => false,
    }
}

/// Four bytes of `r` at `at`.
fn word(r: &[u8], at: usize) -> Option<[u8; 4]> {
    r.get(at..at + 4)?.try_into().ok()
}

/// Why a record was not loaded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[strum(serialize_all = "kebab-case")]
pub enum LoadError {
    /// Too short, or not a calibration record.
    NotARecord,
    /// Written by a firmware with another format version.
    #[strum(serialize = "other-version")]
    Version(u16),
    /// The CRC does not match: a torn or corrupted write.
    #[strum(serialize = "bad-crc")]
    Crc,
    /// An entry names no parameter of this firmware.
    UnknownEntry(u32),
    /// A value is refused by its parameter (named).
    #[strum(serialize = "value-refused")]
    Refused(&'static str),
}

impl LoadError {
    /// Its wire code (`StoredInfo::boot_error`).
    pub const fn code(self) -> u8 {
        match self {
            LoadError::NotARecord => 1,
            LoadError::Version(_) => 2,
            LoadError::Crc => 3,
            LoadError::UnknownEntry(_) => 4,
            LoadError::Refused(_) => 5,
        }
    }

    /// Kebab-case name, as the link prints it.
    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// What the firmware found in flash at boot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AtBoot {
    /// No flash store (a virtual robot without one).
    NoStore,
    /// The store holds no record: the defaults run.
    NothingSaved,
    /// A record was loaded: this many parameters set.
    Loaded(u8),
    /// A record was refused: the defaults run.
    Refused(LoadError),
}

impl AtBoot {
    /// `StoredInfo`'s `boot`, `boot_error` and `entries`.
    pub const fn wire(self) -> (u8, u8, u8) {
        match self {
            AtBoot::NoStore => (0, 0, 0),
            AtBoot::NothingSaved => (1, 0, 0),
            AtBoot::Loaded(n) => (2, 0, n),
            AtBoot::Refused(e) => (3, e.code(), 0),
        }
    }
}

/// A record of `cfg`'s saved parameters, in `out`; its length.
pub fn encode(cfg: &HopperConfig, out: &mut [u8; MAX_RECORD]) -> usize {
    put(out, 0, &MAGIC);
    put(out, 4, &VERSION.to_le_bytes());
    let mut n = 0u8;
    let mut at = HEADER;
    let mut c = *cfg;
    for (p, key) in SAVED.iter().zip(KEYS) {
        let Ok(v) = params::read(&mut c, p) else {
            continue;
        };
        // Room for the entry and the CRC (MAX_RECORD holds MAX_ENTRIES).
        if at + ENTRY + 2 > MAX_RECORD {
            break;
        }
        put(out, at, &key.to_le_bytes());
        put(out, at + 4, &v.to_le_bytes());
        at += ENTRY;
        n += 1;
    }
    put(out, 6, &[n]);
    let crc = crc16(out.get(..at).unwrap_or_default());
    put(out, at, &crc.to_le_bytes());
    at + 2
}

/// Whether `record` (already decoded) carries the tare's two offsets.
pub fn has_offsets(record: &[u8]) -> bool {
    let n = usize::from(record.get(6).copied().unwrap_or(0));
    let keys = record
        .get(HEADER..HEADER + n * ENTRY)
        .unwrap_or_default()
        .chunks_exact(ENTRY)
        .filter_map(|e| word(e, 0).map(u32::from_le_bytes));
    let (lc, pot) = (
        name_hash(params::CAL_LOADCELL_OFFSET.name),
        name_hash(params::CAL_POT_OFFSET.name),
    );
    let (mut has_lc, mut has_pot) = (false, false);
    for k in keys {
        has_lc |= k == lc;
        has_pot |= k == pot;
    }
    has_lc && has_pot
}

/// Checks `record` and applies its entries to a copy of `cfg`: the new
/// configuration, or why nothing is applied.
pub fn decode(record: &[u8], cfg: &HopperConfig) -> Result<HopperConfig, LoadError> {
    let (Some(magic), Some(&[v0, v1, n])) = (record.get(..4), record.get(4..HEADER)) else {
        return Err(LoadError::NotARecord);
    };
    if magic != MAGIC {
        return Err(LoadError::NotARecord);
    }
    let version = u16::from_le_bytes([v0, v1]);
    if version != VERSION {
        return Err(LoadError::Version(version));
    }
    let end = HEADER + usize::from(n) * ENTRY;
    let (Some(body), Some(&[c0, c1])) = (record.get(..end), record.get(end..end + 2)) else {
        return Err(LoadError::NotARecord);
    };
    if crc16(body) != u16::from_le_bytes([c0, c1]) {
        return Err(LoadError::Crc);
    }
    let mut new = *cfg;
    for e in body.get(HEADER..).unwrap_or_default().chunks_exact(ENTRY) {
        let (Some(h), Some(v)) = (word(e, 0), word(e, 4)) else {
            return Err(LoadError::NotARecord);
        };
        let hash = u32::from_le_bytes(h);
        let p = SAVED
            .iter()
            .zip(KEYS)
            .find_map(|(p, k)| (k == hash).then_some(*p))
            .ok_or(LoadError::UnknownEntry(hash))?;
        params::set(&mut new, p.name, f32::from_le_bytes(v))
            .map_err(|_| LoadError::Refused(p.name))?;
    }
    // Each value in its range is not yet a configuration the controller
    // takes (a DAC zero beyond a changed resolution, say): the whole of it
    // is checked as a boot would build it.
    crate::hopper::Hopper::new(new).map_err(|_| LoadError::Refused("configuration"))?;
    Ok(new)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn tuned() -> HopperConfig {
        let mut c = HopperConfig::default();
        params::set(&mut c, "calibration.loadcell_offset_code", 224.06).unwrap_or(());
        params::set(&mut c, "supervisor.spring_rate_n_per_m", 12_635.0).unwrap_or(());
        // Another machine: heavier, a stiffer spring the bench measured
        // apart from the model's, a longer screw lead.
        params::set(&mut c, "model.body_mass_kg", 12.0).unwrap_or(());
        params::set(&mut c, "model.spring_stiffness_n_per_m", 15_000.0).unwrap_or(());
        params::set(&mut c, "model.screw_lead_m", 0.01).unwrap_or(());
        c
    }

    #[test]
    fn a_record_round_trips_and_names_its_entries() {
        let mut buf = [0u8; MAX_RECORD];
        let n = encode(&tuned(), &mut buf);
        assert_eq!(n, HEADER + saved_count() * ENTRY + 2);
        assert!(saved_count() >= 27, "{}", saved_count());
        let back = decode(&buf[..n], &HopperConfig::default());
        assert_eq!(back, Ok(tuned()));
        let back = back.unwrap_or_default();
        assert_eq!(back.model.body_mass_kg, 12.0);
        assert_eq!(
            back.calibration.lead_m_per_rev, 0.01,
            "the lead follows the model"
        );
        assert_eq!(
            back.supervisor.spring_rate_n_per_m, 12_635.0,
            "set apart, kept"
        );
        assert!(has_offsets(&buf[..n]));
        // A record without entries decodes (nothing to set) but is no tare.
        let mut empty = [0u8; MAX_RECORD];
        empty[..HEADER].copy_from_slice(&buf[..HEADER]);
        empty[6] = 0;
        let crc = crc16(&empty[..HEADER]).to_le_bytes();
        empty[HEADER..HEADER + 2].copy_from_slice(&crc);
        assert_eq!(
            decode(&empty[..HEADER + 2], &HopperConfig::default()),
            Ok(HopperConfig::default())
        );
        assert!(!has_offsets(&empty[..HEADER + 2]));
        // The names hash apart.
        for (i, h) in KEYS.iter().enumerate() {
            assert!(!KEYS[i + 1..].contains(h));
            assert_eq!(*h, name_hash(SAVED[i].name));
        }
        // The list is the table's calibration entries (but the height
        // encoder's origin: a zero, per boot) and the spring's two.
        let from_table = params::TABLE.iter().filter(|p| {
            p.name.starts_with("model.")
                || (p.name.starts_with("calibration.")
                    && p.name != params::CAL_HEIGHT_AT_ORIGIN_M.name)
                || p.name == params::SUP_SPRING_RATE.name
                || p.name == params::SUP_SPRING_PRELOAD.name
        });
        let mut n = 0;
        for p in from_table {
            assert!(
                SAVED.iter().any(|s| s.name == p.name),
                "{} not saved",
                p.name
            );
            n += 1;
        }
        assert_eq!(n, SAVED.len());
    }

    #[test]
    fn a_bad_record_changes_nothing() {
        let mut buf = [0u8; MAX_RECORD];
        let n = encode(&tuned(), &mut buf);
        let d = HopperConfig::default();
        assert_eq!(decode(&buf[..3], &d), Err(LoadError::NotARecord));
        assert_eq!(decode(&[0xff; MAX_RECORD], &d), Err(LoadError::NotARecord));
        let mut v = buf;
        v[4] = 9;
        assert_eq!(decode(&v[..n], &d), Err(LoadError::Version(9)));
        let mut c = buf;
        c[HEADER + 5] ^= 1;
        assert_eq!(decode(&c[..n], &d), Err(LoadError::Crc));
        // A value out of its range, with a valid CRC: refused by name.
        let mut r = buf;
        let at = HEADER;
        let bad = f32::NAN.to_le_bytes();
        r[at + 4..at + 8].copy_from_slice(&bad);
        let crc = crc16(&r[..n - 2]).to_le_bytes();
        r[n - 2..n].copy_from_slice(&crc);
        assert!(matches!(decode(&r[..n], &d), Err(LoadError::Refused(_))));
    }

    proptest! {
        /// Any bytes: an error or a valid configuration, never a panic.
        #[test]
        fn decode_takes_any_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let d = HopperConfig::default();
            if let Ok(c) = decode(&bytes, &d) {
                prop_assert!(crate::hopper::Hopper::new(c).is_ok());
            }
        }
    }
}
