//! XDR tilt lines from arbitrary text: never panic; an accepted line gives
//! finite angles.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scanner::protocol::nmea::parse_xdr;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(line) = parse_xdr(text) {
        let t = line.tilt();
        assert!(t.roll_rad.is_finite() && t.pitch_rad.is_finite(), "{text:?}");
    }
});
