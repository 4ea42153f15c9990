//! A `map_server` map: YAML text, a NUL byte, then the image file's bytes (PGM or PNG). Loading
//! never panics; bad files are errors.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let (yaml, image) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[][..]),
    };
    let Ok(yaml) = std::str::from_utf8(yaml) else {
        return;
    };
    let _ = nav::grid::Grid::from_map_server(Path::new("fuzz/map.yaml"), yaml, |_| {
        Ok(image.to_vec())
    });
});
