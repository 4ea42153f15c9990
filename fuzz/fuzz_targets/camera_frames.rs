//! The camera frame stream reader on arbitrary bytes: whole messages and a stream of them.
#![no_main]

use libfuzzer_sys::fuzz_target;
use link::camera::RgbdFrame;

fuzz_target!(|data: &[u8]| {
    let _ = RgbdFrame::decode(data);
    let mut stream = std::io::Cursor::new(data);
    while RgbdFrame::read_from(&mut stream).is_ok() {}
});
