//! A `gcs fly` fleet file: parsing and checking never panic; bad files are errors.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = gcs::fleet_file::parse(text, "fuzz.toml");
    }
});
