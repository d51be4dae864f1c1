//! The PLY header model, shared by every PLY reader and writer: scalar types (the table of
//! their names in both spellings), encodings (the `format` keywords), elements and their
//! properties; parsed from the first bytes of a file by [`parse_header`], written by
//! `write.rs` from the same types.

use std::path::Path;

use crate::error::{Error, Location, Result};

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scalar {
    /// int8
    I8,
    /// uint8
    U8,
    /// int16
    I16,
    /// uint16
    U16,
    /// int32
    I32,
    /// uint32
    U32,
    /// float32
    F32,
    /// float64
    F64,
}

/// The scalar types' names, in the order of [`Scalar`]'s variants: the specification's
/// spelling (the one written), then the sized one (both read).
const SCALAR_NAMES: [(Scalar, &str, &str); 8] = [
    (Scalar::I8, "char", "int8"),
    (Scalar::U8, "uchar", "uint8"),
    (Scalar::I16, "short", "int16"),
    (Scalar::U16, "ushort", "uint16"),
    (Scalar::I32, "int", "int32"),
    (Scalar::U32, "uint", "uint32"),
    (Scalar::F32, "float", "float32"),
    (Scalar::F64, "double", "float64"),
];

impl Scalar {
    /// Parse a type name in either spelling.
    pub fn parse(s: &str) -> Option<Scalar> {
        SCALAR_NAMES
            .iter()
            .find(|&&(_, name, sized)| s == name || s == sized)
            .map(|&(ty, _, _)| ty)
    }

    /// The type's name as written: the specification's spelling (`char` … `double`).
    pub fn name(self) -> &'static str {
        SCALAR_NAMES[self as usize].1
    }

    /// Size in bytes.
    pub fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// Decode one value from the start of `b`.
    #[inline(always)]
    pub fn read(self, b: &[u8], big_endian: bool) -> f64 {
        macro_rules! rd {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                (if big_endian {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => rd!(i16, 2),
            Scalar::U16 => rd!(u16, 2),
            Scalar::I32 => rd!(i32, 4),
            Scalar::U32 => rd!(u32, 4),
            Scalar::F32 => rd!(f32, 4),
            Scalar::F64 => rd!(f64, 8),
        }
    }

    /// Whether the type is `float` or `double`.
    pub fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Largest value of an integer type (used to scale colours); 1 for floats.
    pub(super) fn full_scale(self) -> f64 {
        match self {
            Scalar::I8 => 127.0,
            Scalar::U8 => 255.0,
            Scalar::I16 => 32767.0,
            Scalar::U16 => 65535.0,
            Scalar::I32 => i32::MAX as f64,
            Scalar::U32 => u32::MAX as f64,
            Scalar::F32 | Scalar::F64 => 1.0,
        }
    }
}

/// A property of an element.
#[derive(Debug, Clone, PartialEq)]
pub enum Property {
    /// A scalar.
    Scalar {
        /// Name.
        name: String,
        /// Type.
        ty: Scalar,
    },
    /// A list: a count, then that many items.
    List {
        /// Name.
        name: String,
        /// Type of the count.
        count: Scalar,
        /// Type of the items.
        item: Scalar,
    },
}

impl Property {
    /// A scalar property (of an element to be written).
    pub fn scalar(ty: Scalar, name: &str) -> Property {
        Property::Scalar {
            name: name.to_string(),
            ty,
        }
    }

    /// A list property (of an element to be written).
    pub fn list(count: Scalar, item: Scalar, name: &str) -> Property {
        Property::List {
            name: name.to_string(),
            count,
            item,
        }
    }

    /// The property's name.
    pub fn name(&self) -> &str {
        match self {
            Property::Scalar { name, .. } | Property::List { name, .. } => name,
        }
    }
}

/// An element declaration.
#[derive(Debug, Clone, PartialEq)]
pub struct Element {
    /// Name.
    pub name: String,
    /// Number of records.
    pub count: u64,
    /// Properties in file order.
    pub props: Vec<Property>,
    /// Header line (1-based) that declared it; 0 for an element to be written.
    pub line: u64,
}

impl Element {
    /// An element to be written: `count` records of properties `props`.
    pub fn new(name: &str, count: u64, props: Vec<Property>) -> Element {
        Element {
            name: name.to_string(),
            count,
            props,
            line: 0,
        }
    }

    /// Size of one record when it has no list, in bytes.
    pub fn fixed_size(&self) -> Option<u64> {
        let mut s = 0u64;
        for p in &self.props {
            match p {
                Property::Scalar { ty, .. } => s += ty.size() as u64,
                Property::List { .. } => return None,
            }
        }
        Some(s)
    }
}

/// The storage format line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// Text.
    Ascii,
    /// Binary little endian.
    BinaryLe,
    /// Binary big endian.
    BinaryBe,
}

/// The encodings' keywords on the `format` line.
const ENCODING_KEYWORDS: [(Encoding, &str); 3] = [
    (Encoding::Ascii, "ascii"),
    (Encoding::BinaryLe, "binary_little_endian"),
    (Encoding::BinaryBe, "binary_big_endian"),
];

impl Encoding {
    /// The encoding of a `format` line's keyword.
    pub fn parse(s: &str) -> Option<Encoding> {
        ENCODING_KEYWORDS
            .iter()
            .find(|&&(_, k)| k == s)
            .map(|&(e, _)| e)
    }

    /// The keyword of the `format` line (`ascii`, `binary_little_endian`,
    /// `binary_big_endian`).
    pub fn keyword(self) -> &'static str {
        ENCODING_KEYWORDS[self as usize].1
    }

    /// Whether binary values are stored big endian.
    pub fn big_endian(self) -> bool {
        self == Encoding::BinaryBe
    }
}

/// A parsed PLY header.
#[derive(Debug, Clone, PartialEq)]
pub struct PlyHeader {
    /// Storage format.
    pub encoding: Encoding,
    /// Elements in file order.
    pub elements: Vec<Element>,
    /// Byte offset of the first byte after `end_header\n`.
    pub data_start: u64,
    /// Number of header lines, `end_header` included.
    pub lines: u64,
    /// The `obj_info` lines, in order: the header line (1-based) and the words after the
    /// keyword, joined by single spaces (a range scan's `num_cols 640`, say).
    pub obj_info: Vec<(u64, String)>,
}

/// Parse a header from the first bytes of a file. `bytes` may be longer than the header.
pub fn parse_header(path: &Path, bytes: &[u8]) -> Result<PlyHeader> {
    let mut pos = 0usize;
    let mut line_no = 0u64;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut obj_info = Vec::new();
    loop {
        let Some(nl) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(Error::format(
                path,
                Location::Byte(bytes.len() as u64),
                format!(
                    "PLY header has no end_header line (read {} header lines, then the {})",
                    line_no,
                    if bytes.len() >= HEADER_LIMIT {
                        "header size limit of 1 MiB"
                    } else {
                        "end of the file"
                    }
                ),
            ));
        };
        let raw = &bytes[pos..pos + nl];
        let line_start = pos;
        pos += nl + 1;
        line_no += 1;
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        let Ok(line) = std::str::from_utf8(raw) else {
            return Err(Error::format(
                path,
                Location::Line(line_no),
                format!("PLY header line is not text (byte {line_start})"),
            ));
        };
        let toks: Vec<&str> = line.split_ascii_whitespace().collect();
        let bad = |msg: String| Error::format(path, Location::Line(line_no), msg);
        if line_no == 1 {
            if line.trim_end() != "ply" {
                return Err(Error::format(
                    path,
                    Location::Byte(0),
                    "not a PLY file: the first line must be \"ply\"",
                ));
            }
            continue;
        }
        match toks.first().copied() {
            None => continue,
            Some("comment") => continue,
            Some("obj_info") => obj_info.push((line_no, toks[1..].join(" "))),
            Some("format") => encoding = Some(parse_format(&toks, line, &bad)?),
            Some("element") => elements.push(parse_element(&toks, line, line_no, &bad)?),
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(bad("property before any element".into()));
                };
                let prop = parse_property(&toks, line, &bad)?;
                if el.props.iter().any(|q| q.name() == prop.name()) {
                    return Err(bad(format!(
                        "property \"{}\" declared twice in element \"{}\"",
                        prop.name(),
                        el.name
                    )));
                }
                el.props.push(prop);
            }
            Some("end_header") => break,
            Some(other) => {
                return Err(bad(format!("unknown PLY header keyword \"{other}\"")));
            }
        }
    }
    let Some(encoding) = encoding else {
        return Err(Error::format(
            path,
            Location::Line(2),
            "PLY header has no format line",
        ));
    };
    Ok(PlyHeader {
        encoding,
        elements,
        data_start: pos as u64,
        lines: line_no,
        obj_info,
    })
}

/// Most header bytes read before giving up on finding `end_header`.
pub(super) const HEADER_LIMIT: usize = 1 << 20;

/// The encoding of a `format` line (`toks` its tokens, `bad` makes an error at its line).
fn parse_format(toks: &[&str], line: &str, bad: &dyn Fn(String) -> Error) -> Result<Encoding> {
    if toks.len() != 3 {
        return Err(bad(format!(
            "expected \"format <ascii|binary_little_endian|binary_big_endian> 1.0\", found \"{line}\""
        )));
    }
    Encoding::parse(toks[1]).ok_or_else(|| {
        bad(format!(
            "unknown PLY format \"{}\", expected ascii, binary_little_endian or binary_big_endian",
            toks[1]
        ))
    })
}

/// The element declared by an `element` line at header line `line_no`.
fn parse_element(
    toks: &[&str],
    line: &str,
    line_no: u64,
    bad: &dyn Fn(String) -> Error,
) -> Result<Element> {
    if toks.len() != 3 {
        return Err(bad(format!(
            "expected \"element <name> <count>\", found \"{line}\""
        )));
    }
    let count: u64 = toks[2].parse().map_err(|_| {
        bad(format!(
            "element count \"{}\" is not a non-negative integer",
            toks[2]
        ))
    })?;
    Ok(Element {
        name: toks[1].to_string(),
        count,
        props: Vec::new(),
        line: line_no,
    })
}

/// The property declared by a `property` line (scalar or list).
fn parse_property(toks: &[&str], line: &str, bad: &dyn Fn(String) -> Error) -> Result<Property> {
    let prop = if toks.get(1) == Some(&"list") {
        if toks.len() != 5 {
            return Err(bad(format!(
                "expected \"property list <count type> <item type> <name>\", found \"{line}\""
            )));
        }
        let count = Scalar::parse(toks[2])
            .ok_or_else(|| bad(format!("unknown property type \"{}\"", toks[2])))?;
        if count.is_float() {
            return Err(bad(format!(
                "list count type must be an integer type, found \"{}\"",
                toks[2]
            )));
        }
        let item = Scalar::parse(toks[3])
            .ok_or_else(|| bad(format!("unknown property type \"{}\"", toks[3])))?;
        Property::List {
            name: toks[4].to_string(),
            count,
            item,
        }
    } else {
        if toks.len() != 3 {
            return Err(bad(format!(
                "expected \"property <type> <name>\", found \"{line}\""
            )));
        }
        let ty = Scalar::parse(toks[1]).ok_or_else(|| {
            bad(format!(
                "unknown property type \"{}\" (expected char, uchar, short, ushort, int, uint, float, double or int8…float64)",
                toks[1]
            ))
        })?;
        Property::Scalar {
            name: toks[2].to_string(),
            ty,
        }
    };
    Ok(prop)
}
