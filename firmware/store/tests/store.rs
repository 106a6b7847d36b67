//! The saved calibration on a mock flash: round trips, many saves, a power
//! cut in the middle of a write, and what the firmware makes of the bytes.

use hopper_control::hopper::HopperConfig;
use hopper_control::persist::{self, MAX_RECORD};
use hopper_store::{block_on, RamFlash, Store, StoreError};

type Flash = RamFlash<2, 1024>;

fn record(offset_code: f32) -> ([u8; MAX_RECORD], usize) {
    let mut cfg = HopperConfig::default();
    hopper_control::params::set(&mut cfg, "calibration.loadcell_offset_code", offset_code)
        .unwrap_or_else(|e| panic!("{e:?}"));
    let mut out = [0u8; MAX_RECORD];
    let n = persist::encode(&cfg, &mut out);
    (out, n)
}

fn load(store: &mut Store<Flash>) -> Option<Vec<u8>> {
    let mut out = [0u8; MAX_RECORD];
    block_on(store.load(&mut out))
        .unwrap_or_else(|e| panic!("{e:?}"))
        .map(|n| out[..n].to_vec())
}

#[test]
fn nothing_saved_loads_nothing_and_a_save_loads_back() {
    let mut s = Store::new(Flash::new(), 0..2048).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(load(&mut s), None);
    let (r, n) = record(224.06);
    block_on(s.save(&r[..n])).unwrap_or_else(|e| panic!("{e:?}"));
    let got = load(&mut s).unwrap_or_default();
    assert_eq!(got, r[..n]);
    let cfg = persist::decode(&got, &HopperConfig::default()).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(cfg.calibration.loadcell_offset_code, 224.06);
}

/// A hundred saves on two 1 KiB pages: the last one is what loads, the
/// pages are erased only as they fill (the record is 225 bytes: three to a
/// page with the map's own bytes, so about 33 erases).
#[test]
fn the_last_of_many_saves_loads_and_erases_are_rare() {
    let mut s = Store::new(Flash::new(), 0..2048).unwrap_or_else(|e| panic!("{e:?}"));
    let mut size = 0;
    for i in 0..100 {
        let (r, n) = record(200.0 + i as f32);
        size = n;
        block_on(s.save(&r[..n])).unwrap_or_else(|e| panic!("save {i}: {e:?}"));
        assert_eq!(load(&mut s).unwrap_or_default(), r[..n]);
    }
    let flash = s.into_flash();
    // A record and the map's header for it, at most 32 bytes.
    let per_page = u32::try_from(1024 / (size + 32)).unwrap_or(1);
    assert!(
        flash.erases <= 100 / per_page + 2,
        "{} erases for {per_page} records a page",
        flash.erases
    );
}

/// Power lost in the middle of a save: the flash still gives a good
/// record, the old or the new one, never a torn one.
#[test]
fn a_power_cut_leaves_the_old_or_the_new_record() {
    for cut in 0..12 {
        let mut s = Store::new(Flash::new(), 0..2048).unwrap_or_else(|e| panic!("{e:?}"));
        let (old, n) = record(210.0);
        block_on(s.save(&old[..n])).unwrap_or_else(|e| panic!("{e:?}"));
        let mut flash = s.into_flash();
        flash.fail_after_writes = Some(flash.writes + cut);
        let mut s = Store::new(flash, 0..2048).unwrap_or_else(|e| panic!("{e:?}"));
        let (new, _) = record(220.0);
        let _ = block_on(s.save(&new[..n]));
        // The power comes back.
        let mut flash = s.into_flash();
        flash.fail_after_writes = None;
        let mut s = Store::new(flash, 0..2048).unwrap_or_else(|e| panic!("{e:?}"));
        let got = load(&mut s).unwrap_or_default();
        assert!(
            got == old[..n] || got == new[..n],
            "cut after {cut} writes: {got:?}"
        );
    }
}

#[test]
fn a_bad_range_and_an_oversized_record_are_refused() {
    assert_eq!(
        Store::new(Flash::new(), 0..1024).err(),
        Some(StoreError::Range)
    );
    assert_eq!(
        Store::new(Flash::new(), 100..2048).err(),
        Some(StoreError::Range)
    );
    let mut s = Store::new(Flash::new(), 0..2048).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(block_on(s.save(&[0u8; 300])), Err(StoreError::TooLong));
}
