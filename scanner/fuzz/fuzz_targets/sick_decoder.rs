//! The SICK telegram decoder on arbitrary bytes in arbitrary chunks, both
//! directions: never panics, never loops, every frame it yields has a valid
//! CRC and decodes (or is rejected) as measured values without panicking.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scanner::protocol::sick::{Decoder, Direction, Event, crc16, decode_measured, encode};

fuzz_target!(|data: &[u8]| {
    let Some((&chunk, bytes)) = data.split_first() else { return };
    let chunk = usize::from(chunk).max(1);
    for direction in [Direction::FromDevice, Direction::FromHost] {
        let mut d = Decoder::new(direction);
        let mut events = 0;
        for c in bytes.chunks(chunk) {
            d.push(c);
            while let Some(e) = d.next_event() {
                events += 1;
                assert!(events <= 2 * bytes.len() + 1, "more events than bytes");
                if let Event::Frame(f) = e {
                    let wire = encode(f.address, &f.payload);
                    let n = wire.len();
                    assert_eq!(crc16(&wire[..n - 2]), u16::from_le_bytes([wire[n - 2], wire[n - 1]]));
                    let _ = decode_measured(&f, false);
                    let _ = decode_measured(&f, true);
                }
            }
        }
        assert!(d.pending() <= bytes.len());
    }
});
