//! The coordinate reference system a cloud's coordinates are in, as the
//! files carry it: OGC WKT (version 1, as LAS 1.4 and most readers take
//! it), with the EPSG code when there is one. An EPSG code is looked up in
//! the EPSG definitions of the `crs-definitions` crate; a site without one
//! is a named local engineering frame (`LOCAL_CS`), which says honestly that
//! the coordinates are not georeferenced.

/// A coordinate reference system in metres.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Crs {
    /// Its name: `EPSG:25832`, the WKT's own name, or the local frame's.
    pub name: String,
    /// The EPSG code, when it has one.
    pub epsg: Option<u16>,
    /// Its definition, OGC WKT 1 on one line.
    pub wkt: String,
}

/// WKT keywords of the CRS kinds we accept (coordinates in metres).
const METRIC_KINDS: [&str; 5] = ["PROJCS", "LOCAL_CS", "PROJCRS", "ENGCRS", "ENGINEERINGCRS"];

impl Crs {
    /// Reads `text`: `EPSG:NNNN` (any case) or a WKT definition of a
    /// projected or local engineering CRS. The error says what was found
    /// and what was expected.
    pub fn parse(text: &str) -> Result<Self, String> {
        let text = text.trim();
        if let Some(code) = text.strip_prefix("EPSG:").or_else(|| text.strip_prefix("epsg:")) {
            let code: u16 = code.trim().parse().map_err(|_| {
                format!("\"{text}\": expected EPSG:NNNN with a code from 1024 to 32767, or a WKT definition")
            })?;
            let def = crs_definitions::from_code(code)
                .ok_or_else(|| format!("EPSG:{code} is not in the EPSG definitions this build carries"))?;
            let crs = Self { name: format!("EPSG:{code}"), epsg: Some(code), wkt: def.wkt.to_string() };
            return crs.metric().map(|()| crs);
        }
        let kind: String = text.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
        if kind.is_empty() || !text[kind.len()..].trim_start().starts_with('[') {
            return Err(format!(
                "\"{}\": expected EPSG:NNNN or a WKT definition (PROJCS[…], LOCAL_CS[…], …)",
                shorten(text)
            ));
        }
        balanced(text)?;
        let name = first_quoted(text).unwrap_or_else(|| kind.clone());
        let epsg = authority_code(text);
        let crs = Self { name, epsg, wkt: text.split_whitespace().collect::<Vec<_>>().join(" ") };
        crs.metric().map(|()| crs)
    }

    /// A local engineering frame named `name`: metres, x east, y north,
    /// z up, tied to nothing.
    pub fn local(name: &str) -> Self {
        let quoted = name.replace('"', "'");
        Self {
            name: name.to_string(),
            epsg: None,
            wkt: format!(
                "LOCAL_CS[\"{quoted}\",LOCAL_DATUM[\"{quoted}\",0],UNIT[\"metre\",1],\
                 AXIS[\"X\",EAST],AXIS[\"Y\",NORTH],AXIS[\"Z\",UP]]"
            ),
        }
    }

    /// Whether this is a local engineering frame rather than a georeferenced CRS.
    pub fn is_local(&self) -> bool {
        self.wkt.starts_with("LOCAL_CS") || self.wkt.starts_with("ENGCRS") || self.wkt.starts_with("ENGINEERINGCRS")
    }

    /// Only CRSs in metres: a geographic CRS (degrees) cannot hold a
    /// survey's metric coordinates.
    fn metric(&self) -> Result<(), String> {
        if METRIC_KINDS.iter().any(|k| self.wkt.starts_with(k)) {
            Ok(())
        } else {
            let kind: String = self.wkt.chars().take_while(|c| *c != '[').collect();
            Err(format!(
                "{} is a {kind} coordinate system: expected a projected (PROJCS) or local engineering (LOCAL_CS) one, \
                 in metres",
                self.name
            ))
        }
    }
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
        assert!(Crs::parse("UTM 32").expect_err("prose").contains("expected EPSG:NNNN or a WKT"));
        assert!(Crs::parse("PROJCS[\"a\",UNIT[\"m\",1]").expect_err("open").contains("unclosed"));
    }

    #[test]
    fn a_local_frame_is_a_local_cs() {
        let crs = Crs::local("Hall \"B\" grid");
        assert!(crs.is_local());
        assert_eq!(crs.name, "Hall \"B\" grid");
        assert!(crs.wkt.starts_with("LOCAL_CS[\"Hall 'B' grid\""));
        assert_eq!(Crs::parse(&crs.wkt).expect("own WKT reads back").wkt, crs.wkt);
    }
}
