//! A .tlog file: the reader never panics and always ends.
#![no_main]

use libfuzzer_sys::fuzz_target;
use link::tlog::TlogReader;

fuzz_target!(|data: &[u8]| {
    for rec in TlogReader::new(data) {
        if let Ok(rec) = rec {
            let _ = rec.frame.decode();
        }
    }
});
