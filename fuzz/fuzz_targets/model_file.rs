//! Any bytes as a whole model file: the loader must return a model or a ModelFileError, never
//! panic, hang or allocate past the budget (libFuzzer's -rss_limit_mb catches the last).
#![no_main]
use libfuzzer_sys::fuzz_target;
use palpate_core::hybrid::file::from_bytes;

fuzz_target!(|data: &[u8]| {
    let _ = from_bytes(data, "fuzz.palpate");
});
