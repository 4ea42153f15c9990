//! A g2o pose-graph file (2D or 3D): parsing never panics; bad lines are errors.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = slam::posegraph::parse_g2o(text, Path::new("fuzz.g2o"));
    }
});
