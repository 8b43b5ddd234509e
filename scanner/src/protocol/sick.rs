//! SICK LMS-2xx telegrams (device_protocols.md §1).
//!
//! A telegram is `STX address length(u16 LE) payload crc(u16 LE)`; the
//! length counts the payload (command code, data and — in replies only —
//! the status byte); the CRC covers STX to the status byte. A device answers
//! a valid request with a raw `ACK` byte and then its reply (its code is the
//! request's plus 80h), a request with a bad CRC with a raw `NAK`.
//! Multi-byte fields are little endian.

use super::{ProtocolError, hex_excerpt};

/// Start of every telegram.
pub const STX: u8 = 0x02;
/// Raw acknowledge byte (request accepted, reply follows).
pub const ACK: u8 = 0x06;
/// Raw not-acknowledge byte (bad CRC; resend after ≥ 30 ms).
pub const NAK: u8 = 0x15;
/// The host's destination address (broadcast).
pub const HOST_TO_DEVICE: u8 = 0x00;
/// Replies carry the device address + 80h.
pub const REPLY_BIT: u8 = 0x80;
/// Largest payload (length field) of a standard telegram.
pub const MAX_LENGTH: usize = 812;
/// The status byte of a device in normal operation (LMS type 6, no error).
pub const STATUS_OK: u8 = 0x10;
/// The default installation-mode password.
pub const PASSWORD: &[u8; 8] = b"SICK_LMS";

/// Command codes (requests; the reply is the code + 80h).
pub mod cmd {
    /// Soft reset (answered 91h, then 90h).
    pub const RESET: u8 = 0x10;
    /// Operating mode / session baud rate (answered A0h).
    pub const MODE: u8 = 0x20;
    /// Measured values on request (answered B0h).
    pub const SCAN: u8 = 0x30;
    /// Status (answered B1h).
    pub const STATUS: u8 = 0x31;
    /// Type string (answered BAh).
    pub const TYPE: u8 = 0x3A;
    /// Scan angle and resolution (answered BBh).
    pub const VARIANT: u8 = 0x3B;
    /// Read the configuration block (answered F4h).
    pub const READ_CONFIG: u8 = 0x74;
    /// Write the configuration block (answered F7h).
    pub const WRITE_CONFIG: u8 = 0x77;
    /// Reply code: the request is not allowed in this state.
    pub const NOT_ALLOWED: u8 = 0x92;
    /// The measured-values reply code.
    pub const MEASURED: u8 = 0xB0;
}

/// Sub-commands of [`cmd::MODE`].
pub mod mode {
    /// Installation mode (followed by the 8-byte password).
    pub const INSTALLATION: u8 = 0x00;
    /// Monitoring mode, continuous output of all values.
    pub const CONTINUOUS: u8 = 0x24;
    /// Monitoring mode, values on request only (stops streaming).
    pub const ON_REQUEST: u8 = 0x25;
    /// Session baud rate 38400.
    pub const BAUD_38400: u8 = 0x40;
    /// Session baud rate 19200.
    pub const BAUD_19200: u8 = 0x41;
    /// Session baud rate 9600.
    pub const BAUD_9600: u8 = 0x42;
    /// Session baud rate 500000 (RS-422).
    pub const BAUD_500000: u8 = 0x48;
}

/// The 34-byte configuration block of 74h (read) and 77h (write), §1.6.
pub mod config {
    /// Its length.
    pub const LEN: usize = 34;
    /// Availability flags; bit 1 appends the real-time scan indices to B0h.
    pub const AVAILABILITY: usize = 4;
    /// The measuring mode ([`super::Range::config_byte`]).
    pub const MEASURING_MODE: usize = 5;
    /// The unit: 00h cm, 01h mm.
    pub const UNIT: usize = 6;
    /// Bit of [`AVAILABILITY`] that appends the scan and telegram indices.
    pub const INDICES: u8 = 0x02;

    /// An LMS200's factory block: peak threshold 46h, 8 m mode, mm.
    pub fn factory() -> [u8; LEN] {
        let mut b = [0_u8; LEN];
        b[2] = 0x46;
        b[UNIT] = 0x01;
        b
    }
}

/// A 3Bh request for a field of view of `angle_deg` (100 or 180) at
/// `resolution_cdeg` hundredths of a degree (100, 50 or 25).
pub fn variant_request(angle_deg: u16, resolution_cdeg: u16) -> Vec<u8> {
    let mut data = Vec::with_capacity(4);
    data.extend(angle_deg.to_le_bytes());
    data.extend(resolution_cdeg.to_le_bytes());
    request(cmd::VARIANT, &data)
}

/// The [`cmd::MODE`] sub-command that switches to `baud`, if the LMS has it.
pub fn baud_mode(baud: u32) -> Option<u8> {
    match baud {
        9600 => Some(mode::BAUD_9600),
        19200 => Some(mode::BAUD_19200),
        38400 => Some(mode::BAUD_38400),
        500_000 => Some(mode::BAUD_500000),
        _ => None,
    }
}

/// The baud rate a [`cmd::MODE`] sub-command selects.
pub fn mode_baud(sub: u8) -> Option<u32> {
    [9600, 19200, 38400, 500_000].into_iter().find(|b| baud_mode(*b) == Some(sub))
}

/// The SICK CRC-16 over `data` (§1.5: the register is shifted, XORed with
/// 8005h when the bit shifted out was set, then XORed with the 16-bit word
/// of the previous and the current byte). Not a table CRC.
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    let mut prev: u8 = 0;
    for &b in data {
        crc = if crc & 0x8000 != 0 { ((crc & 0x7FFF) << 1) ^ 0x8005 } else { crc << 1 };
        crc ^= u16::from_be_bytes([prev, b]);
        prev = b;
    }
    crc
}

/// A whole telegram: header, `payload` (code, data and, in replies, the
/// status byte) and CRC.
pub fn encode(address: u8, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len() + 6);
    out.extend([STX, address]);
    out.extend((payload.len() as u16).to_le_bytes());
    out.extend(payload);
    let crc = crc16(&out);
    out.extend(crc.to_le_bytes());
    out
}

/// A host request: command `code` with `data`, to the broadcast address.
pub fn request(code: u8, data: &[u8]) -> Vec<u8> {
    let mut payload = Vec::with_capacity(data.len() + 1);
    payload.push(code);
    payload.extend(data);
    encode(HOST_TO_DEVICE, &payload)
}

/// A device reply with `code` (request + 80h), `data` and `status`.
pub fn reply(code: u8, data: &[u8], status: u8) -> Vec<u8> {
    let mut payload = Vec::with_capacity(data.len() + 2);
    payload.push(code);
    payload.extend(data);
    payload.push(status);
    encode(REPLY_BIT, &payload)
}

/// One decoded telegram.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// The address byte (bit 7 set in replies).
    pub address: u8,
    /// Code, data and (replies) the status byte.
    pub payload: Vec<u8>,
}

impl Frame {
    /// Whether it is a device reply (address bit 7).
    pub fn is_reply(&self) -> bool {
        self.address & REPLY_BIT != 0
    }

    /// The command or reply code.
    pub fn code(&self) -> u8 {
        self.payload.first().copied().unwrap_or(0)
    }

    /// The data between the code and (in replies) the status byte.
    pub fn data(&self) -> &[u8] {
        let end = if self.is_reply() { self.payload.len().saturating_sub(1) } else { self.payload.len() };
        self.payload.get(1..end.max(1)).unwrap_or(&[])
    }

    /// The status byte of a reply.
    pub fn status(&self) -> Option<Status> {
        if self.is_reply() && self.payload.len() >= 2 { self.payload.last().copied().map(Status) } else { None }
    }
}

/// The status byte of a reply (§1.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Status(pub u8);

impl Status {
    /// 0 no error, 1 info, 2 warning, 3 error, 4 fatal error.
    pub fn severity(&self) -> u8 {
        self.0 & 0x07
    }

    /// Bit 6: implausible measured values.
    pub fn implausible(&self) -> bool {
        self.0 & 0x40 != 0
    }

    /// Bit 7: the front screen is dirty.
    pub fn pollution(&self) -> bool {
        self.0 & 0x80 != 0
    }

    /// A sentence for messages, or `None` when all is well.
    pub fn problem(&self) -> Option<String> {
        let mut parts = Vec::new();
        match self.severity() {
            0 | 1 => {}
            2 => parts.push("warning"),
            3 => parts.push("error"),
            _ => parts.push("fatal error"),
        }
        if self.implausible() {
            parts.push("implausible measured values");
        }
        if self.pollution() {
            parts.push("front screen polluted");
        }
        (!parts.is_empty()).then(|| format!("status {:#04x}: {}", self.0, parts.join(", ")))
    }
}

/// What a [`Decoder`] finds in the byte stream.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A raw ACK byte (device → host only).
    Ack,
    /// A raw NAK byte (device → host only).
    Nak,
    /// A telegram with a valid CRC.
    Frame(Frame),
    /// A telegram-shaped run of bytes whose CRC fails; the decoder has moved
    /// one byte past its STX to look for the next telegram.
    Corrupt(ProtocolError),
}

/// Which side's telegrams a [`Decoder`] reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Device replies (address bit 7 set), ACK and NAK bytes: the host's view.
    FromDevice,
    /// Host requests (address bit 7 clear): the device's (emulator's) view.
    FromHost,
}

/// A streaming telegram decoder: push bytes as they arrive (in any chunks),
/// take events. It resynchronises on `STX` + a plausible address + a
/// plausible length after garbage, dropped bytes or a failed CRC.
#[derive(Debug, Clone)]
pub struct Decoder {
    direction: Direction,
    buf: Vec<u8>,
    start: usize,
    skipped: usize,
}

impl Decoder {
    /// A decoder for `direction`.
    pub fn new(direction: Direction) -> Self {
        Self { direction, buf: Vec::with_capacity(2048), start: 0, skipped: 0 }
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.start > 0 && self.start == self.buf.len() {
            self.buf.clear();
            self.start = 0;
        } else if self.start > 4096 {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// Drops everything buffered (e.g. after a baud-rate change).
    pub fn clear(&mut self) {
        self.buf.clear();
        self.start = 0;
    }

    /// Bytes buffered and not yet decoded.
    pub fn pending(&self) -> usize {
        self.buf.len() - self.start
    }

    /// Bytes skipped as garbage so far.
    pub fn skipped(&self) -> usize {
        self.skipped
    }

    fn plausible_address(&self, a: u8) -> bool {
        match self.direction {
            Direction::FromDevice => a & REPLY_BIT != 0,
            Direction::FromHost => a & REPLY_BIT == 0,
        }
    }

    fn skip(&mut self, n: usize) {
        self.start += n;
        self.skipped += n;
    }

    /// The next event, or `None` until more bytes arrive.
    pub fn next_event(&mut self) -> Option<Event> {
        loop {
            let b = &self.buf[self.start..];
            let first = *b.first()?;
            match first {
                STX => {
                    if b.len() < 4 {
                        if b.len() >= 2 && !self.plausible_address(b[1]) {
                            self.skip(1);
                            continue;
                        }
                        return None;
                    }
                    let len = usize::from(u16::from_le_bytes([b[2], b[3]]));
                    let min = if self.direction == Direction::FromDevice { 2 } else { 1 };
                    if !self.plausible_address(b[1]) || len < min || len > MAX_LENGTH {
                        self.skip(1);
                        continue;
                    }
                    let total = len + 6;
                    if b.len() < total {
                        return None;
                    }
                    let computed = crc16(&b[..len + 4]);
                    let received = u16::from_le_bytes([b[len + 4], b[len + 5]]);
                    if computed != received {
                        self.skip(1);
                        return Some(Event::Corrupt(ProtocolError::Checksum {
                            what: "SICK CRC-16",
                            received,
                            computed,
                        }));
                    }
                    let frame = Frame { address: b[1], payload: b[4..len + 4].to_vec() };
                    self.start += total;
                    return Some(Event::Frame(frame));
                }
                ACK if self.direction == Direction::FromDevice => {
                    self.start += 1;
                    return Some(Event::Ack);
                }
                NAK if self.direction == Direction::FromDevice => {
                    self.start += 1;
                    return Some(Event::Nak);
                }
                _ => self.skip(1),
            }
        }
    }
}

/// Unit of the measured values (count-word bits 14–15).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unit {
    /// Centimetres.
    Cm,
    /// Millimetres.
    Mm,
}

impl Unit {
    /// Metres per count.
    pub fn metres_per_count(&self) -> f64 {
        match self {
            Unit::Cm => 0.01,
            Unit::Mm => 0.001,
        }
    }
}

/// Measuring mode (configuration byte 5): how many bits of a value word
/// are distance (the rest are field and dazzle flags).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Range {
    /// Modes 00h/02h: 13 distance bits (8 m in mm, 80 m in cm).
    Bits13,
    /// Mode 04h: 14 distance bits (16 m in mm).
    Bits14,
    /// Mode 06h: 15 distance bits (32 m in mm).
    Bits15,
}

impl Range {
    /// The distance bits.
    pub fn mask(&self) -> u16 {
        match self {
            Range::Bits13 => 0x1FFF,
            Range::Bits14 => 0x3FFF,
            Range::Bits15 => 0x7FFF,
        }
    }

    /// The first code that is not a distance (…F7h, "greater than maximum").
    pub fn max_valid(&self) -> u16 {
        self.mask() - 8
    }

    /// The range a configuration byte 5 selects (00h and 02h: 13 bits,
    /// 04h: 14, 06h: 15); the reflectivity modes 01h/03h/05h give no range.
    pub fn from_config_byte(b: u8) -> Option<Self> {
        match b {
            0x00 | 0x02 => Some(Range::Bits13),
            0x04 => Some(Range::Bits14),
            0x06 => Some(Range::Bits15),
            _ => None,
        }
    }

    /// Configuration byte 5 for this range.
    pub fn config_byte(&self) -> u8 {
        match self {
            Range::Bits13 => 0x00,
            Range::Bits14 => 0x04,
            Range::Bits15 => 0x06,
        }
    }
}

/// Why a value is not a distance (§1.7's special codes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoReturn {
    /// …FFh: no stop signal (nothing hit).
    NoEcho,
    /// …FEh: dazzled.
    Dazzle,
    /// …FDh: operation overflow.
    Overflow,
    /// …FBh: signal-to-noise ratio too small.
    LowSignal,
    /// …FAh: error reading channel 1.
    ChannelError,
    /// …F7h: value greater than maximum (e.g. open sky).
    OutOfRange,
    /// …F8h, …F9h, …FCh: codes the listing does not define.
    Reserved,
}

/// The distance in counts of a value word, or why there is none.
pub fn distance(word: u16, range: Range) -> Result<u16, NoReturn> {
    let d = word & range.mask();
    if d < range.max_valid() {
        return Ok(d);
    }
    Err(match range.mask() - d {
        0 => NoReturn::NoEcho,
        1 => NoReturn::Dazzle,
        2 => NoReturn::Overflow,
        4 => NoReturn::LowSignal,
        5 => NoReturn::ChannelError,
        8 => NoReturn::OutOfRange,
        _ => NoReturn::Reserved,
    })
}

/// A decoded B0h telegram (§1.7).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Measured {
    /// The raw value words, ascending angle.
    pub words: Vec<u16>,
    /// Their unit.
    pub unit: Unit,
    /// The interlace index (0–3: x.00°, x.25°, x.50°, x.75°) of a partial scan.
    pub partial: Option<u8>,
    /// Real-time scan index, when configured.
    pub scan_index: Option<u8>,
    /// Telegram index, when configured.
    pub telegram_index: Option<u8>,
    /// The status byte.
    pub status: Status,
}

/// Decodes a B0h reply; `indices` says whether the scanner appends the
/// real-time scan and telegram indices (configuration byte 4 bit 1).
pub fn decode_measured(frame: &Frame, indices: bool) -> Result<Measured, ProtocolError> {
    let malformed = |reason: String| ProtocolError::Malformed {
        what: "B0h measured-values telegram",
        reason,
        excerpt: hex_excerpt(&frame.payload, 12),
    };
    if frame.code() != cmd::MEASURED || !frame.is_reply() {
        return Err(ProtocolError::Unexpected {
            expected: "a B0h reply".into(),
            received: format!("code {:#04x} (address {:#04x})", frame.code(), frame.address),
        });
    }
    let status = frame.status().ok_or_else(|| malformed("no status byte".into()))?;
    let data = frame.data();
    if data.len() < 2 {
        return Err(malformed(format!("{} data bytes; expected at least the 2-byte count word", data.len())));
    }
    let count = u16::from_le_bytes([data[0], data[1]]);
    let n = usize::from(count & 0x03FF);
    let unit = match count >> 14 {
        0 => Unit::Cm,
        1 => Unit::Mm,
        u => return Err(malformed(format!("unit bits {u:02b}; expected 00 (cm) or 01 (mm)"))),
    };
    let partial = (count & 0x2000 != 0).then_some(((count >> 11) & 0x3) as u8);
    let extra = if indices { 2 } else { 0 };
    let expected = 2 + 2 * n + extra;
    if data.len() != expected {
        return Err(malformed(format!(
            "{} data bytes for {n} values; expected {expected} (count word {count:#06x}{})",
            data.len(),
            if indices { ", with the scan and telegram indices" } else { "" }
        )));
    }
    let words = data[2..2 + 2 * n].chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
    let (scan_index, telegram_index) =
        if indices { (Some(data[2 + 2 * n]), Some(data[3 + 2 * n])) } else { (None, None) };
    Ok(Measured { words, unit, partial, scan_index, telegram_index, status })
}

/// Encodes a B0h reply for `words` (a complete scan), the inverse of
/// [`decode_measured`] without indices.
pub fn encode_measured(words: &[u16], unit: Unit, status: u8) -> Vec<u8> {
    let unit_bits: u16 = match unit {
        Unit::Cm => 0,
        Unit::Mm => 1 << 14,
    };
    let count = (words.len() as u16 & 0x03FF) | unit_bits;
    let mut data = Vec::with_capacity(2 + 2 * words.len());
    data.extend(count.to_le_bytes());
    for w in words {
        data.extend(w.to_le_bytes());
    }
    reply(cmd::MEASURED, &data, status)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        s.split_whitespace().map(|b| u8::from_str_radix(b, 16).expect("hex")).collect()
    }

    /// The telegrams of device_protocols.md §1.9, whose CRCs were verified
    /// against SICK's telegram listing and exchanged with MRPT.
    #[test]
    fn golden_telegrams() {
        let cases = [
            (request(cmd::MODE, &[mode::CONTINUOUS]), "02 00 02 00 20 24 34 08"),
            (request(cmd::MODE, &[mode::ON_REQUEST]), "02 00 02 00 20 25 35 08"),
            (request(cmd::SCAN, &[0x01]), "02 00 02 00 30 01 31 18"),
            (request(cmd::MODE, &[mode::BAUD_38400]), "02 00 02 00 20 40 50 08"),
            (request(cmd::MODE, &[mode::BAUD_19200]), "02 00 02 00 20 41 51 08"),
            (request(cmd::MODE, &[mode::BAUD_9600]), "02 00 02 00 20 42 52 08"),
            (request(cmd::MODE, &[mode::BAUD_500000]), "02 00 02 00 20 48 58 08"),
            (request(cmd::STATUS, &[]), "02 00 01 00 31 15 12"),
            (reply(0xA0, &[0x00], STATUS_OK), "02 80 03 00 A0 00 10 16 0A"),
            (
                request(cmd::MODE, &[&[mode::INSTALLATION][..], PASSWORD].concat()),
                "02 00 0A 00 20 00 53 49 43 4B 5F 4C 4D 53 BE C5",
            ),
            (request(cmd::VARIANT, &[0xB4, 0x00, 0x64, 0x00]), "02 00 05 00 3B B4 00 64 00 97 49"),
            (request(cmd::VARIANT, &[0xB4, 0x00, 0x32, 0x00]), "02 00 05 00 3B B4 00 32 00 3B 1F"),
            (reply(0xBB, &[0x01, 0xB4, 0x00, 0x64, 0x00], STATUS_OK), "02 80 07 00 BB 01 B4 00 64 00 10 5B 30"),
            (
                encode_measured(&[1000, 1500, 0x1FF7, 0x1FFE, 250], Unit::Mm, STATUS_OK),
                "02 80 0E 00 B0 05 40 E8 03 DC 05 F7 1F FE 1F FA 00 10 10 8D",
            ),
        ];
        for (built, expected) in cases {
            assert_eq!(built, hex(expected), "{expected}");
        }
        // The listing's other verified vectors, by CRC alone (§1.5).
        assert_eq!(crc16(&hex("02 00 01 00 10")), 0x1234); // 10h reset: 34 12
        assert_eq!(crc16(&hex("02 00 01 00 3A")), 0x121E); // 3Ah type: 1E 12
    }

    #[test]
    fn the_decoder_finds_frames_in_any_chunks_and_after_garbage() {
        let toy = hex("02 80 0E 00 B0 05 40 E8 03 DC 05 F7 1F FE 1F FA 00 10 10 8D");
        let mut stream = vec![0x55, 0x02, 0x02, 0x80, 0xFF, 0xFF, ACK];
        stream.extend(&toy);
        stream.extend([NAK]);
        for chunk in [1, 3, 7, stream.len()] {
            let mut d = Decoder::new(Direction::FromDevice);
            let mut events = Vec::new();
            for c in stream.chunks(chunk) {
                d.push(c);
                while let Some(e) = d.next_event() {
                    events.push(e);
                }
            }
            assert_eq!(events.len(), 3, "chunk {chunk}: {events:?}");
            assert_eq!(events[0], Event::Ack);
            let Event::Frame(f) = &events[1] else { panic!("a frame: {events:?}") };
            assert_eq!(events[2], Event::Nak);
            let m = decode_measured(f, false).expect("B0h");
            assert_eq!(m.words, [1000, 1500, 0x1FF7, 0x1FFE, 250]);
            assert_eq!((m.unit, m.status, m.partial), (Unit::Mm, Status(0x10), None));
            let ranges: Vec<_> = m.words.iter().map(|w| distance(*w, Range::Bits13)).collect();
            assert_eq!(ranges, [Ok(1000), Ok(1500), Err(NoReturn::OutOfRange), Err(NoReturn::Dazzle), Ok(250)]);
            assert_eq!(d.skipped(), 6, "0x55, a lone STX, the STX of `02 80 FF FF` and its 3 bytes");
        }
    }

    #[test]
    fn a_bad_crc_is_reported_and_the_next_frame_still_found() {
        // §1.9's NAK case, seen by the device: the request with its CRC off by one.
        let mut d = Decoder::new(Direction::FromHost);
        d.push(&hex("02 00 02 00 20 24 34 09 02 00 02 00 20 25 35 08"));
        let Some(Event::Corrupt(ProtocolError::Checksum { received: 0x0934, computed: 0x0834, .. })) = d.next_event()
        else {
            panic!("a CRC error")
        };
        let Some(Event::Frame(f)) = d.next_event() else { panic!("the next request") };
        assert_eq!((f.code(), f.data()), (cmd::MODE, &[mode::ON_REQUEST][..]));
        assert!(!f.is_reply() && f.status().is_none());
        assert_eq!(d.next_event(), None);
    }

    #[test]
    fn measured_values_are_checked() {
        let frame = |payload: Vec<u8>| Frame { address: 0x80, payload };
        // Count says 5 values, 3 present.
        let short = frame(vec![0xB0, 0x05, 0x40, 1, 0, 2, 0, 3, 0, 0x10]);
        assert!(matches!(decode_measured(&short, false), Err(ProtocolError::Malformed { .. })));
        // Reserved unit bits.
        let unit = frame(vec![0xB0, 0x01, 0x80, 1, 0, 0x10]);
        assert!(matches!(decode_measured(&unit, false), Err(ProtocolError::Malformed { .. })));
        // With indices, partial scan index 2, cm.
        let ok = frame(vec![0xB0, 0x02, 0x30, 0x10, 0x00, 0x20, 0x00, 7, 9, 0x10]);
        let m = decode_measured(&ok, true).expect("valid");
        assert_eq!((m.words, m.unit, m.partial), (vec![16, 32], Unit::Cm, Some(2)));
        assert_eq!((m.scan_index, m.telegram_index), (Some(7), Some(9)));
        assert!(matches!(decode_measured(&frame(vec![0xA0, 0, 0x10]), false), Err(ProtocolError::Unexpected { .. })));
        // Every special code of the 15-bit range, flags masked off.
        let codes = [0x7FFF, 0x7FFE, 0x7FFD, 0x7FFB, 0x7FFA, 0x7FF7, 0x7FF9];
        let got: Vec<_> = codes.iter().map(|c| distance(c | 0x8000, Range::Bits15)).collect();
        use NoReturn::*;
        let expected = [NoEcho, Dazzle, Overflow, LowSignal, ChannelError, OutOfRange, Reserved].map(Err);
        assert_eq!(got, expected);
        assert_eq!(distance(0x7FF6, Range::Bits15), Ok(0x7FF6));
        assert_eq!(Status(0x13).problem().as_deref(), Some("status 0x13: error"));
        assert_eq!(Status(0x10).problem(), None);
    }
}
