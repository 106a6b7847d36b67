//! The board's saved calibration: flash sectors 10 and 11
//! (0x080C_0000..0x0810_0000, 128 KiB each, kept out of the image by
//! `memory.x`) under [`hopper_store::Store`], written only in `init`.
//!
//! Why in `init`: the F405 has one flash bank, and erasing a 128 KiB sector
//! stalls every instruction fetch from flash for 1 to 2 s (RM0090, DS8626
//! t_ERASE128KB at x32), longer than the 5 ms watchdog, and no control
//! period may wait anyway. So a `hopper-link save` (accepted only while
//! disarmed) puts the record in a RAM slot that survives a reset
//! ([`queue_save`]), and the control task resets the MCU; the next `init`
//! writes the slot to flash before it starts the watchdog, with the
//! amplifier off since the first instruction ([`at_boot`]), then loads it.
//! The slot carries a magic word and the record's own CRC, so the random
//! RAM of a power-on is never taken for a save.
//!
//! Programming follows RM0090 section 3.6: unlock (KEYR), x32 parallelism
//! (PSIZE = 2, for a 2.7-3.6 V supply), sector erase (SER, SNB, STRT), word
//! programming (PG), BSY polled with a bound, the error flags checked and
//! cleared, the data cache reset after, then lock again. Not tested on
//! hardware yet: QEMU models no flash writes (docs/board.md).

use core::mem::MaybeUninit;
use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use hopper_control::persist::MAX_RECORD;
use stm32f4::stm32f405 as pac;

/// Where the store starts: sector 10.
pub const STORE_START: u32 = 0x080C_0000;
/// Two sectors of 128 KiB.
const SECTOR_BYTES: usize = 128 * 1024;
const FIRST_SECTOR: u32 = 10;
const SECTORS: u32 = 2;
/// The store's range, as offsets from [`STORE_START`].
pub const STORE_RANGE: core::ops::Range<u32> = 0..SECTORS * SECTOR_BYTES as u32;

const KEY1: u32 = 0x4567_0123;
const KEY2: u32 = 0xCDEF_89AB;
const CR_PG: u32 = 1 << 0;
const CR_SER: u32 = 1 << 1;
const CR_PSIZE_X32: u32 = 0b10 << 8;
const CR_STRT: u32 = 1 << 16;
const CR_LOCK: u32 = 1 << 31;
const SR_BSY: u32 = 1 << 16;
/// OPERR, WRPERR, PGAERR, PGPERR, PGSERR.
const SR_ERRORS: u32 = (1 << 1) | (1 << 4) | (1 << 5) | (1 << 6) | (1 << 7);
const ACR_DCEN: u32 = 1 << 10;
const ACR_DCRST: u32 = 1 << 12;
/// BSY polls before giving up: over 10 s at 168 MHz, beyond the 2 s
/// worst-case sector erase.
const BUSY_POLLS: u32 = 200_000_000;

/// What the flash controller reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum FlashError {
    /// Outside the store or misaligned.
    Bounds,
    /// Still busy after the bound.
    Timeout,
    /// An error flag (FLASH_SR's bits).
    Status(u32),
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::Bounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// Sectors 10 and 11 of the internal flash.
pub struct InternalFlash<'a> {
    flash: &'a pac::FLASH,
}

impl<'a> InternalFlash<'a> {
    /// The store's sectors, through the flash interface registers.
    pub fn new(flash: &'a pac::FLASH) -> Self {
        Self { flash }
    }

    #[allow(unsafe_code)] // KEYR and CR take raw words.
    fn unlock(&self) {
        if self.flash.cr().read().bits() & CR_LOCK != 0 {
            self.flash.keyr().write(|w| unsafe { w.bits(KEY1) });
            self.flash.keyr().write(|w| unsafe { w.bits(KEY2) });
        }
    }

    #[allow(unsafe_code)] // CR takes raw words.
    fn lock(&self) {
        self.flash.cr().write(|w| unsafe { w.bits(CR_LOCK) });
        // The data cache may hold what was there before the erase: reset it,
        // which RM0090 allows only with the cache off (off, reset, reset
        // released, back on).
        let acr = self.flash.acr().read().bits();
        let off = acr & !ACR_DCEN;
        self.flash.acr().write(|w| unsafe { w.bits(off) });
        self.flash
            .acr()
            .write(|w| unsafe { w.bits(off | ACR_DCRST) });
        self.flash.acr().write(|w| unsafe { w.bits(off) });
        self.flash.acr().write(|w| unsafe { w.bits(acr) });
    }

    #[allow(unsafe_code)] // SR's flags are cleared by writing ones.
    fn wait(&self) -> Result<(), FlashError> {
        let mut polls = 0u32;
        while self.flash.sr().read().bits() & SR_BSY != 0 {
            polls += 1;
            if polls > BUSY_POLLS {
                return Err(FlashError::Timeout);
            }
        }
        let sr = self.flash.sr().read().bits();
        if sr & SR_ERRORS != 0 {
            self.flash.sr().write(|w| unsafe { w.bits(sr & SR_ERRORS) });
            return Err(FlashError::Status(sr & SR_ERRORS));
        }
        Ok(())
    }

    fn address(offset: u32, len: usize) -> Result<u32, FlashError> {
        let end = (offset as usize)
            .checked_add(len)
            .ok_or(FlashError::Bounds)?;
        if end > SECTORS as usize * SECTOR_BYTES {
            return Err(FlashError::Bounds);
        }
        Ok(STORE_START + offset)
    }

    #[allow(unsafe_code)] // CR takes raw words.
    fn erase_sector(&self, sector: u32) -> Result<(), FlashError> {
        self.wait()?;
        self.flash
            .cr()
            .write(|w| unsafe { w.bits(CR_PSIZE_X32 | CR_SER | (sector << 3)) });
        self.flash
            .cr()
            .write(|w| unsafe { w.bits(CR_PSIZE_X32 | CR_SER | (sector << 3) | CR_STRT) });
        self.wait()
    }

    #[allow(unsafe_code)] // CR takes raw words; the word goes to its flash address.
    fn program(&self, address: u32, bytes: &[u8]) -> Result<(), FlashError> {
        self.wait()?;
        self.flash
            .cr()
            .write(|w| unsafe { w.bits(CR_PSIZE_X32 | CR_PG) });
        for (i, c) in bytes.chunks_exact(4).enumerate() {
            let word = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
            // SAFETY: `address` is within the store's sectors (checked),
            // word-aligned (WRITE_SIZE), and the controller is in PG mode.
            unsafe {
                core::ptr::write_volatile((address + 4 * i as u32) as *mut u32, word);
            }
            self.wait()?;
        }
        Ok(())
    }
}

impl ErrorType for InternalFlash<'_> {
    type Error = FlashError;
}

impl ReadNorFlash for InternalFlash<'_> {
    const READ_SIZE: usize = 1;

    #[allow(unsafe_code)] // The store's sectors are read as memory.
    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let a = Self::address(offset, bytes.len())?;
        for (i, b) in bytes.iter_mut().enumerate() {
            // SAFETY: within the store's sectors (checked above), which the
            // image never occupies (memory.x).
            *b = unsafe { core::ptr::read_volatile((a + i as u32) as *const u8) };
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        SECTORS as usize * SECTOR_BYTES
    }
}

impl NorFlash for InternalFlash<'_> {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = SECTOR_BYTES;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if !(from as usize).is_multiple_of(SECTOR_BYTES)
            || !(to as usize).is_multiple_of(SECTOR_BYTES)
            || to < from
        {
            return Err(FlashError::Bounds);
        }
        Self::address(from, (to - from) as usize)?;
        self.unlock();
        let mut r = Ok(());
        for s in from / SECTOR_BYTES as u32..to / SECTOR_BYTES as u32 {
            r = r.and_then(|()| self.erase_sector(FIRST_SECTOR + s));
        }
        self.lock();
        r
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        if !offset.is_multiple_of(4) || !bytes.len().is_multiple_of(4) {
            return Err(FlashError::Bounds);
        }
        let a = Self::address(offset, bytes.len())?;
        self.unlock();
        let r = self.program(a, bytes);
        self.lock();
        r
    }
}

/// The RAM slot a save waits in across the reset.
#[repr(C)]
struct Slot {
    magic: u32,
    len: u32,
    crc: u32,
    record: [u8; MAX_RECORD],
}

const PENDING: u32 = 0x5341_5645; // "SAVE"

/// Not initialised by the runtime: it keeps its contents across a reset.
#[allow(unsafe_code)] // `.uninit` (cortex-m-rt's no-load section) is the point.
#[link_section = ".uninit.HOPPER_SAVE"]
static mut SLOT: MaybeUninit<Slot> = MaybeUninit::uninit();

fn slot_crc(record: &[u8]) -> u32 {
    0x5a5a_0000 | u32::from(hopper_protocol::crc16(record))
}

/// Puts `record` in the RAM slot for the next `init` to write (the control
/// task, disarmed, then resets the MCU).
#[allow(unsafe_code)] // The slot is a `static mut` in `.uninit`.
pub fn queue_save(record: &[u8]) {
    let n = record.len().min(MAX_RECORD);
    let mut bytes = [0u8; MAX_RECORD];
    bytes[..n].copy_from_slice(&record[..n]);
    // SAFETY: only the link task (one priority; the control task resets
    // the MCU after it) and `init` (before any task runs) touch the slot;
    // written through a raw pointer, never referenced.
    unsafe {
        let s = core::ptr::addr_of_mut!(SLOT).cast::<Slot>();
        core::ptr::write_volatile(
            s,
            Slot {
                magic: PENDING,
                len: n as u32,
                crc: slot_crc(&bytes[..n]),
                record: bytes,
            },
        );
    }
}

/// What `init` found and did.
pub struct AtBoot {
    /// The record read from the store and its length (`None`: none saved).
    pub record: [u8; MAX_RECORD],
    /// Its length, if one was read.
    pub len: Option<usize>,
    /// A save was pending and written and read back (`Some(true)`) or
    /// failed to be.
    pub saved: Option<bool>,
    /// Why a pending save was refused, if it was ([`save_refusal`]).
    pub refused: Option<&'static str>,
    /// The store's error, if reading it failed.
    pub error: Option<hopper_store::StoreError>,
}

impl AtBoot {
    /// The record, if one was read.
    pub fn record(&self) -> Option<&[u8]> {
        self.record.get(..self.len?)
    }
}

/// FLASH_OPTCR's WDG_SW (bit 5): 0 is the hardware watchdog option, the
/// IWDG running from reset (RM0090, option bytes).
const OPTCR_WDG_SW: u32 = 1 << 5;

/// Start the programmable voltage detector at level 6 (2.8 V rising,
/// 2.7 V falling, DS8626), once, at boot, and leave it on: PVDO reads 1
/// while VDD is below it ([`save_refusal`], [`save_refusal_now`]).
fn pvd_start(pwr: &pac::PWR) {
    pwr.cr().modify(|_, w| w.pls().set(6).pvde().set_bit());
}

/// Whether the PVD reads the supply below 2.8 V.
fn supply_low(pwr: &pac::pwr::RegisterBlock) -> bool {
    pwr.csr().read().pvdo().bit_is_set()
}

/// Why a pending save is not written, if it must not be: the hardware
/// watchdog option (its reset, 0.5 s after boot at its reset prescaler,
/// would cut the 1-2 s sector erase, and every later boot would try it
/// again), or a supply below the erase's minimum for x32 parallelism
/// (2.7 V, RM0090 Table 13), read through the PVD ([`pvd_start`]).
fn save_refusal(flash: &pac::FLASH, pwr: &pac::PWR) -> Option<&'static str> {
    if flash.optcr().read().bits() & OPTCR_WDG_SW == 0 {
        return Some("the hardware watchdog option (WDG_SW = 0) is set: its reset would cut the sector erase");
    }
    // The PVD, just started, settles within 100 us (DS8626 t_PVD): about
    // 17,000 cycles at 168 MHz, 1,600 on the HSI; wait 20,000 nops.
    for _ in 0..20_000 {
        cortex_m::asm::nop();
    }
    supply_low(pwr)
        .then_some("the supply is below 2.8 V (the PVD): a sector erase at x32 needs 2.7-3.6 V")
}

/// Why a save asked for now could not be written after the restart, read
/// without waiting (the link task, before it answers a `save`): the
/// hardware watchdog option, or the supply below the PVD's 2.8 V (the PVD
/// runs from `at_boot` on); `at_boot` checks both again before it erases.
#[allow(unsafe_code)] // Reads of FLASH_OPTCR and PWR_CSR, owned by no task.
pub fn save_refusal_now() -> Option<hopper_robot_link::Refusal> {
    // SAFETY: the registers' fixed addresses, read only.
    let (flash, pwr) = unsafe { (&*pac::FLASH::ptr(), &*pac::PWR::ptr()) };
    if flash.optcr().read().bits() & OPTCR_WDG_SW == 0 {
        return Some(hopper_robot_link::Refusal::HardwareWatchdogOption);
    }
    supply_low(pwr).then_some(hopper_robot_link::Refusal::SupplyLow)
}

/// In `init`, before the watchdog starts: writes a pending save, then
/// reads the saved record. The slot is marked taken only once the record
/// reads back from flash as written (a reset in the middle of the erase
/// tries again at the next boot), or when the save is refused
/// ([`save_refusal`]: it is dropped, and `init` says why).
#[allow(unsafe_code)] // The slot is a `static mut` in `.uninit`.
pub fn at_boot(flash: &pac::FLASH, pwr: &pac::PWR) -> AtBoot {
    pvd_start(pwr);
    // SAFETY: `init` runs before every task: nothing else touches the slot;
    // read as words through a raw pointer (its bytes may be a power-on's
    // random RAM: every value is checked before use).
    let slot = core::ptr::addr_of_mut!(SLOT).cast::<Slot>();
    let pending = unsafe {
        let magic = core::ptr::read_volatile(core::ptr::addr_of!((*slot).magic));
        let len = core::ptr::read_volatile(core::ptr::addr_of!((*slot).len)) as usize;
        let crc = core::ptr::read_volatile(core::ptr::addr_of!((*slot).crc));
        let record = core::ptr::read_volatile(core::ptr::addr_of!((*slot).record));
        (magic == PENDING && len <= MAX_RECORD && crc == slot_crc(&record[..len]))
            .then_some((record, len))
    };
    // SAFETY: as above.
    let take = || unsafe { core::ptr::write_volatile(core::ptr::addr_of_mut!((*slot).magic), 0) };
    let mut out = AtBoot {
        record: [0; MAX_RECORD],
        len: None,
        saved: None,
        refused: None,
        error: None,
    };
    let mut store = match hopper_store::Store::new(InternalFlash::new(flash), STORE_RANGE) {
        Ok(s) => s,
        Err(e) => {
            out.error = Some(e);
            return out;
        }
    };
    if let Some((record, len)) = pending {
        if let Some(why) = save_refusal(flash, pwr) {
            out.saved = Some(false);
            out.refused = Some(why);
        } else {
            let written = hopper_store::block_on(store.save(&record[..len])).is_ok();
            let mut back = [0u8; MAX_RECORD];
            let verified = written
                && matches!(hopper_store::block_on(store.load(&mut back)), Ok(Some(n)) if back[..n] == record[..len]);
            out.saved = Some(verified);
        }
        // Taken only now, after the write and its read-back (a reset
        // during the erase leaves it pending); a refused or failed save is
        // not retried (it would fail the same way at every boot).
        take();
    }
    match hopper_store::block_on(store.load(&mut out.record)) {
        Ok(len) => out.len = len,
        Err(e) => out.error = Some(e),
    }
    out
}
