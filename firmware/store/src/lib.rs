//! The saved calibration in flash: one record
//! (`hopper_control::persist`, versioned and CRC-checked) under one key of
//! a [`sequential_storage`] map, over any [`NorFlash`]. The map appends a
//! new copy on each save and erases a page only when its range is full, so
//! a save costs one write, not an erase, most of the time, and a torn
//! write leaves the previous copy readable.
//!
//! The flashes here never wait, so the async calls complete on their first
//! poll: [`block_on`] runs them where no executor is (the board's `init`,
//! the simulator's loop). [`RamFlash`] is a flash in RAM that refuses what
//! a NOR flash refuses (writing a bit from 0 to 1 without an erase,
//! misaligned access): the host tests' flash and the simulator's.

#![no_std]
#![warn(missing_docs)]

use core::ops::Range;
pub use embassy_futures::block_on;
pub use embedded_storage_async::nor_flash::NorFlash;
use embedded_storage_async::nor_flash::{
    ErrorType, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use sequential_storage::cache::Cache;
use sequential_storage::map::{MapConfig, MapStorage};

/// The record's key in the map.
const KEY: u8 = 1;

/// Room for the record with the map's item header, rounded to words.
pub const BUFFER: usize = 256;

/// Why a save or a load failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreError {
    /// The flash range is not whole erase pages, or fewer than two.
    Range,
    /// The flash reported an error, or the map's structure is corrupt
    /// beyond repair.
    Flash,
    /// The record does not fit the buffer.
    TooLong,
}

impl StoreError {
    /// Kebab-case name, as the link prints it.
    pub const fn name(self) -> &'static str {
        match self {
            StoreError::Range => "bad-flash-range",
            StoreError::Flash => "flash-error",
            StoreError::TooLong => "record-too-long",
        }
    }
}

/// The calibration store on `S`.
pub struct Store<S: NorFlash> {
    map: MapStorage<
        u8,
        S,
        Cache<
            sequential_storage::cache::Uncached,
            sequential_storage::cache::Uncached,
            sequential_storage::cache::Uncached,
            u8,
        >,
    >,
    buf: [u8; BUFFER],
}

impl<S: NorFlash> Store<S> {
    /// A store in `range` of `flash` (whole erase pages, at least two).
    pub fn new(flash: S, range: Range<u32>) -> Result<Self, StoreError> {
        let config = MapConfig::try_new(range).map_err(|_| StoreError::Range)?;
        Ok(Self {
            map: MapStorage::new(flash, config, Cache::new_uncached()),
            buf: [0; BUFFER],
        })
    }

    /// Saves `record` (replacing the last one).
    pub async fn save(&mut self, record: &[u8]) -> Result<(), StoreError> {
        if record.len() + 16 > BUFFER {
            return Err(StoreError::TooLong);
        }
        self.map
            .store_item(&mut self.buf, &KEY, &record)
            .await
            .map_err(|_| StoreError::Flash)
    }

    /// The last saved record copied into `out`: its length, `None` if none
    /// was ever saved.
    pub async fn load(&mut self, out: &mut [u8]) -> Result<Option<usize>, StoreError> {
        let got: Option<&[u8]> = self
            .map
            .fetch_item(&mut self.buf, &KEY)
            .await
            .map_err(|_| StoreError::Flash)?;
        match got {
            None => Ok(None),
            Some(r) => {
                let dst = out.get_mut(..r.len()).ok_or(StoreError::TooLong)?;
                dst.copy_from_slice(r);
                Ok(Some(r.len()))
            }
        }
    }

    /// The flash back.
    pub fn into_flash(self) -> S {
        self.map.destroy().0
    }
}

/// A NOR flash in RAM: `PAGES` erase pages of `PAGE` bytes, erased to
/// 0xFF, written in 4-byte words, a written bit cleared only by an erase.
pub struct RamFlash<const PAGES: usize, const PAGE: usize> {
    pages: [[u8; PAGE]; PAGES],
    /// Writes and erases so far (the tests' wear and torn-write checks).
    pub writes: u32,
    /// Erases so far.
    pub erases: u32,
    /// Fail every operation after this many writes (a power cut).
    pub fail_after_writes: Option<u32>,
}

/// What [`RamFlash`] refuses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RamFlashError {
    /// Not word-aligned, or outside the flash.
    Bounds,
    /// A write that would set an already cleared bit.
    NotErased,
    /// The simulated power cut.
    PowerCut,
}

impl NorFlashError for RamFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            RamFlashError::Bounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

impl<const PAGES: usize, const PAGE: usize> Default for RamFlash<PAGES, PAGE> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const PAGES: usize, const PAGE: usize> RamFlash<PAGES, PAGE> {
    /// Erased.
    pub const fn new() -> Self {
        Self {
            pages: [[0xff; PAGE]; PAGES],
            writes: 0,
            erases: 0,
            fail_after_writes: None,
        }
    }

    /// Its contents, page by page (to keep them in a file).
    pub fn pages(&self) -> &[[u8; PAGE]; PAGES] {
        &self.pages
    }

    /// Its contents set from `bytes` (as [`Self::pages`] gave them; a short
    /// slice leaves the rest erased).
    pub fn load_bytes(&mut self, bytes: &[u8]) {
        for (i, b) in bytes.iter().take(PAGES * PAGE).enumerate() {
            self.pages[i / PAGE][i % PAGE] = *b;
        }
    }

    fn span(offset: u32, len: usize) -> Result<Range<usize>, RamFlashError> {
        let start = offset as usize;
        let end = start.checked_add(len).ok_or(RamFlashError::Bounds)?;
        if end > PAGES * PAGE {
            return Err(RamFlashError::Bounds);
        }
        Ok(start..end)
    }
}

impl<const PAGES: usize, const PAGE: usize> ErrorType for RamFlash<PAGES, PAGE> {
    type Error = RamFlashError;
}

impl<const PAGES: usize, const PAGE: usize> ReadNorFlash for RamFlash<PAGES, PAGE> {
    const READ_SIZE: usize = 4;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        if !offset.is_multiple_of(4) || !bytes.len().is_multiple_of(4) {
            return Err(RamFlashError::Bounds);
        }
        for (k, i) in Self::span(offset, bytes.len())?.enumerate() {
            bytes[k] = self.pages[i / PAGE][i % PAGE];
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        PAGES * PAGE
    }
}

impl<const PAGES: usize, const PAGE: usize> NorFlash for RamFlash<PAGES, PAGE> {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if !(from as usize).is_multiple_of(PAGE) || !(to as usize).is_multiple_of(PAGE) || to < from
        {
            return Err(RamFlashError::Bounds);
        }
        let r = Self::span(from, (to - from) as usize)?;
        for p in r.start / PAGE..r.end / PAGE {
            self.pages[p] = [0xff; PAGE];
            self.erases += 1;
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        if !offset.is_multiple_of(4) || !bytes.len().is_multiple_of(4) {
            return Err(RamFlashError::Bounds);
        }
        if self.fail_after_writes.is_some_and(|n| self.writes >= n) {
            return Err(RamFlashError::PowerCut);
        }
        let r = Self::span(offset, bytes.len())?;
        for (k, i) in r.clone().enumerate() {
            let old = self.pages[i / PAGE][i % PAGE];
            if bytes[k] & !old != 0 {
                return Err(RamFlashError::NotErased);
            }
        }
        for (k, i) in r.enumerate() {
            self.pages[i / PAGE][i % PAGE] &= bytes[k];
        }
        self.writes += 1;
        Ok(())
    }
}
