//! Leica GeoCOM ASCII RPC (device_protocols.md §2.1).
//!
//! Request `%R1Q,<rpc>,<trid>[,<crc>]:<p0>,<p1>…` and reply
//! `%R1P,<com_rc>,<trid>[,<crc>]:<rc>,<v0>,<v1>…`, one line each, CR LF
//! terminated. Angles are radians (Hz clockwise, V from the zenith),
//! distances metres. The optional CRC is CRC-16/ARC over the line without
//! the CRC field and its comma.

use super::{ProtocolError, text_excerpt};

/// The RPCs the survey uses.
pub mod rpc {
    /// COM_NullProc: connection check.
    pub const NULL_PROC: u16 = 0;
    /// COM_GetDoublePrecision.
    pub const GET_DOUBLE_PRECISION: u16 = 108;
    /// COM_GetSWVersion.
    pub const GET_SW_VERSION: u16 = 110;
    /// CSV_GetInstrumentNo.
    pub const GET_INSTRUMENT_NO: u16 = 5003;
    /// CSV_GetInstrumentName.
    pub const GET_INSTRUMENT_NAME: u16 = 5004;
    /// CSV_GetSWVersion.
    pub const CSV_GET_SW_VERSION: u16 = 5034;
    /// BAP_SetTargetType.
    pub const SET_TARGET_TYPE: u16 = 17021;
    /// BAP_SetPrismType.
    pub const SET_PRISM_TYPE: u16 = 17008;
    /// BAP_SetMeasPrg.
    pub const SET_MEAS_PRG: u16 = 17019;
    /// AUT_MakePositioning: Hz, V, posmode, atrmode, 0.
    pub const MAKE_POSITIONING: u16 = 9027;
    /// AUT_FineAdjust: search window Hz, V, 0 (ATR onto the prism).
    pub const FINE_ADJUST: u16 = 9037;
    /// AUT_SetLockStatus.
    pub const SET_LOCK_STATUS: u16 = 9020;
    /// AUT_LockIn.
    pub const LOCK_IN: u16 = 9013;
    /// TMC_DoMeasure: program, inclination mode.
    pub const DO_MEASURE: u16 = 2008;
    /// TMC_GetSimpleMea: wait ms, inclination mode → Hz, V, slope distance.
    pub const GET_SIMPLE_MEA: u16 = 2108;
    /// TMC_GetAngle1.
    pub const GET_ANGLE1: u16 = 2003;
    /// BAP_MeasDistanceAngle: mode → Hz, V, slope distance, mode.
    pub const MEAS_DISTANCE_ANGLE: u16 = 17017;
}

/// A GeoCOM return code (GRC_*, and the COM layer's), typed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReturnCode {
    /// 0: success.
    Ok,
    /// 1: undefined error.
    Undefined,
    /// 2: invalid parameter.
    InvalidParameter,
    /// 5: not implemented.
    NotImplemented,
    /// 8: aborted.
    Aborted,
    /// 13: system busy.
    SystemBusy,
    /// 27: not available (licence).
    NotAvailable,
    /// 1283: measured, without full correction (warning; values valid).
    NoFullCorrection,
    /// 1284: accuracy not guaranteed (warning; values valid).
    AccuracyNotGuaranteed,
    /// 1285: angles only, no distance.
    AnglesOnly,
    /// 1292: distance measurement error.
    DistanceError,
    /// 1293: the measurement system is busy.
    MeasurementBusy,
    /// 3077: communication timed out.
    ComTimedOut,
    /// 3101, 3102: checksum errors on the instrument's side.
    ComChecksum,
    /// 8704: ATR timed out.
    AtrTimeout,
    /// 8710: no prism in the ATR's field of view.
    NoTarget,
    /// 8711: several prisms in the field of view.
    MultipleTargets,
    /// Any other code.
    Other(u16),
}

impl ReturnCode {
    /// The typed code of a number.
    pub fn from_code(code: u16) -> Self {
        match code {
            0 => Self::Ok,
            1 => Self::Undefined,
            2 => Self::InvalidParameter,
            5 => Self::NotImplemented,
            8 => Self::Aborted,
            13 => Self::SystemBusy,
            27 => Self::NotAvailable,
            1283 => Self::NoFullCorrection,
            1284 => Self::AccuracyNotGuaranteed,
            1285 => Self::AnglesOnly,
            1292 => Self::DistanceError,
            1293 => Self::MeasurementBusy,
            3077 => Self::ComTimedOut,
            3101 | 3102 => Self::ComChecksum,
            8704 => Self::AtrTimeout,
            8710 => Self::NoTarget,
            8711 => Self::MultipleTargets,
            other => Self::Other(other),
        }
    }

    /// The number on the wire (3101 for [`ReturnCode::ComChecksum`]).
    pub fn code(&self) -> u16 {
        match self {
            Self::Ok => 0,
            Self::Undefined => 1,
            Self::InvalidParameter => 2,
            Self::NotImplemented => 5,
            Self::Aborted => 8,
            Self::SystemBusy => 13,
            Self::NotAvailable => 27,
            Self::NoFullCorrection => 1283,
            Self::AccuracyNotGuaranteed => 1284,
            Self::AnglesOnly => 1285,
            Self::DistanceError => 1292,
            Self::MeasurementBusy => 1293,
            Self::ComTimedOut => 3077,
            Self::ComChecksum => 3101,
            Self::AtrTimeout => 8704,
            Self::NoTarget => 8710,
            Self::MultipleTargets => 8711,
            Self::Other(c) => *c,
        }
    }

    /// Success or a warning whose values are valid.
    pub fn values_valid(&self) -> bool {
        matches!(self, Self::Ok | Self::NoFullCorrection | Self::AccuracyNotGuaranteed)
    }

    /// Whether trying again may help (busy, timeout, checksum).
    pub fn transient(&self) -> bool {
        matches!(
            self,
            Self::SystemBusy | Self::MeasurementBusy | Self::ComTimedOut | Self::ComChecksum | Self::AtrTimeout
        )
    }
}

impl std::fmt::Display for ReturnCode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let what = match self {
            Self::Ok => "OK",
            Self::Undefined => "undefined error",
            Self::InvalidParameter => "invalid parameter",
            Self::NotImplemented => "not implemented",
            Self::Aborted => "aborted",
            Self::SystemBusy => "system busy",
            Self::NotAvailable => "not available (licence)",
            Self::NoFullCorrection => "measured without full correction",
            Self::AccuracyNotGuaranteed => "accuracy not guaranteed",
            Self::AnglesOnly => "angles only, no distance",
            Self::DistanceError => "distance measurement error",
            Self::MeasurementBusy => "measurement system busy",
            Self::ComTimedOut => "communication timed out",
            Self::ComChecksum => "checksum error at the instrument",
            Self::AtrTimeout => "ATR timed out",
            Self::NoTarget => "no prism in the ATR's view",
            Self::MultipleTargets => "several prisms in the ATR's view",
            Self::Other(_) => "return code",
        };
        write!(f, "{what} ({})", self.code())
    }
}

/// CRC-16/ARC (reflected 8005h, init 0, no final XOR).
pub fn crc16_arc(data: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    for &b in data {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xA001 } else { crc >> 1 };
        }
    }
    crc
}

/// A parameter of a request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Param<'a> {
    /// An integer or enum.
    Int(i64),
    /// A double (radians, metres).
    Double(f64),
    /// A string (sent in double quotes).
    Str(&'a str),
}

impl std::fmt::Display for Param<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Param::Int(i) => write!(f, "{i}"),
            Param::Double(d) => write!(f, "{d}"),
            Param::Str(s) => write!(f, "\"{s}\""),
        }
    }
}

fn with_crc(tag: &str, header: &[String], body: &str, checksum: bool) -> String {
    let plain = format!("{tag},{}:{body}", header.join(","));
    if !checksum {
        return format!("{plain}\r\n");
    }
    let crc = crc16_arc(plain.as_bytes());
    format!("{tag},{},{crc}:{body}\r\n", header.join(","))
}

/// A request line (CR LF included).
pub fn format_request(rpc: u16, transaction: u16, params: &[Param], checksum: bool) -> String {
    let body = params.iter().map(ToString::to_string).collect::<Vec<_>>().join(",");
    with_crc("%R1Q", &[rpc.to_string(), transaction.to_string()], &body, checksum)
}

/// A reply line (CR LF included).
pub fn format_reply(com: u16, transaction: u16, rc: ReturnCode, values: &[String], checksum: bool) -> String {
    let body = std::iter::once(rc.code().to_string()).chain(values.iter().cloned()).collect::<Vec<_>>().join(",");
    with_crc("%R1P", &[com.to_string(), transaction.to_string()], &body, checksum)
}

/// A parsed request (the emulator's side).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Request {
    /// The RPC number.
    pub rpc: u16,
    /// The transaction id (0 when omitted).
    pub transaction: u16,
    /// Whether it carried a CRC (the reply then carries one too).
    pub checksum: bool,
    /// The parameters as text (strings with their quotes removed).
    pub params: Vec<String>,
}

/// A parsed reply (the driver's side).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reply {
    /// The communication layer's return code.
    pub com: ReturnCode,
    /// The transaction id.
    pub transaction: u16,
    /// The procedure's return code.
    pub rc: ReturnCode,
    /// The values after it, as text.
    pub values: Vec<String>,
}

impl Reply {
    /// Value `i` as a double.
    pub fn double(&self, i: usize) -> Result<f64, ProtocolError> {
        let v = self.values.get(i).ok_or_else(|| ProtocolError::Malformed {
            what: "GeoCOM reply",
            reason: format!("{} values; expected at least {}", self.values.len(), i + 1),
            excerpt: self.values.join(","),
        })?;
        v.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| ProtocolError::Malformed {
            what: "GeoCOM reply",
            reason: format!("value {i} is {v:?}; expected a finite number"),
            excerpt: self.values.join(","),
        })
    }
}

/// Splits on commas outside double quotes and removes the quotes.
fn fields(s: &str) -> Vec<String> {
    let mut out = Vec::new();
    let (mut cur, mut quoted) = (String::new(), false);
    for c in s.chars() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => out.push(std::mem::take(&mut cur)),
            c => cur.push(c),
        }
    }
    out.push(cur);
    out
}

/// Parses `<tag>,<a>,<b>[,<crc>]:<body>`: the two header numbers, the body
/// fields and whether a CRC was present (and right).
fn parse_line(line: &str, tag: &str, what: &'static str) -> Result<(u16, u16, bool, Vec<String>), ProtocolError> {
    let malformed = |reason: String| ProtocolError::Malformed { what, reason, excerpt: text_excerpt(line, 60) };
    let text = line.trim_start_matches(['\n', '\r']).trim_end_matches(['\n', '\r']);
    let rest = text.strip_prefix(tag).ok_or_else(|| malformed(format!("expected it to start with {tag}")))?;
    let (header, body) =
        rest.split_once(':').ok_or_else(|| malformed("no ':' between the header and the values".into()))?;
    let numbers: Vec<&str> = header.split(',').skip(1).collect();
    let number = |i: usize, name: &str| -> Result<u16, ProtocolError> {
        let s = numbers.get(i).ok_or_else(|| malformed(format!("no {name} in the header")))?;
        s.parse().map_err(|_| malformed(format!("{name} is {s:?}; expected a number 0–65535")))
    };
    if !header.is_empty() && !header.starts_with(',') {
        return Err(malformed(format!("expected ',' after {tag}")));
    }
    let (a, b) = (number(0, "first header field")?, number(1, "transaction id")?);
    let checksum = match numbers.len() {
        2 => false,
        3 => {
            let received = number(2, "CRC")?;
            let plain = format!("{tag},{},{}:{body}", numbers[0], numbers[1]);
            let computed = crc16_arc(plain.as_bytes());
            if received != computed {
                return Err(ProtocolError::Checksum { what: "GeoCOM CRC-16/ARC", received, computed });
            }
            true
        }
        n => return Err(malformed(format!("{n} header fields; expected 2 or 3"))),
    };
    Ok((a, b, checksum, if body.is_empty() { Vec::new() } else { fields(body) }))
}

/// Parses a request line.
pub fn parse_request(line: &str) -> Result<Request, ProtocolError> {
    let (rpc, transaction, checksum, params) = parse_line(line, "%R1Q", "GeoCOM request")?;
    Ok(Request { rpc, transaction, checksum, params })
}

/// Parses a reply line.
pub fn parse_reply(line: &str) -> Result<Reply, ProtocolError> {
    let (com, transaction, _, mut values) = parse_line(line, "%R1P", "GeoCOM reply")?;
    if values.is_empty() {
        return Err(ProtocolError::Malformed {
            what: "GeoCOM reply",
            reason: "no return code after ':'".into(),
            excerpt: text_excerpt(line, 60),
        });
    }
    let rc_text = values.remove(0);
    let rc = rc_text.trim().parse::<u16>().map_err(|_| ProtocolError::Malformed {
        what: "GeoCOM reply",
        reason: format!("return code {rc_text:?}; expected a number"),
        excerpt: text_excerpt(line, 60),
    })?;
    Ok(Reply { com: ReturnCode::from_code(com), transaction, rc: ReturnCode::from_code(rc), values })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_check_values() {
        assert_eq!(crc16_arc(b"123456789"), 0xBB3D);
        assert_eq!(crc16_arc(b"%R1P,0,11:0"), 22896);
        assert_eq!(format_reply(0, 11, ReturnCode::Ok, &[], true), "%R1P,0,11,22896:0\r\n");
    }

    #[test]
    fn the_documented_exchange_round_trips() {
        // device_protocols.md §2.1, as geocompy sent it.
        let r = parse_request("%R1Q,9037,7:0.017453,0.017453,0\r\n").expect("request");
        assert_eq!((r.rpc, r.transaction, r.checksum), (9037, 7, false));
        assert_eq!(r.params, ["0.017453", "0.017453", "0"]);
        assert_eq!(parse_request("\n%R1Q,0,0:").expect("null proc").params, Vec::<String>::new());
        let reply = parse_reply("%R1P,0,9:0,1.2345678901,1.5012345678,12.3456\r\n").expect("reply");
        assert_eq!((reply.com, reply.transaction, reply.rc), (ReturnCode::Ok, 9, ReturnCode::Ok));
        assert_eq!(reply.double(2), Ok(12.3456));
        assert!(reply.double(3).is_err());
        let angles_only = parse_reply("%R1P,0,9:1285,1.2345678901,1.5012345678,0.0000").expect("reply");
        assert_eq!(angles_only.rc, ReturnCode::AnglesOnly);
        assert!(!angles_only.rc.values_valid());
        assert_eq!(parse_reply("%R1P,0,7:8710").expect("reply").rc, ReturnCode::NoTarget);
        let line = format_request(2108, 9, &[Param::Int(5000), Param::Int(1)], false);
        assert_eq!(line, "%R1Q,2108,9:5000,1\r\n");
        let with = format_request(5004, 3, &[], true);
        let parsed = parse_request(&with).expect("checksummed request");
        assert!(parsed.checksum && parsed.rpc == 5004);
        assert_eq!(parse_reply("%R1P,0,4:0,\"TS30\"").expect("name").values, ["TS30"]);
    }

    #[test]
    fn malformed_and_corrupted_lines_are_named() {
        for bad in ["%R1P,0,9", "R1P,0,9:0", "%R1P,x,9:0", "%R1P,0:0", "%R1P,0,9:", "%R1P,0,9,1,2:0", "%R1P,0,9:abc"] {
            assert!(matches!(parse_reply(bad), Err(ProtocolError::Malformed { .. })), "{bad}");
        }
        assert!(matches!(
            parse_reply("%R1P,0,11,22897:0"),
            Err(ProtocolError::Checksum { received: 22897, computed: 22896, .. })
        ));
        assert_eq!(ReturnCode::from_code(8711).to_string(), "several prisms in the ATR's view (8711)");
        assert_eq!(ReturnCode::from_code(4242), ReturnCode::Other(4242));
    }
}
