//! A mission log (MCAP) as `gcs replay` reads it: never panics, ends at the first unreadable
//! message.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = gcs::mission_log::read(data, "fuzz.mcap");
});
