//! Robot sentences from arbitrary text: never panic; an accepted sentence
//! formats back to a line that parses to the same sentence.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scanner::protocol::robot::{Message, Sentence};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(s) = Sentence::parse(text) {
        let again = Sentence::parse(&s.format()).expect("our own line parses");
        assert_eq!(again.seq, s.seq);
        if !matches!(s.message, Message::Error { .. }) {
            // Numbers go through 9 decimals: compare the kinds.
            assert_eq!(std::mem::discriminant(&again.message), std::mem::discriminant(&s.message));
        }
    }
});
