//! Bytes from a MAVLink vehicle: the frame scanner and the decoder never panic, and the scanner's
//! memory stays bounded.
#![no_main]

use libfuzzer_sys::fuzz_target;
use link::mavlink::frame::FrameScanner;

fuzz_target!(|data: &[u8]| {
    let mut s = FrameScanner::new();
    let split = data.first().map_or(1, |&b| usize::from(b) + 1);
    for chunk in data.chunks(split) {
        s.push(chunk);
        while let Some(f) = s.next_frame() {
            let _ = f.decode();
            let _ = (f.header(), f.message_id(), f.payload(), f.is_signed());
        }
    }
});
