//! Arbitrary bytes into the link protocol's decoder: the logic is
//! `hopper_fuzz::link::run` (also run on stable by `cargo test
//! --manifest-path fuzz/Cargo.toml`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = hopper_fuzz::link::run(data);
});
