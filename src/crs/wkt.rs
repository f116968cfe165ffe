//! Reading a WKT (OGC well-known text, versions 1 and 2) as far as `info` and the CRS checks
//! need: the outermost object's name and EPSG code, the vertical component's code, and the
//! linear units of the horizontal and the vertical systems.
//!
//! The text is parsed into a tree of keywords with their bracketed items; no part of the
//! projection is interpreted. A horizontal system's unit is the `UNIT`, `LENGTHUNIT` or
//! `ANGLEUNIT` that is its own item (WKT 1, and WKT 2's unit of the whole coordinate system)
//! or that of its first `AXIS` (WKT 2 per axis), never one deeper down (the base geographic
//! system's degrees, a datum's). A compound system (`COMPD_CS`, `COMPOUNDCRS`) has its
//! horizontal and its vertical component; a projected system with a `VERTCS` among its items (as
//! some LAS writers nest it) has that as its vertical one.

use super::Unit;

/// A node of the WKT tree: a keyword with its items, a quoted text, or a bare word (a number,
/// an enumeration like `EAST`).
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Wkt {
    Node(String, Vec<Wkt>),
    Text(String),
    Word(String),
}

/// Nesting deeper than this is refused (a damaged or hostile VLR cannot overflow the stack).
const DEPTH: usize = 64;

/// The tree of `text`, `None` when it is not WKT.
pub(super) fn parse(text: &str) -> Option<Wkt> {
    let chars: Vec<char> = text.chars().collect();
    let mut at = 0;
    let node = item(&chars, &mut at, 0)?;
    matches!(node, Wkt::Node(..)).then_some(node)
}

fn skip_space(chars: &[char], at: &mut usize) {
    while *at < chars.len() && chars[*at].is_whitespace() {
        *at += 1;
    }
}

fn item(chars: &[char], at: &mut usize, depth: usize) -> Option<Wkt> {
    if depth > DEPTH {
        return None;
    }
    skip_space(chars, at);
    if chars.get(*at) == Some(&'"') {
        // A quoted text; WKT 2 doubles a quote inside it.
        let mut text = String::new();
        *at += 1;
        loop {
            match chars.get(*at)? {
                '"' if chars.get(*at + 1) == Some(&'"') => {
                    text.push('"');
                    *at += 2;
                }
                '"' => {
                    *at += 1;
                    return Some(Wkt::Text(text));
                }
                c => {
                    text.push(*c);
                    *at += 1;
                }
            }
        }
    }
    let start = *at;
    while *at < chars.len() && !matches!(chars[*at], '[' | '(' | ']' | ')' | ',' | '"') {
        *at += 1;
    }
    let word: String = chars[start..*at]
        .iter()
        .collect::<String>()
        .trim()
        .to_string();
    skip_space(chars, at);
    if !matches!(chars.get(*at), Some('[' | '(')) {
        return (!word.is_empty()).then_some(Wkt::Word(word));
    }
    *at += 1;
    let mut items = Vec::new();
    loop {
        skip_space(chars, at);
        if matches!(chars.get(*at), Some(']' | ')')) {
            *at += 1;
            return Some(Wkt::Node(word.to_ascii_uppercase(), items));
        }
        items.push(item(chars, at, depth + 1)?);
        skip_space(chars, at);
        match chars.get(*at)? {
            ',' => *at += 1,
            ']' | ')' => {}
            _ => return None,
        }
    }
}

impl Wkt {
    fn keyword(&self) -> Option<&str> {
        match self {
            Wkt::Node(k, _) => Some(k),
            _ => None,
        }
    }

    fn items(&self) -> &[Wkt] {
        match self {
            Wkt::Node(_, items) => items,
            _ => &[],
        }
    }

    /// The node's name: its first item, when that is a quoted text.
    pub(super) fn name(&self) -> Option<String> {
        match self.items().first() {
            Some(Wkt::Text(t)) => Some(t.clone()),
            _ => None,
        }
    }

    /// The EPSG code of the node's own `AUTHORITY["EPSG","n"]` or `ID["EPSG",n]`.
    fn own_epsg(&self) -> Option<u32> {
        self.items().iter().find_map(|i| {
            let (Some("AUTHORITY" | "ID"), [Wkt::Text(a), code, ..]) = (i.keyword(), i.items())
            else {
                return None;
            };
            let code = match code {
                Wkt::Text(t) | Wkt::Word(t) => t.trim().parse().ok(),
                Wkt::Node(..) => None,
            };
            code.filter(|_| a.eq_ignore_ascii_case("EPSG"))
        })
    }

    fn is_compound(&self) -> bool {
        matches!(self.keyword(), Some("COMPD_CS" | "COMPOUNDCRS"))
    }

    fn is_vertical(&self) -> bool {
        matches!(
            self.keyword(),
            Some("VERT_CS" | "VERTCS" | "VERTCRS" | "VERTICALCRS")
        )
    }

    fn is_crs(&self) -> bool {
        matches!(
            self.keyword(),
            Some(
                "PROJCS"
                    | "GEOGCS"
                    | "GEOCCS"
                    | "PROJCRS"
                    | "PROJECTEDCRS"
                    | "GEOGCRS"
                    | "GEOGRAPHICCRS"
                    | "GEODCRS"
                    | "GEODETICCRS"
            )
        )
    }

    /// The horizontal system: the node itself, or a compound's first component that is not
    /// vertical.
    pub(super) fn horizontal(&self) -> Option<&Wkt> {
        match self.is_compound() {
            true => self.items().iter().find(|i| i.is_crs()),
            false => Some(self),
        }
    }

    /// The vertical system: a compound's vertical component, or one nested among a projected
    /// system's items.
    pub(super) fn vertical(&self) -> Option<&Wkt> {
        fn within(n: &Wkt) -> Option<&Wkt> {
            n.items().iter().find(|i| i.is_vertical())
        }
        match self.is_compound() {
            true => within(self).or_else(|| self.horizontal().and_then(within)),
            false => within(self),
        }
    }

    /// The system's EPSG code: its own, or a compound's horizontal component's.
    pub(super) fn epsg(&self) -> Option<u32> {
        self.own_epsg().or_else(|| match self.is_compound() {
            true => self.horizontal().and_then(Wkt::own_epsg),
            false => None,
        })
    }

    /// The vertical component's EPSG code.
    pub(super) fn vertical_epsg(&self) -> Option<u32> {
        self.vertical().and_then(Wkt::own_epsg)
    }

    /// The unit of this system's coordinates (module docs).
    pub(super) fn unit(&self) -> Option<Unit> {
        let unit_of = |n: &Wkt| {
            n.items()
                .iter()
                .find_map(|i| match (i.keyword(), i.items()) {
                    (Some("UNIT" | "LENGTHUNIT" | "ANGLEUNIT"), [Wkt::Text(name), factor, ..]) => {
                        let factor = match factor {
                            Wkt::Word(w) => w.parse().ok(),
                            _ => None,
                        };
                        Some(Unit::of_wkt(name, factor))
                    }
                    _ => None,
                })
        };
        unit_of(self).or_else(|| {
            self.items()
                .iter()
                .find(|i| i.keyword() == Some("AXIS"))
                .and_then(unit_of)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_a_compound_system_and_its_units() {
        let text = r#"COMPD_CS["A + B",PROJCS["A",GEOGCS["G",UNIT["degree",0.0174532925199433]],
            UNIT["metre",1,AUTHORITY["EPSG","9001"]],AUTHORITY["EPSG","2991"]],
            VERT_CS["B",UNIT["US survey foot",0.304800609601219],AUTHORITY["EPSG","6360"]]]"#;
        let w = parse(text).unwrap();
        assert_eq!(w.name().as_deref(), Some("A + B"));
        assert_eq!((w.epsg(), w.vertical_epsg()), (Some(2991), Some(6360)));
        assert_eq!(w.horizontal().unwrap().unit(), Some(Unit::Metre));
        assert_eq!(w.vertical().unwrap().unit(), Some(Unit::UsSurveyFoot));
    }

    #[test]
    fn reads_wkt2_units_per_axis_and_refuses_what_is_not_wkt() {
        let text = r#"PROJCRS["P",BASEGEOGCRS["G",ANGLEUNIT["degree",0.0174532925199433]],
            CS[Cartesian,2],AXIS["easting (E)",east,LENGTHUNIT["US survey foot",0.30480060960121924]],
            ID["EPSG",2903]]"#;
        let w = parse(text).unwrap();
        assert_eq!(w.epsg(), Some(2903));
        assert_eq!(w.unit(), Some(Unit::UsSurveyFoot));
        assert!(parse("not wkt").is_none());
        assert!(parse(&"A[".repeat(100)).is_none());
        assert!(parse("A[\"unterminated").is_none());
    }
}
