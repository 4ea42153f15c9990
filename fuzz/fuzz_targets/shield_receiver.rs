//! Station → shield bytes: the shield's receiver never panics and never yields a pulse outside
//! 1000–2000 µs.
#![no_main]

use libfuzzer_sys::fuzz_target;
use link::shield::wire::{Event, Receiver};

fuzz_target!(|data: &[u8]| {
    let mut r = Receiver::new();
    for &b in data {
        if let Some(Event::Pulses(p)) = r.push(b) {
            for us in [p.roll, p.pitch, p.yaw, p.throttle] {
                assert!((1000..=2000).contains(&us), "pulse {us} µs");
            }
        }
    }
});
