//! Shield → station bytes: the frame decoder never panics, whatever the chunking.
#![no_main]

use libfuzzer_sys::fuzz_target;
use link::shield::wire::FrameDecoder;

fuzz_target!(|data: &[u8]| {
    let mut d = FrameDecoder::new();
    let mut out = Vec::new();
    let split = data.first().map_or(1, |&b| usize::from(b % 16) + 1);
    for chunk in data.chunks(split) {
        d.push(chunk, &mut out);
        out.clear();
    }
});
