//! The `persist` fuzz target's logic (`fuzz_targets/persist.rs`): bytes
//! into the saved-calibration decoder (`hopper_control::persist::decode`),
//! as a flash could hold them after any corruption. Half of each input is
//! taken as is; the other half patches a valid record and fixes its CRC,
//! so the fuzzer reaches the entries' checks and not only the CRC's. Never
//! a panic; a record that loads gives a configuration the controller takes
//! and saves again to a record that loads to the same configuration.

use hopper_control::hopper::{Hopper, HopperConfig};
use hopper_control::persist::{decode, encode, MAX_RECORD};

/// Decodes `data` raw and as patches to a valid record; how many loaded.
pub fn run(data: &[u8]) -> usize {
    let base = HopperConfig::default();
    let mut loaded = 0;
    if check(data, &base) {
        loaded += 1;
    }
    let mut record = [0u8; MAX_RECORD];
    let n = encode(&base, &mut record);
    // Patches: (offset, value) byte pairs.
    for p in data.chunks_exact(2) {
        let at = usize::from(p[0]) % n.saturating_sub(2).max(1);
        record[at] = p[1];
    }
    let crc = hopper_protocol::crc16(&record[..n - 2]).to_le_bytes();
    record[n - 2..n].copy_from_slice(&crc);
    if check(&record[..n], &base) {
        loaded += 1;
    }
    loaded
}

fn check(bytes: &[u8], base: &HopperConfig) -> bool {
    let Ok(cfg) = decode(bytes, base) else {
        return false;
    };
    assert!(
        Hopper::new(cfg).is_ok(),
        "a loaded record must build a controller"
    );
    let mut again = [0u8; MAX_RECORD];
    let n = encode(&cfg, &mut again);
    assert_eq!(decode(&again[..n], base), Ok(cfg));
    true
}

#[cfg(test)]
mod tests {
    /// Random bytes and random patches of a valid record.
    #[test]
    fn random_bytes_and_patched_records() {
        let mut x: u64 = 0x5A7E_0018;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let mut loaded = 0;
        for i in 0..20_000 {
            let len = (next() % 160) as usize;
            let mut data: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            if i % 2 == 0 {
                // Few patches: many still load.
                data.truncate(4);
            }
            loaded += super::run(&data);
        }
        assert!(loaded > 500, "{loaded}");
    }
}
