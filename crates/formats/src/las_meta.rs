//! What `info` tells of a LAS or LAZ file beyond its points, as PDAL's `info --metadata` does:
//! version, point format, scale and offset, the writing software, the coordinate reference
//! system and the returns and classes present.
//!
//! **The CRS** is read from the projection records that LAS 1.4 (§2.5, "Georeferencing
//! information VLRs") defines under the user id `LASF_Projection`: the OGC WKT record (2112,
//! a null-terminated string, in a VLR or an extended VLR) and the GeoTIFF key directory (34735:
//! `u16` words, a 4-word header then 4-word entries `key, location, count, value`, the value
//! inline where the location is 0). The keys read are `ProjectedCSTypeGeoKey` (3072),
//! `GeographicTypeGeoKey` (2048) and `VerticalCSTypeGeoKey` (4096); 32767 means
//! "user-defined" (the WKT then says what it is). Both are reported as written; scanflow
//! does not reproject. A warning is given where the CRS contradicts the coordinates: a
//! geographic CRS (degrees) with `|x| > 180` or `|y| > 90`, or a projected one whose points
//! all lie within a few degrees' span of the origin of longitude and latitude values.

use std::collections::BTreeMap;

/// A CRS as the file's projection records give it.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Crs {
    /// `ProjectedCSTypeGeoKey` (32767: user-defined).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub projected_epsg: Option<u16>,
    /// `GeographicTypeGeoKey` (32767: user-defined).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub geographic_epsg: Option<u16>,
    /// `VerticalCSTypeGeoKey` (32767: user-defined).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vertical_epsg: Option<u16>,
    /// The OGC WKT record, as written.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wkt: Option<String>,
}

impl Crs {
    /// Whether any record was found.
    pub fn is_empty(&self) -> bool {
        *self == Crs::default()
    }

    /// The name the WKT gives its outermost system (`PROJCS["name", …` or `GEOGCS[…`).
    pub fn name(&self) -> Option<&str> {
        let w = self.wkt.as_deref()?;
        let open = w.find('[')?;
        let rest = w[open + 1..].strip_prefix('"')?;
        Some(&rest[..rest.find('"')?])
    }

    /// Whether the coordinates are degrees: a geographic system (a WKT whose outermost system
    /// is `GEOGCS`/`GEOGCRS`, or a geographic key with no projected one). `None`: unknown.
    pub fn geographic(&self) -> Option<bool> {
        if let Some(w) = &self.wkt {
            let head = w.trim_start().to_ascii_uppercase();
            return Some(head.starts_with("GEOGCS") || head.starts_with("GEOGCRS"));
        }
        match (self.projected_epsg, self.geographic_epsg) {
            (Some(_), _) => Some(false),
            (None, Some(_)) => Some(true),
            _ => None,
        }
    }

    /// One line: the EPSG codes, then the WKT's name.
    pub fn summary(&self) -> String {
        let code = |c: u16| {
            if c == USER_DEFINED {
                "user-defined".to_string()
            } else {
                format!("EPSG:{c}")
            }
        };
        let mut parts = Vec::new();
        if let Some(c) = self.projected_epsg {
            parts.push(format!("projected {}", code(c)));
        }
        if let Some(c) = self.geographic_epsg {
            parts.push(format!("geographic {}", code(c)));
        }
        if let Some(c) = self.vertical_epsg {
            parts.push(format!("vertical {}", code(c)));
        }
        if let Some(n) = self.name() {
            parts.push(format!("WKT \"{n}\""));
        } else if self.wkt.is_some() {
            parts.push("WKT".to_string());
        }
        if parts.is_empty() {
            "none".to_string()
        } else {
            parts.join(", ")
        }
    }

    /// A CRS given as text, as E57's `coordinateMetadata` holds it: OGC WKT (a keyword and a
    /// bracket, `PROJCS[…`), or an EPSG code (`EPSG:32610`, `urn:ogc:def:crs:EPSG::4326`).
    /// A code is placed as projected or geographic where its range says which (UTM zones
    /// 32601–32760 and 25828–25838, NAD83 UTM 26901–26923, and the common geographic
    /// systems 4326, 4269, 4258, 4283, 4617, 4979); other codes and free text stay unknown,
    /// and nothing is warned about them.
    pub fn from_text(text: &str) -> Crs {
        let t = text.trim();
        let head: String = t
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        if !head.is_empty() && t[head.len()..].trim_start().starts_with('[') {
            return Crs {
                wkt: Some(t.to_string()),
                ..Crs::default()
            };
        }
        let upper = t.to_ascii_uppercase();
        let code = upper
            .rfind("EPSG")
            .map(|i| upper[i + 4..].trim_start_matches(|c: char| c == ':' || c.is_whitespace()))
            .and_then(|rest| rest.parse::<u16>().ok());
        let mut crs = Crs::default();
        match code {
            Some(c @ (32601..=32660 | 32701..=32760 | 25828..=25838 | 26901..=26923)) => {
                crs.projected_epsg = Some(c)
            }
            Some(c @ (4326 | 4269 | 4258 | 4283 | 4617 | 4979)) => crs.geographic_epsg = Some(c),
            _ => {}
        }
        crs
    }

    /// Warnings where the CRS contradicts the points' bounds `min`..`max` (module docs).
    pub fn warnings(&self, min: [f64; 3], max: [f64; 3]) -> Vec<String> {
        let mut w = Vec::new();
        if !(min.iter().chain(&max).all(|v| v.is_finite())) {
            return w;
        }
        let big_x = min[0].abs().max(max[0].abs());
        let big_y = min[1].abs().max(max[1].abs());
        match self.geographic() {
            Some(true) if big_x > 180.0 || big_y > 90.0 => w.push(format!(
                "the CRS ({}) is geographic, in degrees, but the points reach x = {big_x}, y = {big_y}, beyond ±180 and ±90",
                self.summary()
            )),
            Some(false) if big_x <= 180.0 && big_y <= 90.0 && max[0] - min[0] < 5.0 => {
                w.push(format!(
                    "the CRS ({}) is projected, but every point lies within longitude and latitude values (|x| <= 180, |y| <= 90) over a few units: are the coordinates degrees?",
                    self.summary()
                ))
            }
            _ => {}
        }
        w
    }
}

/// The GeoTIFF code for a user-defined system.
const USER_DEFINED: u16 = 32767;

/// What `info` tells of a LAS file's header and records (the module docs).
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct LasMeta {
    /// `major.minor`.
    pub version: String,
    /// Point data record format (0–10).
    pub point_format: u8,
    /// LASzip-compressed (LAZ).
    pub compressed: bool,
    /// Scale factors of x, y, z.
    pub scale: [f64; 3],
    /// Offsets of x, y, z.
    pub offset: [f64; 3],
    /// The header's system identifier.
    pub system_identifier: String,
    /// The header's generating software.
    pub generating_software: String,
    /// The header's creation date (`YYYY-MM-DD`), where it has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub creation_date: Option<String>,
    /// The coordinate reference system.
    pub crs: Crs,
}

impl LasMeta {
    /// From a parsed header.
    pub fn from_header(h: &las::Header, point_format: u8) -> LasMeta {
        let v = h.version();
        let t = h.transforms();
        let mut crs = Crs::default();
        for vlr in h.vlrs().iter().chain(h.evlrs()) {
            if vlr.user_id.trim_end_matches('\0') != "LASF_Projection" {
                continue;
            }
            match vlr.record_id {
                2112 => {
                    let text = vlr.data.split(|&b| b == 0).next().unwrap_or(&[]);
                    let text = String::from_utf8_lossy(text).trim().to_string();
                    if !text.is_empty() {
                        crs.wkt = Some(text);
                    }
                }
                34735 => geo_keys(&vlr.data, &mut crs),
                _ => {}
            }
        }
        LasMeta {
            version: format!("{}.{}", v.major, v.minor),
            point_format,
            compressed: h.point_format().is_compressed,
            scale: [t.x.scale, t.y.scale, t.z.scale],
            offset: [t.x.offset, t.y.offset, t.z.offset],
            system_identifier: h.system_identifier().trim_end_matches('\0').to_string(),
            generating_software: h.generating_software().trim_end_matches('\0').to_string(),
            creation_date: h.date().map(|d| d.to_string()),
            crs,
        }
    }

    /// Warnings where the CRS contradicts the points' bounds `min`..`max` (module docs).
    pub fn warnings(&self, min: [f64; 3], max: [f64; 3]) -> Vec<String> {
        self.crs.warnings(min, max)
    }
}

/// The projection keys of a GeoKeyDirectoryTag record (`data`: little-endian `u16` words).
fn geo_keys(data: &[u8], crs: &mut Crs) {
    let words: Vec<u16> = data
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect();
    let Some(&n) = words.get(3) else { return };
    for e in words[4..].chunks_exact(4).take(n as usize) {
        let (key, location, value) = (e[0], e[1], e[3]);
        if location != 0 {
            continue;
        }
        match key {
            3072 => crs.projected_epsg = Some(value),
            2048 => crs.geographic_epsg = Some(value),
            4096 => crs.vertical_epsg = Some(value),
            _ => {}
        }
    }
}

/// How many points carry each classification and each return number.
#[derive(Debug, Clone, PartialEq)]
pub struct LasTally {
    /// Points per classification value.
    pub classes: [u64; 256],
    /// Points per return number (0–15).
    pub returns: [u64; 16],
}

impl Default for LasTally {
    fn default() -> Self {
        LasTally {
            classes: [0; 256],
            returns: [0; 16],
        }
    }
}

impl LasTally {
    /// Count one point.
    pub fn add(&mut self, class: u8, return_number: u8) {
        self.classes[class as usize] += 1;
        self.returns[(return_number & 15) as usize] += 1;
    }

    /// Pool `other` into `self`.
    pub fn merge(&mut self, other: &LasTally) {
        for (a, b) in self.classes.iter_mut().zip(&other.classes) {
            *a += b;
        }
        for (a, b) in self.returns.iter_mut().zip(&other.returns) {
            *a += b;
        }
    }

    /// The classes present, with their counts.
    pub fn classes_present(&self) -> BTreeMap<u8, u64> {
        present(&self.classes)
    }

    /// The return numbers present, with their counts.
    pub fn returns_present(&self) -> BTreeMap<u8, u64> {
        present(&self.returns)
    }
}

fn present(counts: &[u64]) -> BTreeMap<u8, u64> {
    counts
        .iter()
        .enumerate()
        .filter(|(_, c)| **c > 0)
        .map(|(i, &c)| (i as u8, c))
        .collect()
}

/// The ASPRS standard name of classification `c` (LAS 1.4, table 17), where it has one.
pub fn class_name(c: u8) -> Option<&'static str> {
    Some(match c {
        0 => "never classified",
        1 => "unclassified",
        2 => "ground",
        3 => "low vegetation",
        4 => "medium vegetation",
        5 => "high vegetation",
        6 => "building",
        7 => "low point (noise)",
        8 => "model key-point",
        9 => "water",
        10 => "rail",
        11 => "road surface",
        12 => "overlap",
        13 => "wire guard",
        14 => "wire conductor",
        15 => "transmission tower",
        16 => "wire connector",
        17 => "bridge deck",
        18 => "high noise",
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geo_keys_give_the_codes_written_inline() {
        // Header (version 1, revision 1.0, 3 keys), then: model type, projected 26910, a key
        // stored elsewhere (location 34736, ignored), and vertical 5703 beyond the count.
        let words: [u16; 20] = [
            1, 1, 0, 3, 1024, 0, 1, 1, 3072, 0, 1, 26910, 2048, 34736, 1, 0, 4096, 0, 1, 5703,
        ];
        let data: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let mut crs = Crs::default();
        geo_keys(&data, &mut crs);
        assert_eq!(crs.projected_epsg, Some(26910));
        assert_eq!(crs.geographic_epsg, None);
        assert_eq!(crs.vertical_epsg, None);
        assert_eq!(crs.geographic(), Some(false));
        assert_eq!(crs.summary(), "projected EPSG:26910");
        // A record cut short is read as far as it goes.
        let mut short = Crs::default();
        geo_keys(&data[..13], &mut short);
        assert!(short.is_empty());
    }

    #[test]
    fn a_crs_as_text_is_wkt_or_an_epsg_code() {
        let w = Crs::from_text(" PROJCS[\"NAD83 / UTM zone 10N\",GEOGCS[\"NAD83\"]]");
        assert_eq!(w.name(), Some("NAD83 / UTM zone 10N"));
        assert_eq!(w.geographic(), Some(false));
        assert_eq!(
            Crs::from_text("GEOGCRS [\"WGS 84\"]").geographic(),
            Some(true)
        );
        let utm = Crs::from_text("EPSG:32610");
        assert_eq!(utm.projected_epsg, Some(32610));
        assert_eq!(utm.geographic(), Some(false));
        let wgs = Crs::from_text("urn:ogc:def:crs:EPSG::4326");
        assert_eq!(wgs.geographic_epsg, Some(4326));
        assert_eq!(wgs.geographic(), Some(true));
        // Codes of unknown kind and free text: nothing to check against.
        for t in [
            "EPSG:2056",
            "site grid, metres",
            "",
            "EPSG:",
            "EPSG:99999999",
        ] {
            let c = Crs::from_text(t);
            assert_eq!(c.geographic(), None, "{t}");
            assert!(c.warnings([1e6; 3], [2e6; 3]).is_empty(), "{t}");
        }
        assert!(
            !wgs.warnings([636001.0, 848935.0, 0.0], [637179.0, 849497.0, 1.0])
                .is_empty()
        );
    }

    #[test]
    fn a_geographic_crs_with_metres_is_warned_about() {
        let mut m = LasMeta {
            crs: Crs {
                wkt: Some("GEOGCS[\"WGS 84\",DATUM[\"WGS_1984\"]]".to_string()),
                ..Crs::default()
            },
            ..LasMeta::default()
        };
        assert_eq!(m.crs.name(), Some("WGS 84"));
        assert_eq!(m.crs.geographic(), Some(true));
        let w = m.warnings([636001.0, 848935.0, 0.0], [637179.0, 849497.0, 1.0]);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains("geographic") && w[0].contains("637179"),
            "{w:?}"
        );
        assert!(
            m.warnings([-123.1, 44.0, 0.0], [-123.0, 44.1, 1.0])
                .is_empty()
        );
        // A projected CRS with degree-like coordinates.
        m.crs = Crs {
            projected_epsg: Some(32610),
            ..Crs::default()
        };
        let w = m.warnings([-123.1, 44.0, 0.0], [-123.0, 44.1, 1.0]);
        assert!(w.len() == 1 && w[0].contains("degrees"), "{w:?}");
        assert!(
            m.warnings([500000.0, 4e6, 0.0], [500100.0, 4.0001e6, 1.0])
                .is_empty()
        );
    }
}
