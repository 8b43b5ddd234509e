//! The coordinate reference system a cloud's coordinates are in, as the
//! files carry it: OGC WKT version 1 (as LAS 1.4 refers to it, and as GDAL
//! and PROJ read it), with the EPSG code when there is one. An EPSG code is
//! looked up in the EPSG definitions of the `crs-definitions` crate and
//! written as GDAL ≥ 3 exports it (no `TOWGS84` clause, which would make
//! PROJ read a bound CRS and find no code); `EPSG:H+V` joins a projected
//! CRS and a vertical one into a compound CRS. A site without a CRS is a
//! named local engineering frame (`LOCAL_CS` with two axes, the form GDAL
//! and PROJ before 9.4 parse), which says honestly that the coordinates are
//! not georeferenced. Coordinates are metres: a CRS in any other unit is
//! refused, never written as metres that readers would take as feet.

/// A coordinate reference system in metres.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Crs {
    /// Its name: `EPSG:25832`, `EPSG:25832+7837`, the WKT's own name, or
    /// the local frame's.
    pub name: String,
    /// The EPSG code, when it has one.
    pub epsg: Option<u16>,
    /// Its definition, OGC WKT 1 on one line.
    pub wkt: String,
}

/// The longest WKT definition taken.
const MAX_WKT_BYTES: usize = 64 * 1024;

/// Unicode's bidirectional controls: they make a name read differently
/// from what it holds (`hall\u{202e}gnp.exe` shows as `hallexe.png`).
pub fn is_bidi_control(c: char) -> bool {
    matches!(c, '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}' | '\u{200e}' | '\u{200f}' | '\u{061c}')
}

/// WKT keywords of the CRS kinds we accept (coordinates in metres).
const METRIC_KINDS: [&str; 6] = ["PROJCS", "LOCAL_CS", "COMPD_CS", "PROJCRS", "ENGCRS", "ENGINEERINGCRS"];

impl Crs {
    /// Reads `text`: `EPSG:NNNN` (any case), `EPSG:H+V` (a projected and a
    /// vertical CRS), or a WKT definition of a projected, compound or local
    /// engineering CRS. The error says what was found and what was expected.
    pub fn parse(text: &str) -> Result<Self, String> {
        let text = text.trim();
        if let Some(codes) = text.strip_prefix("EPSG:").or_else(|| text.strip_prefix("epsg:")) {
            let crs = match codes.split_once('+') {
                None => {
                    let code = epsg_code(text, codes)?;
                    Self { name: format!("EPSG:{code}"), epsg: Some(code), wkt: epsg_wkt(code)? }
                }
                Some((h, v)) => compound(text, epsg_code(text, h)?, epsg_code(text, v)?)?,
            };
            return crs.metric().map(|()| crs);
        }
        let kind: String = text.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
        if kind.is_empty() || !text[kind.len()..].trim_start().starts_with('[') {
            return Err(format!(
                "\"{}\": expected EPSG:NNNN, EPSG:H+V or a WKT definition (PROJCS[…], COMPD_CS[…], LOCAL_CS[…], …)",
                shorten(text)
            ));
        }
        if text.len() > MAX_WKT_BYTES {
            return Err(format!(
                "a WKT definition of {} bytes: expected at most {MAX_WKT_BYTES} (an EPSG definition has a few thousand)",
                text.len()
            ));
        }
        balanced(text)?;
        // Line breaks and tabs are layout (folded below); any other control
        // character would end up in file headers (a PLY header ended early).
        if let Some(c) = text.chars().find(|c| c.is_control() && !c.is_whitespace() || is_bidi_control(*c)) {
            return Err(format!("a WKT definition holding {c:?}: expected printable text"));
        }
        let name = first_quoted(text).unwrap_or_else(|| kind.clone());
        let epsg = authority_code(text);
        let crs = Self { name, epsg, wkt: text.split_whitespace().collect::<Vec<_>>().join(" ") };
        crs.metric()?;
        crs.structure()?;
        Ok(crs)
    }

    /// Checks a local frame's name: printable text on one line (it goes
    /// into file headers and comments), at most 200 bytes.
    pub fn check_local_name(name: &str) -> Result<(), String> {
        if let Some(c) = name.chars().find(|c| c.is_control() || is_bidi_control(*c)) {
            return Err(format!(
                "\"{}\" holds {c:?}: expected a name on one line without control characters",
                name.escape_debug()
            ));
        }
        if name.len() > 200 {
            return Err(format!("a name of {} bytes: expected at most 200", name.len()));
        }
        Ok(())
    }

    /// The nodes each kind of CRS must hold (OGC 01-009): a WKT that only
    /// looks like one (`PROJCS["x",AAAA…]`) would be written into every
    /// deliverable and refused by every reader.
    fn structure(&self) -> Result<(), String> {
        let required: &[(&str, &[&str])] = &[
            ("PROJCS", &["GEOGCS", "PROJECTION", "UNIT"]),
            ("LOCAL_CS", &["LOCAL_DATUM", "UNIT"]),
            ("VERT_CS", &["VERT_DATUM", "UNIT"]),
            ("GEOGCS", &["DATUM", "PRIMEM", "UNIT"]),
        ];
        let mut stack = vec![self.wkt.as_str()];
        while let Some(node) = stack.pop() {
            let kind = keyword(node);
            let children: Vec<&str> = top_level(node).into_iter().filter(|c| c.contains('[')).collect();
            let kinds: Vec<String> = children.iter().map(|c| keyword(c)).collect();
            if let Some((_, needs)) = required.iter().find(|(k, _)| *k == kind)
                && let Some(missing) = needs.iter().find(|n| !kinds.iter().any(|k| k == *n))
            {
                return Err(format!(
                    "{}: its {kind}[…] has no {missing}[…]: expected {} (OGC WKT 1)",
                    self.name,
                    needs.iter().map(|n| format!("{n}[…]")).collect::<Vec<_>>().join(", ")
                ));
            }
            if matches!(kind.as_str(), "PROJCS" | "COMPD_CS") {
                stack.extend(
                    children.into_iter().filter(|c| matches!(keyword(c).as_str(), "GEOGCS" | "PROJCS" | "VERT_CS")),
                );
            }
        }
        Ok(())
    }

    /// A local engineering frame named `name`: metres, x east, y north
    /// (z up), tied to nothing. WKT 1 `LOCAL_CS` with two axes: GDAL and
    /// PROJ before 9.4 refuse three ("buildCS: unexpected AXIS count").
    pub fn local(name: &str) -> Self {
        let quoted = name.replace('"', "'");
        Self {
            name: name.to_string(),
            epsg: None,
            wkt: format!(
                "LOCAL_CS[\"{quoted}\",LOCAL_DATUM[\"{quoted}\",0],UNIT[\"metre\",1],AXIS[\"X\",EAST],AXIS[\"Y\",NORTH]]"
            ),
        }
    }

    /// Whether this is a local engineering frame rather than a georeferenced CRS.
    pub fn is_local(&self) -> bool {
        self.wkt.starts_with("LOCAL_CS") || self.wkt.starts_with("ENGCRS") || self.wkt.starts_with("ENGINEERINGCRS")
    }

    /// Whether it states the heights' datum (a compound CRS).
    pub fn is_compound(&self) -> bool {
        self.wkt.starts_with("COMPD_CS") || self.wkt.starts_with("COMPOUNDCRS")
    }

    /// Only CRSs in metres: a geographic CRS (degrees) cannot hold a
    /// survey's metric coordinates, and one in feet would read our metres
    /// as feet.
    fn metric(&self) -> Result<(), String> {
        if !METRIC_KINDS.iter().any(|k| self.wkt.starts_with(k)) {
            let kind: String = self.wkt.chars().take_while(|c| *c != '[').collect();
            return Err(format!(
                "{} is a {kind} coordinate system: expected a projected (PROJCS), compound (COMPD_CS) or local \
                 engineering (LOCAL_CS) one, in metres",
                self.name
            ));
        }
        if self.wkt.starts_with("COMPD_CS") {
            let kinds: Vec<String> = top_level(&self.wkt)
                .into_iter()
                .filter(|item| item.contains('['))
                .map(keyword)
                .filter(|k| k != "AUTHORITY")
                .collect();
            if kinds != ["PROJCS", "VERT_CS"] {
                return Err(format!(
                    "{} is a compound CRS of {}: expected a projected CRS (PROJCS) and a vertical one (VERT_CS)",
                    self.name,
                    kinds.join(" + ")
                ));
            }
        }
        match foreign_unit(&self.wkt) {
            None => Ok(()),
            Some((unit, factor)) => Err(format!(
                "{} has its coordinates in {unit} ({factor} m): cps-survey computes and writes metres, which \
                 readers would take as {unit}; choose the CRS's metric variant (or a local frame)",
                self.name
            )),
        }
    }
}

/// The code of `EPSG:code` (`text` for the error).
fn epsg_code(text: &str, code: &str) -> Result<u16, String> {
    code.trim().parse().map_err(|_| {
        format!("\"{text}\": expected EPSG:NNNN (a code from 1024 to 32767), EPSG:H+V, or a WKT definition")
    })
}

/// The WKT of EPSG `code` as GDAL ≥ 3 exports it: without `TOWGS84`.
fn epsg_wkt(code: u16) -> Result<String, String> {
    let def = crs_definitions::from_code(code)
        .ok_or_else(|| format!("EPSG:{code} is not in the EPSG definitions this build carries"))?;
    Ok(without_towgs84(def.wkt))
}

/// `EPSG:H+V`: the projected CRS `h` with the vertical CRS `v`, which is
/// taken from a compound definition that carries it (the definitions hold
/// no vertical CRS on its own).
fn compound(text: &str, h: u16, v: u16) -> Result<Crs, String> {
    let horizontal = epsg_wkt(h)?;
    if !horizontal.starts_with("PROJCS") {
        return Err(format!("\"{text}\": EPSG:{h} is not a projected CRS: expected EPSG:H+V with H projected"));
    }
    let tag = format!("AUTHORITY[\"EPSG\",\"{v}\"]]");
    let vertical = (1024..=32767)
        .filter_map(crs_definitions::from_code)
        .filter(|d| d.wkt.starts_with("COMPD_CS"))
        .find_map(|d| top_level(d.wkt).into_iter().find(|c| c.starts_with("VERT_CS[") && c.ends_with(&tag)))
        .ok_or_else(|| {
            format!("\"{text}\": EPSG:{v} is not a vertical CRS in the EPSG definitions this build carries")
        })?;
    let name = |wkt: &str| first_quoted(wkt).unwrap_or_default();
    Ok(Crs {
        name: format!("EPSG:{h}+{v}"),
        epsg: None,
        wkt: format!("COMPD_CS[\"{} + {}\",{horizontal},{vertical}]", name(&horizontal), name(vertical)),
    })
}

/// `wkt` without its `TOWGS84[…]` clauses.
fn without_towgs84(wkt: &str) -> String {
    let mut out = String::with_capacity(wkt.len());
    let mut rest = wkt;
    while let Some(at) = rest.find(",TOWGS84[") {
        out.push_str(&rest[..at]);
        rest = &rest[at + 1..];
        rest = rest.find(']').map_or("", |end| &rest[end + 1..]);
    }
    out.push_str(rest);
    out
}

/// The comma-separated items directly inside a WKT node's brackets.
fn top_level(wkt: &str) -> Vec<&str> {
    let Some(open) = wkt.find('[') else { return Vec::new() };
    let (mut depth, mut quoted, mut from, mut items) = (0usize, false, open + 1, Vec::new());
    for (i, c) in wkt.char_indices().skip_while(|(i, _)| *i <= open) {
        match c {
            '"' => quoted = !quoted,
            '[' | '(' if !quoted => depth += 1,
            ']' | ')' if !quoted && depth == 0 => {
                items.push(wkt[from..i].trim());
                break;
            }
            ']' | ')' if !quoted => depth -= 1,
            ',' if !quoted && depth == 0 => {
                items.push(wkt[from..i].trim());
                from = i + 1;
            }
            _ => {}
        }
    }
    items
}

/// A WKT node's keyword.
fn keyword(node: &str) -> String {
    node.chars().take_while(|c| *c != '[').collect::<String>().trim().to_string()
}

/// The first linear unit of the coordinates that is not the metre: a
/// projected CRS's own `UNIT` (not its geographic CRS's degrees), a
/// vertical or local CRS's, or a WKT 2 `LENGTHUNIT`.
fn foreign_unit(wkt: &str) -> Option<(String, f64)> {
    let mut units = Vec::new();
    let mut stack = vec![wkt];
    while let Some(node) = stack.pop() {
        let kind = keyword(node);
        for child in top_level(node) {
            match keyword(child).as_str() {
                "UNIT" if matches!(kind.as_str(), "PROJCS" | "VERT_CS" | "LOCAL_CS") => units.push(child),
                "LENGTHUNIT" => units.push(child),
                "PROJCS" | "VERT_CS" | "LOCAL_CS" | "COMPD_CS" | "PROJCRS" | "ENGCRS" | "ENGINEERINGCRS"
                | "VERTCRS" | "COMPOUNDCRS" | "AXIS" => stack.push(child),
                _ => {}
            }
        }
    }
    units.into_iter().find_map(|unit| {
        let items = top_level(unit);
        let name = items.first()?.trim_matches('"').to_string();
        let factor: f64 = items.get(1)?.parse().ok()?;
        ((factor - 1.0).abs() > 1e-12).then_some((name, factor))
    })
}

/// Brackets and quotes that close, or where they do not.
fn balanced(text: &str) -> Result<(), String> {
    let (mut depth, mut quoted) = (0i64, false);
    for (i, c) in text.char_indices() {
        match c {
            '"' => quoted = !quoted,
            '[' | '(' if !quoted => depth += 1,
            ']' | ')' if !quoted => {
                depth -= 1;
                if depth < 0 {
                    return Err(format!("WKT: unmatched `{c}` at character {i}"));
                }
            }
            _ => {}
        }
    }
    if quoted || depth != 0 {
        return Err(format!(
            "WKT: {} unclosed bracket(s){}",
            depth,
            if quoted { " and an unclosed quote" } else { "" }
        ));
    }
    Ok(())
}

/// The first quoted string (a WKT's name).
fn first_quoted(text: &str) -> Option<String> {
    let start = text.find('"')? + 1;
    let len = text[start..].find('"')?;
    Some(text[start..start + len].to_string())
}

/// The last `AUTHORITY["EPSG","N"]` or `ID["EPSG",N]` (the CRS's own).
fn authority_code(text: &str) -> Option<u16> {
    ["AUTHORITY[\"EPSG\",", "ID[\"EPSG\","].iter().find_map(|tag| {
        let at = text.rfind(tag)? + tag.len();
        let rest = text[at..].trim_start_matches('"');
        rest.split(|c: char| !c.is_ascii_digit()).next()?.parse().ok()
    })
}

fn shorten(text: &str) -> String {
    let mut s: String = text.chars().take(40).collect();
    if text.chars().count() > 40 {
        s.push('…');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epsg_codes_resolve_to_their_wkt() {
        let crs = Crs::parse("EPSG:25832").expect("UTM 32N");
        assert_eq!(crs.epsg, Some(25832));
        assert!(crs.wkt.starts_with("PROJCS[\"ETRS89 / UTM zone 32N\""), "{}", crs.wkt);
        assert!(crs.wkt.ends_with("AUTHORITY[\"EPSG\",\"25832\"]]"), "{}", crs.wkt);
        assert!(!crs.is_local());
    }

    #[test]
    fn wkt_keeps_its_name_and_code() {
        let wkt = crs_definitions::from_code(31467).expect("GK3").wkt;
        let crs = Crs::parse(&format!("  {wkt}\n")).expect("WKT");
        assert_eq!(crs.name, "DHDN / 3-degree Gauss-Kruger zone 3");
        assert_eq!(crs.epsg, Some(31467));
        assert_eq!(crs.wkt, wkt);
    }

    #[test]
    fn refuses_what_is_not_a_metric_crs() {
        let degrees = Crs::parse("EPSG:4326").expect_err("geographic");
        assert!(degrees.contains("GEOGCS") && degrees.contains("metres"), "{degrees}");
        assert!(Crs::parse("EPSG:x").expect_err("code").contains("EPSG:NNNN"));
        assert!(Crs::parse("EPSG:1").expect_err("unknown").contains("EPSG:1 is not"));
        assert!(Crs::parse("UTM 32").expect_err("prose").contains("expected EPSG:NNNN, EPSG:H+V or a WKT"));
        assert!(Crs::parse("PROJCS[\"a\",UNIT[\"m\",1]").expect_err("open").contains("unclosed"));
    }

    /// GDAL ≥ 3 exports EPSG CRSs without TOWGS84 (PROJ then reads a
    /// bound CRS and finds no code); neither a null nor a real one is kept.
    #[test]
    fn epsg_wkt_carries_no_towgs84() {
        for code in ["EPSG:25832", "EPSG:7415", "EPSG:31467", "EPSG:5555"] {
            let crs = Crs::parse(code).expect(code);
            assert!(!crs.wkt.contains("TOWGS84"), "{code}: {}", crs.wkt);
            balanced(&crs.wkt).expect("still balanced");
            assert_eq!(authority_code(&crs.wkt), crs.epsg, "{code}");
        }
        assert_eq!(without_towgs84("A[B[1,TOWGS84[0,0,0]],C[2,TOWGS84[1,2,3,4,5,6,7]],D]"), "A[B[1],C[2],D]");
    }

    /// A CRS in feet would label our metres as feet: refused, naming the unit.
    #[test]
    fn a_crs_in_feet_is_refused_naming_its_unit() {
        let feet = Crs::parse("EPSG:2263").expect_err("US survey feet");
        assert!(feet.contains("US survey foot") && feet.contains("0.3048006096012192"), "{feet}");
        let intl = Crs::parse("EPSG:2039").map(|c| c.wkt);
        assert!(intl.is_ok(), "Israeli grid, metres: {intl:?}");
        let wkt = crs_definitions::from_code(2263).expect("2263").wkt;
        assert!(Crs::parse(wkt).expect_err("as WKT too").contains("US survey foot"));
        let local_feet =
            "LOCAL_CS[\"site\",LOCAL_DATUM[\"site\",0],UNIT[\"foot\",0.3048],AXIS[\"X\",EAST],AXIS[\"Y\",NORTH]]";
        assert!(Crs::parse(local_feet).expect_err("local feet").contains("foot"));
    }

    /// Compound CRSs state the heights' datum: by code, as `EPSG:H+V`, or as
    /// WKT; a compound of anything but a projected and a vertical CRS is refused.
    #[test]
    fn compound_crss_carry_their_vertical_datum() {
        let nap = Crs::parse("EPSG:7415").expect("RD New + NAP");
        assert!(nap.is_compound() && nap.epsg == Some(7415) && !nap.is_local());
        assert!(nap.wkt.contains("VERT_CS[\"NAP height\""), "{}", nap.wkt);
        let joined = Crs::parse("EPSG:25832+5783").expect("UTM 32N + DHHN92");
        assert_eq!(joined.name, "EPSG:25832+5783");
        assert_eq!(joined.epsg, None);
        assert!(joined.wkt.starts_with("COMPD_CS[\"ETRS89 / UTM zone 32N + DHHN92 height\",PROJCS["), "{}", joined.wkt);
        assert_eq!(keyword(top_level(&joined.wkt)[2]), "VERT_CS");
        assert!(joined.wkt.ends_with("AUTHORITY[\"EPSG\",\"5783\"]]]"), "{}", joined.wkt);
        assert_eq!(Crs::parse(&joined.wkt).expect("reads back").wkt, joined.wkt);
        assert!(Crs::parse("EPSG:4326+5783").expect_err("geographic").contains("not a projected CRS"));
        assert!(Crs::parse("EPSG:25832+25833").expect_err("not vertical").contains("not a vertical CRS"));
        assert!(Crs::parse("EPSG:25832+x").expect_err("code").contains("EPSG:H+V"));
        let geographic = crs_definitions::from_code(4326).expect("4326").wkt;
        let wrong = format!("COMPD_CS[\"x\",{geographic},{}]", top_level(&joined.wkt)[2]);
        assert!(Crs::parse(&wrong).expect_err("GEOGCS + VERT_CS").contains("GEOGCS + VERT_CS"));
    }

    /// Only a WKT with the nodes its kind needs, printable and of a
    /// sensible size, reaches the deliverables.
    #[test]
    fn a_wkt_that_only_looks_like_one_is_refused() {
        let fake = format!("PROJCS[\"x\",{}]", "A".repeat(1000));
        assert!(Crs::parse(&fake).expect_err("no GEOGCS").contains("has no GEOGCS[…]"));
        let huge = format!("PROJCS[\"x\",{}]", "A".repeat(1 << 20));
        assert!(Crs::parse(&huge).expect_err("1 MB").contains("expected at most 65536"));
        let local = "LOCAL_CS[\"a\",UNIT[\"metre\",1]]";
        assert!(Crs::parse(local).expect_err("no datum").contains("has no LOCAL_DATUM[…]"));
        let escape = Crs::local("a").wkt.replace("\"a\"", "\"a\u{1b}[2J\"");
        assert!(Crs::parse(&escape).expect_err("ESC").contains("expected printable text"));
        // Layout is fine: an EPSG WKT spread over lines reads as on one.
        let wkt = Crs::parse("EPSG:25832").expect("UTM").wkt;
        assert_eq!(Crs::parse(&wkt.replace(",", ",\n\t")).expect("multi-line").wkt, wkt.replace(",", ", "));
        assert!(Crs::check_local_name("grid\nend_header").expect_err("newline").contains("on one line"));
        assert!(Crs::check_local_name("grid\u{202e}").is_err());
        assert!(Crs::check_local_name("Hall B grid").is_ok());
    }

    /// Every projected and compound EPSG definition this build carries is
    /// either taken or refused for its unit — none for its structure.
    #[test]
    fn every_epsg_definition_passes_the_structure_check() {
        let (mut taken, mut feet) = (0, 0);
        for code in 1024..=32767u16 {
            let Some(def) = crs_definitions::from_code(code) else { continue };
            if !(def.wkt.starts_with("PROJCS") || def.wkt.starts_with("COMPD_CS")) {
                continue;
            }
            match Crs::parse(&format!("EPSG:{code}")) {
                Ok(crs) => {
                    assert!(crs.structure().is_ok());
                    taken += 1;
                }
                Err(e) if e.contains("has its coordinates in") || e.contains("a compound CRS of") => feet += 1,
                Err(e) => panic!("EPSG:{code}: {e}"),
            }
        }
        assert!(taken > 4000 && feet > 100, "{taken} taken, {feet} refused for their unit or parts");
    }

    #[test]
    fn a_local_frame_is_a_local_cs() {
        let crs = Crs::local("Hall \"B\" grid");
        assert!(crs.is_local());
        assert_eq!(crs.name, "Hall \"B\" grid");
        assert!(crs.wkt.starts_with("LOCAL_CS[\"Hall 'B' grid\""));
        // Two axes: GDAL and PROJ before 9.4 refuse a LOCAL_CS with three.
        assert_eq!(crs.wkt.matches("AXIS[").count(), 2, "{}", crs.wkt);
        assert_eq!(Crs::parse(&crs.wkt).expect("own WKT reads back").wkt, crs.wkt);
    }
}
