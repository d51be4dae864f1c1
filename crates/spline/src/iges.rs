//! IGES 5.3 writer for tensor-product B-spline surfaces (entity 128).
//!
//! # The file (IGES 5.3, section 2: file structure)
//!
//! ASCII, fixed 80-column lines. Columns 1–72 hold data, column 73 the section letter and
//! columns 74–80 the line's sequence number within its section (1-based, right-justified).
//! The sections, in order:
//!
//! * **S**, Start (§2.2.4.2): free text for a human reader;
//! * **G**, Global (§2.2.4.3): 26 parameters separated by `,` and ended by `;`: delimiters,
//!   product and file names, the sending system, number precision, model space scale (1),
//!   units flag and name, line weights, the file's date, the minimum resolution, the maximum
//!   coordinate, author and organisation, the version (11 = 5.3), drafting standard (0) and
//!   the model's date. Strings are Hollerith constants, `nH` followed by their `n` characters;
//!   a parameter never spans two lines;
//! * **D**, Directory Entry (§2.2.4.4): two lines per entity, ten 8-column fields each:
//!   entity type (128), pointer to its first P line, structure, line font, level, view,
//!   transformation matrix, label display (all 0), status `00000000` (visible, independent,
//!   geometry), then type again, line weight, colour, its count of P lines, form (0), two
//!   reserved fields, label and subscript;
//! * **P**, Parameter Data (§2.2.4.5): columns 1–64 the entity's parameters (same
//!   delimiters), columns 66–72 the back pointer to its first D line;
//! * **T**, Terminate (§2.2.4.6): the count of lines of each section above.
//!
//! # Entity 128, rational B-spline surface (IGES 5.3, §4.24)
//!
//! `128, K1, K2, M1, M2, PROP1..PROP5, S(-M1)..S(N1+M1), T(-M2)..T(N2+M2), W(0,0)..W(K1,K2),
//! X(0,0) Y(0,0) Z(0,0) .. X(K1,K2) Y Z, U(0), U(1), V(0), V(1);` with `K = count - 1`, `M` the
//! degree, `N = 1 + K - M`, so `K + M + 2` knots per direction; weights and control points
//! first index (u) fastest, which is [`TensorSurface`]'s order. PROP1/PROP2 (closed in u/v)
//! are 1 only when the knots are clamped and the first and last rows of control points are
//! equal, so that the surface's opposite boundary curves coincide; PROP3 = 1 (polynomial:
//! every weight is 1); PROP4/PROP5 (periodic) are 0. The parameter range is the surface's
//! [domain](TensorSurface::domain). Form 0 (no special shape claimed).
//!
//! # Numbers
//!
//! Integers in decimal; reals in Rust's shortest round-trip form, always with a decimal point,
//! with an `E` exponent for very large and very small magnitudes (`0.1`, `-3.0`, `1.5E-7`,
//! `1.0E20`), so a reader that parses a double correctly gets the same bits back (OpenCascade's
//! own parser is off by one unit in the last place on some numbers). A number never spans two lines.
//!
//! # Units
//!
//! The input's units are unknown, and both independent readers that matter here,
//! OpenCascade's `IGESControl_Reader` and gmsh (which imports through OpenCascade), convert
//! what they read into their working unit, the millimetre: a file in inches comes back scaled
//! by 25.4, one in metres by 1000. [`IgesUnit::Millimetre`] (flag 2, `MM`), the default,
//! is the one flag they read back unscaled: coordinates in the file are the input's numbers,
//! whatever unit those were. A caller that knows the unit passes it; CAD then scales it.
//!
//! Output goes through the one atomic writer ([`crate::fs::atomic`]): the file appears under
//! its name only when complete.

use std::path::Path;

use crate::error::{Error, Result};
use crate::types::TensorSurface;

/// Lines are 80 columns: data in 1–72, section letter in 73, sequence number in 74–80.
const DATA_COLS: usize = 72;
/// P lines hold parameters in columns 1–64; 65 is blank, 66–72 the D back pointer.
const P_COLS: usize = 64;
/// The longest string written into the Global section, in characters (longer ones are cut),
/// so that a Hollerith constant (`60H...,`) always fits on one line.
pub const MAX_STRING: usize = 60;

/// The IGES unit flags (Global parameter 14) scanflow writes, with their names (parameter 15).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum IgesUnit {
    /// Flag 2, `MM`: the default, read back unscaled by OpenCascade and gmsh (module docs).
    #[default]
    Millimetre,
    /// Flag 1, `IN`.
    Inch,
    /// Flag 4, `FT`.
    Foot,
    /// Flag 6, `M`.
    Metre,
    /// Flag 7, `KM`.
    Kilometre,
    /// Flag 10, `CM`.
    Centimetre,
}

impl IgesUnit {
    /// The units flag and the unit's name.
    pub fn flag_and_name(self) -> (u32, &'static str) {
        match self {
            IgesUnit::Millimetre => (2, "MM"),
            IgesUnit::Inch => (1, "IN"),
            IgesUnit::Foot => (4, "FT"),
            IgesUnit::Metre => (6, "M"),
            IgesUnit::Kilometre => (7, "KM"),
            IgesUnit::Centimetre => (10, "CM"),
        }
    }
}

/// What the Start and Global sections say about the file. Strings are written as ASCII
/// (any other character becomes `?`) and cut to [`MAX_STRING`] characters.
#[derive(Debug, Clone, PartialEq)]
pub struct IgesMeta {
    /// The file's name (Global parameter 4, and product identification, parameters 3 and 12).
    pub file_name: String,
    /// Seconds since 1970-01-01 00:00:00 UTC: the file's and the model's date (parameters 18
    /// and 25), passed in so that the same surfaces give the same bytes.
    pub unix_seconds: i64,
    /// Units flag and name (parameters 14 and 15).
    pub unit: IgesUnit,
    /// Minimum user-intended resolution (parameter 19), in the file's units; `None` takes
    /// 1e-9 of the largest control-point coordinate's magnitude (1e-9 when that is 0).
    pub resolution: Option<f64>,
    /// Author (parameter 21).
    pub author: String,
    /// Author's organisation (parameter 22).
    pub organisation: String,
    /// Lines of the Start section (each cut to 72 characters); none gives one line naming
    /// scanflow.
    pub start: Vec<String>,
}

impl IgesMeta {
    /// Millimetres (read back unscaled), automatic resolution, author `scanflow`, no
    /// organisation, the default Start line.
    pub fn new(file_name: impl Into<String>, unix_seconds: i64) -> IgesMeta {
        IgesMeta {
            file_name: file_name.into(),
            unix_seconds,
            unit: IgesUnit::default(),
            resolution: None,
            author: "scanflow".into(),
            organisation: String::new(),
            start: Vec::new(),
        }
    }
}

/// What [`write_iges`] wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IgesStats {
    /// Entities 128 written.
    pub surfaces: usize,
    /// Control points over all surfaces.
    pub control_points: usize,
    /// Lines of the S, G, D and P sections (T has one).
    pub lines: [usize; 4],
    /// Bytes of the file.
    pub bytes: u64,
}

/// Write `surfaces` to `path` as IGES 5.3 (see the [module docs](self)), atomically. No
/// surface, an inconsistent surface, an empty domain or a non-finite number is an error naming
/// the file, the surface and the value, and nothing is written.
pub fn write_iges(path: &Path, surfaces: &[TensorSurface], meta: &IgesMeta) -> Result<IgesStats> {
    let (bytes, mut stats) = build(surfaces, meta).map_err(|m| Error::input(path, m))?;
    stats.bytes = bytes.len() as u64;
    crate::fs::atomic::write(path, &bytes, crate::fs::atomic::Durability::Synced)?;
    Ok(stats)
}

/// The bytes [`write_iges`] writes. Errors name `meta.file_name`.
pub fn iges_bytes(surfaces: &[TensorSurface], meta: &IgesMeta) -> Result<Vec<u8>> {
    build(surfaces, meta)
        .map(|(b, _)| b)
        .map_err(|m| Error::input(&meta.file_name, m))
}

/// A real as IGES reads it: shortest round-trip digits, a decimal point, `E` exponent.
pub fn format_real(x: f64) -> String {
    let s = format!("{x:?}");
    match s.split_once('e') {
        Some((mantissa, exp)) if mantissa.contains('.') => format!("{mantissa}E{exp}"),
        Some((mantissa, exp)) => format!("{mantissa}.0E{exp}"),
        None => s,
    }
}

/// `s` with every character that is not printable ASCII replaced by `?`, cut to `max`.
fn ascii(s: &str, max: usize) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii() && !c.is_ascii_control() {
                c
            } else {
                '?'
            }
        })
        .take(max)
        .collect()
}

/// A Hollerith string constant of `s` made ASCII and cut to [`MAX_STRING`] characters.
fn hollerith(s: &str) -> String {
    let t = ascii(s, MAX_STRING);
    format!("{}H{t}", t.len())
}

/// One section's lines, numbered as they are added.
struct Section {
    letter: char,
    lines: Vec<String>,
}

impl Section {
    fn new(letter: char) -> Section {
        Section {
            letter,
            lines: Vec::new(),
        }
    }

    /// Add a line of at most 72 data columns, padded; returns its sequence number.
    fn push(&mut self, data: &str) -> usize {
        let n = self.lines.len() + 1;
        self.lines
            .push(format!("{data:<DATA_COLS$}{}{n:07}", self.letter));
        n
    }

    /// Pack delimited parameters into lines of `width` columns, never splitting one;
    /// `suffix` (the P back pointer) fills columns `width + 1..=72`. Returns the first and
    /// the count of lines added.
    fn push_params(&mut self, params: &[String], width: usize, suffix: &str) -> (usize, usize) {
        let first = self.lines.len() + 1;
        let mut line = String::new();
        for (i, p) in params.iter().enumerate() {
            let delim = if i + 1 == params.len() { ';' } else { ',' };
            if !line.is_empty() && line.len() + p.len() + 1 > width {
                self.push(&format!("{line:<width$}{suffix}"));
                line.clear();
            }
            line.push_str(p);
            line.push(delim);
        }
        self.push(&format!("{line:<width$}{suffix}"));
        (first, self.lines.len() + 1 - first)
    }
}

/// `YYYYMMDD.HHNNSS` of `unix_seconds` (UTC), by the days-to-civil conversion of the
/// proleptic Gregorian calendar (H. Hinnant, `civil_from_days`).
fn date_string(unix_seconds: i64) -> String {
    let (year, month, day) =
        crate::exec::progress::civil_from_days(unix_seconds.div_euclid(86_400));
    let secs = unix_seconds.rem_euclid(86_400);
    format!(
        "{year:04}{month:02}{day:02}.{:02}{:02}{:02}",
        secs / 3600,
        secs / 60 % 60,
        secs % 60
    )
}

/// What is wrong with surface `k`, if anything: sizes, knot order or a non-finite number.
fn check_surface(k: usize, s: &TensorSurface) -> Option<String> {
    if !s.is_consistent() {
        return Some(format!(
            "surface {k}: inconsistent sizes (degree {:?}, count {:?}, {} and {} knots, {} \
             control points) or decreasing knots",
            s.degree,
            s.count,
            s.knots[0].len(),
            s.knots[1].len(),
            s.ctrl.len()
        ));
    }
    for d in 0..2 {
        let [a, b] = s.domain()[d];
        if let Some(t) = s.knots[d].iter().find(|t| !t.is_finite()) {
            return Some(format!("surface {k}: knot {t} along {}", ["u", "v"][d]));
        }
        if a >= b {
            return Some(format!(
                "surface {k}: empty domain [{a}, {b}] along {}",
                ["u", "v"][d]
            ));
        }
    }
    let bad = s
        .ctrl
        .iter()
        .enumerate()
        .find(|(_, c)| c.iter().any(|x| !x.is_finite()));
    bad.map(|(i, c)| format!("surface {k}: control point {i} is {c:?}, expected finite"))
}

/// Whether the surface closes along direction `d`: clamped knots and equal first and last
/// rows of control points.
fn closed(s: &TensorSurface, d: usize) -> bool {
    let (p, n, k) = (s.degree[d], s.count[d], &s.knots[d]);
    let clamped = k[..=p].iter().all(|&t| t == k[0]) && k[n..].iter().all(|&t| t == k[n]);
    let at = |i: usize, j: usize| {
        if d == 0 {
            s.ctrl[i + s.count[0] * j]
        } else {
            s.ctrl[j + s.count[0] * i]
        }
    };
    clamped && (0..s.count[1 - d]).all(|j| at(0, j) == at(n - 1, j))
}

/// Entity 128's parameters for `s` (module docs), starting with the type.
fn entity_params(s: &TensorSurface) -> Vec<String> {
    let int = |i: usize| i.to_string();
    let mut p = vec![int(128), int(s.count[0] - 1), int(s.count[1] - 1)];
    p.extend([int(s.degree[0]), int(s.degree[1])]);
    p.extend([closed(s, 0), closed(s, 1)].map(|c| int(usize::from(c))));
    p.extend([int(1), int(0), int(0)]);
    for d in 0..2 {
        p.extend(s.knots[d].iter().map(|&t| format_real(t)));
    }
    p.extend(std::iter::repeat_n(format_real(1.0), s.ctrl.len()));
    p.extend(s.ctrl.iter().flatten().map(|&x| format_real(x)));
    p.extend(s.domain().iter().flatten().map(|&t| format_real(t)));
    p
}

/// The Global section's 26 parameters.
fn global_params(meta: &IgesMeta, max_coord: f64) -> Vec<String> {
    let (flag, unit) = meta.unit.flag_and_name();
    let date = hollerith(&date_string(meta.unix_seconds));
    let resolution = meta.resolution.unwrap_or(if max_coord > 0.0 {
        1e-9 * max_coord
    } else {
        1e-9
    });
    let name = hollerith(&meta.file_name);
    vec![
        "1H,".into(),
        "1H;".into(),
        name.clone(),
        name.clone(),
        hollerith("scanflow"),
        hollerith(concat!("scanflow ", env!("CARGO_PKG_VERSION"))),
        "32".into(),
        "38".into(),
        "6".into(),
        "308".into(),
        "15".into(),
        name,
        format_real(1.0),
        flag.to_string(),
        hollerith(unit),
        "1".into(),
        format_real(0.0),
        date.clone(),
        format_real(resolution),
        format_real(max_coord),
        hollerith(&meta.author),
        hollerith(&meta.organisation),
        "11".into(),
        "0".into(),
        date,
        hollerith(""),
    ]
}

/// The file's bytes and its statistics (bytes left 0), or what is wrong.
fn build(
    surfaces: &[TensorSurface],
    meta: &IgesMeta,
) -> std::result::Result<(Vec<u8>, IgesStats), String> {
    if surfaces.is_empty() {
        return Err("no surface to write".into());
    }
    if let Some(m) = surfaces
        .iter()
        .enumerate()
        .find_map(|(k, s)| check_surface(k, s))
    {
        return Err(m);
    }
    if let Some(r) = meta.resolution.filter(|r| !(r.is_finite() && *r > 0.0)) {
        return Err(format!("resolution {r}, expected a positive finite number"));
    }
    let max_coord = surfaces
        .iter()
        .flat_map(|s| s.ctrl.iter().flatten())
        .fold(0.0f64, |m, x| m.max(x.abs()));

    let mut start = Section::new('S');
    if meta.start.is_empty() {
        start.push("scanflow: tensor-product B-spline surfaces (entity 128), IGES 5.3");
    }
    for l in &meta.start {
        start.push(&ascii(l, DATA_COLS));
    }
    let mut global = Section::new('G');
    global.push_params(&global_params(meta, max_coord), DATA_COLS, "");

    let mut dir = Section::new('D');
    let mut params = Section::new('P');
    for (k, s) in surfaces.iter().enumerate() {
        let de = 2 * k + 1;
        let (first, count) = params.push_params(&entity_params(s), P_COLS, &format!(" {de:>7}"));
        let f = |v: &dyn std::fmt::Display| format!("{v:>8}");
        let line1 = [f(&128), f(&first), f(&0), f(&0), f(&0), f(&0), f(&0), f(&0)].concat();
        dir.push(&format!("{line1}00000000"));
        let label = format!("{:>8}", "SURFACE");
        let line2 = [
            f(&128),
            f(&0),
            f(&0),
            f(&count),
            f(&0),
            f(&""),
            f(&""),
            label,
        ];
        dir.push(&format!("{}{:>8}", line2.concat(), k + 1));
    }
    let lines = [
        start.lines.len(),
        global.lines.len(),
        dir.lines.len(),
        params.lines.len(),
    ];
    let mut term = Section::new('T');
    term.push(&format!(
        "S{:07}G{:07}D{:07}P{:07}",
        lines[0], lines[1], lines[2], lines[3]
    ));
    let mut out = Vec::with_capacity(81 * (lines.iter().sum::<usize>() + 1));
    for sec in [&start, &global, &dir, &params, &term] {
        for l in &sec.lines {
            out.extend_from_slice(l.as_bytes());
            out.push(b'\n');
        }
    }
    let stats = IgesStats {
        surfaces: surfaces.len(),
        control_points: surfaces.iter().map(|s| s.ctrl.len()).sum(),
        lines,
        bytes: 0,
    };
    Ok((out, stats))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bicubic (u) by quadratic (v) surface with an interior knot along each direction.
    fn surface(shift: f64) -> TensorSurface {
        let count = [5, 4];
        let ctrl = (0..count[0] * count[1])
            .map(|k| {
                let (i, j) = ((k % count[0]) as f64, (k / count[0]) as f64);
                [
                    i * 0.1 + shift,
                    j / 3.0,
                    (i * j).sin() * 1e-7 + 1e20 * shift,
                ]
            })
            .collect();
        TensorSurface {
            degree: [3, 2],
            knots: [
                vec![0.0, 0.0, 0.0, 0.0, 0.4, 1.0, 1.0, 1.0, 1.0],
                vec![-2.0, -2.0, -2.0, 0.7, 3.0, 3.0, 3.0],
            ],
            count,
            ctrl,
        }
    }

    /// The file's lines, each checked to be 80 columns, grouped by section letter in order.
    fn sections(bytes: &[u8]) -> Vec<(char, Vec<String>)> {
        let text = std::str::from_utf8(bytes).unwrap();
        let mut out: Vec<(char, Vec<String>)> = Vec::new();
        for line in text.lines() {
            assert_eq!(line.len(), 80, "{line:?}");
            let letter = line.as_bytes()[72] as char;
            let seq: usize = line[73..].parse().unwrap();
            match out.last_mut() {
                Some((l, lines)) if *l == letter => lines.push(line.to_string()),
                _ => out.push((letter, vec![line.to_string()])),
            }
            let lines = &out.last().unwrap().1;
            assert_eq!(seq, lines.len(), "sequence number of {line:?}");
        }
        out
    }

    /// Split delimited parameters, Hollerith strings read by their count.
    fn split_params(text: &str) -> Vec<String> {
        let (mut out, mut rest) = (Vec::new(), text.trim_end());
        while !rest.is_empty() {
            let digits = rest
                .find(|c: char| !c.is_ascii_digit())
                .unwrap_or(rest.len());
            let end = if digits > 0 && rest[digits..].starts_with('H') {
                digits + 1 + rest[..digits].parse::<usize>().unwrap()
            } else {
                rest.find([',', ';']).unwrap()
            };
            out.push(rest[..end].trim().to_string());
            let delim = rest.as_bytes()[end];
            rest = &rest[end + 1..];
            if delim == b';' {
                assert!(rest.trim().is_empty(), "parameters after ';': {rest:?}");
                break;
            }
        }
        out
    }

    /// Read back entity 128 parameters as a surface.
    fn parse_128(p: &[String]) -> TensorSurface {
        let int = |i: usize| p[i].parse::<usize>().unwrap();
        let real = |s: &String| s.replace('D', "E").parse::<f64>().unwrap();
        assert_eq!(int(0), 128);
        let (k, m) = ([int(1), int(2)], [int(3), int(4)]);
        assert_eq!(
            [int(7), int(8), int(9)],
            [1, 0, 0],
            "polynomial, not periodic"
        );
        let count = [k[0] + 1, k[1] + 1];
        let mut at = 10;
        let mut take = |n: usize| {
            let v: Vec<f64> = p[at..at + n].iter().map(real).collect();
            at += n;
            v
        };
        let knots = [take(k[0] + m[0] + 2), take(k[1] + m[1] + 2)];
        let weights = take(count[0] * count[1]);
        assert!(weights.iter().all(|&w| w == 1.0));
        let xyz = take(3 * count[0] * count[1]);
        let range = take(4);
        let s = TensorSurface {
            degree: m,
            knots,
            count,
            ctrl: xyz.chunks(3).map(|c| [c[0], c[1], c[2]]).collect(),
        };
        assert_eq!(range, s.domain().concat());
        assert_eq!(at, p.len());
        s
    }

    /// Every entity's surface, through the D and P pointers, checking them on the way.
    fn read_back(bytes: &[u8]) -> (Vec<String>, Vec<TensorSurface>) {
        let secs = sections(bytes);
        let letters: String = secs.iter().map(|(l, _)| *l).collect();
        assert_eq!(letters, "SGDPT");
        let (g, d, p, t) = (&secs[1].1, &secs[2].1, &secs[3].1, &secs[4].1);
        let want = format!(
            "S{:07}G{:07}D{:07}P{:07}",
            secs[0].1.len(),
            g.len(),
            d.len(),
            p.len()
        );
        assert_eq!(t[0][..32], want);
        let global = split_params(&g.iter().map(|l| &l[..72]).collect::<String>());
        let mut out = Vec::new();
        for (e, de) in d.chunks(2).enumerate() {
            let field = |l: usize, f: usize| de[l][8 * f..8 * f + 8].trim().to_string();
            assert_eq!([field(0, 0), field(1, 0)], ["128", "128"]);
            assert_eq!(field(0, 8), "00000000");
            let (first, n): (usize, usize) =
                (field(0, 1).parse().unwrap(), field(1, 3).parse().unwrap());
            let lines = &p[first - 1..first - 1 + n];
            for l in lines {
                assert_eq!(&l[64..65], " ");
                assert_eq!(l[65..72].trim().parse::<usize>().unwrap(), 2 * e + 1);
            }
            let text: String = lines.iter().map(|l| &l[..64]).collect();
            out.push(parse_128(&split_params(&text)));
        }
        let covered: usize = d
            .chunks(2)
            .map(|de| de[1][24..32].trim().parse::<usize>().unwrap())
            .sum();
        assert_eq!(covered, p.len(), "every P line belongs to one entity");
        (global, out)
    }

    #[test]
    fn round_trip_through_a_minimal_reader_gives_the_same_bits() {
        let surfaces = [surface(0.0), surface(-1.0 / 3.0)];
        let bytes = iges_bytes(&surfaces, &IgesMeta::new("two.igs", 1_795_346_032)).unwrap();
        let (_, back) = read_back(&bytes);
        assert_eq!(back, surfaces, "bit-exact knots and control points");
    }

    #[test]
    fn global_section_states_units_scale_dates_and_version() {
        let mut meta = IgesMeta::new("a,b;c.igs", 1_795_346_032);
        meta.author = "Zoë".into();
        let bytes = iges_bytes(&[surface(2.5)], &meta).unwrap();
        let (g, _) = read_back(&bytes);
        assert_eq!(g.len(), 26);
        assert_eq!([&g[0], &g[1], &g[2]], ["1H,", "1H;", "9Ha,b;c.igs"]);
        assert_eq!([&g[12], &g[13], &g[14]], ["1.0", "2", "2HMM"]);
        assert_eq!(g[17], "15H20261122.111352");
        assert_eq!(g[24], g[17]);
        assert_eq!(g[19], format_real(1e20 * 2.5), "max coordinate");
        assert_eq!(g[20], "3HZo?");
        assert_eq!(g[22], "11");
        meta.unit = IgesUnit::Metre;
        meta.resolution = Some(0.25);
        let (g, _) = read_back(&iges_bytes(&[surface(0.0)], &meta).unwrap());
        assert_eq!([&g[13], &g[14], &g[18]], ["6", "1HM", "0.25"]);
    }

    #[test]
    fn long_strings_are_cut_so_that_no_parameter_spans_lines() {
        let mut meta = IgesMeta::new("n".repeat(200), 0);
        meta.start = vec!["s".repeat(100)];
        let bytes = iges_bytes(&[surface(0.0)], &meta).unwrap();
        let (g, _) = read_back(&bytes);
        assert_eq!(g[3], format!("60H{}", "n".repeat(60)));
        assert_eq!(g[17], "15H19700101.000000");
    }

    #[test]
    fn format_real_round_trips_with_a_decimal_point() {
        let mut state = 99u64;
        let mut values = vec![
            0.0,
            -0.0,
            1.0,
            -3.0,
            0.1,
            1e-7,
            1e17,
            1e300,
            5e-324,
            f64::MAX,
        ];
        for _ in 0..2000 {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
            let x = f64::from_bits(state);
            if x.is_finite() {
                values.push(x);
            }
        }
        for x in values {
            let s = format_real(x);
            assert!(s.contains('.') && !s.contains('e'), "{s}");
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), x.to_bits(), "{s}");
            assert!(s.len() < P_COLS, "{s}");
        }
        assert_eq!(format_real(1.5e-7), "1.5E-7");
        assert_eq!(format_real(1e20), "1.0E20");
    }

    #[test]
    fn dates_are_utc_civil_dates() {
        assert_eq!(date_string(0), "19700101.000000");
        assert_eq!(date_string(951_782_400), "20000229.000000");
        assert_eq!(date_string(1_795_346_032), "20261122.111352");
        assert_eq!(date_string(-86_400), "19691231.000000");
    }

    #[test]
    fn closed_flag_only_for_clamped_surface_with_equal_end_rows() {
        let mut s = surface(0.0);
        assert!(!closed(&s, 0) && !closed(&s, 1));
        for j in 0..s.count[1] {
            s.ctrl[4 + 5 * j] = s.ctrl[5 * j];
        }
        assert!(closed(&s, 0) && !closed(&s, 1));
        let params = entity_params(&s);
        assert_eq!([&params[5], &params[6]], ["1", "0"]);
        s.knots[0][0] = -1.0;
        assert!(!closed(&s, 0), "not clamped");
    }

    #[test]
    fn bad_surfaces_are_errors_naming_file_and_surface() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.igs");
        let meta = IgesMeta::new("bad.igs", 0);
        let mut nan = surface(0.0);
        nan.ctrl[7][1] = f64::NAN;
        let e = write_iges(&path, &[surface(0.0), nan], &meta)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("bad.igs") && e.contains("surface 1: control point 7"),
            "{e}"
        );
        let mut short = surface(0.0);
        short.knots[1].pop();
        let e = write_iges(&path, &[short], &meta).unwrap_err().to_string();
        assert!(e.contains("surface 0: inconsistent"), "{e}");
        let e = write_iges(&path, &[], &meta).unwrap_err().to_string();
        assert!(e.contains("no surface"), "{e}");
        assert!(!path.exists());
        let stats = write_iges(&path, &[surface(0.0)], &meta).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(bytes, iges_bytes(&[surface(0.0)], &meta).unwrap());
        assert_eq!(stats.bytes, bytes.len() as u64);
        assert_eq!((stats.surfaces, stats.control_points), (1, 20));
    }
}
