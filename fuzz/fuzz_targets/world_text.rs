//! The simulator's world text parser on arbitrary text.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        // Keep worlds small enough that a fuzzer's memory limit is not the finding.
        if text.len() <= 4096 {
            let _ = sitl::World::parse_text("fuzz", text);
        }
    }
});
