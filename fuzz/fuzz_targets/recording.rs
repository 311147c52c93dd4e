//! The input as a haptic recording file's bytes (`Recording::from_bytes`, what `Recording::load`
//! reads after its size check): refused with a reason or loaded, never a panic or an allocation
//! the file's size does not account for; what loads saves to the same bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;
use palpate_haptics::record::Recording;

fuzz_target!(|data: &[u8]| {
    if let Ok(r) = Recording::from_bytes(data, "fuzz") {
        // Every field is read from where the format puts it: saving gives the file back, but for
        // the padding (written as zeros) and a version-1 file (saved as version 2).
        let again = Recording::from_bytes(&r.to_bytes(), "again").expect("a saved recording loads");
        assert_eq!(again.ticks.len(), r.ticks.len());
        assert_eq!(again.model_ticks, r.model_ticks);
        assert_eq!(again.identity, r.identity);
    }
});
