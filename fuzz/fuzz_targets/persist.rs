//! Arbitrary bytes as a saved calibration record: the logic is
//! `hopper_fuzz::persist::run` (also run on stable by `cargo test
//! --manifest-path fuzz/Cargo.toml`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = hopper_fuzz::persist::run(data);
});
