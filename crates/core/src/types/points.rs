//! Points in struct-of-arrays batches, their optional attributes, and scan viewpoints.

use serde::{Deserialize, Serialize};

use super::Rigid;

/// Which optional attributes points carry besides their position.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Attributes {
    /// Unit normals (`nx ny nz`).
    pub normal: bool,
    /// Colour (`red green blue`).
    pub color: bool,
    /// Alpha channel with the colour.
    pub alpha: bool,
    /// Scanner intensity.
    pub intensity: bool,
    /// Per-point confidence.
    pub confidence: bool,
    /// Index of the input (scan) each point came from, kept when a scan's viewpoint is known
    /// so that normals can be oriented toward it.
    #[serde(default)]
    pub source: bool,
}

impl Attributes {
    /// Attributes present in both.
    pub fn intersect(self, o: Attributes) -> Attributes {
        Attributes {
            normal: self.normal && o.normal,
            color: self.color && o.color,
            alpha: self.alpha && o.alpha,
            intensity: self.intensity && o.intensity,
            confidence: self.confidence && o.confidence,
            source: self.source && o.source,
        }
    }

    /// Names of the attributes present, for messages and `info`.
    pub fn names(self) -> Vec<&'static str> {
        let mut v = vec!["x", "y", "z"];
        if self.normal {
            v.extend(["nx", "ny", "nz"]);
        }
        if self.color {
            v.extend(["red", "green", "blue"]);
        }
        if self.alpha {
            v.push("alpha");
        }
        if self.intensity {
            v.push("intensity");
        }
        if self.confidence {
            v.push("confidence");
        }
        if self.source {
            v.push("scan");
        }
        v
    }
}

/// Points in struct-of-arrays form. An attribute's vector is empty when the batch does not
/// carry it, else as long as `pos`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointBatch {
    /// Positions, world frame.
    pub pos: Vec<[f64; 3]>,
    /// Unit normals.
    pub normal: Vec<[f32; 3]>,
    /// RGBA colour, 16 bits per channel (alpha 65535 when the input has none).
    pub color: Vec<[u16; 4]>,
    /// Intensity.
    pub intensity: Vec<f32>,
    /// Confidence.
    pub confidence: Vec<f32>,
    /// Index of the input each point came from.
    pub source: Vec<u16>,
}

impl PointBatch {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.pos.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.pos.is_empty()
    }

    /// Empty every vector, keeping capacity.
    pub fn clear(&mut self) {
        self.pos.clear();
        self.normal.clear();
        self.color.clear();
        self.intensity.clear();
        self.confidence.clear();
        self.source.clear();
    }

    /// Bytes held by the vectors' contents.
    pub fn heap_bytes(&self) -> usize {
        use std::mem::size_of;
        self.pos.capacity() * size_of::<[f64; 3]>()
            + self.normal.capacity() * size_of::<[f32; 3]>()
            + self.color.capacity() * size_of::<[u16; 4]>()
            + (self.intensity.capacity() + self.confidence.capacity()) * size_of::<f32>()
            + self.source.capacity() * size_of::<u16>()
    }

    /// Apply a rigid transform to positions and normals.
    pub fn transform(&mut self, t: &Rigid) {
        for p in &mut self.pos {
            *p = t.apply(*p);
        }
        for n in &mut self.normal {
            let r = t.rotate([n[0] as f64, n[1] as f64, n[2] as f64]);
            *n = [r[0] as f32, r[1] as f32, r[2] as f32];
        }
    }
}

/// Where a scan was seen from, in the common frame: normals are oriented toward it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Viewpoint {
    /// A scanner position (terrestrial scanners, `--viewpoint x,y,z`).
    Point([f64; 3]),
    /// A direction toward the scanner, for orthographic or far-away sensors (the
    /// Cyberware range images of a `.conf` scan: their local `+z`).
    Direction([f64; 3]),
}

impl Viewpoint {
    /// Unit vector from `p` toward the viewpoint (zero when `p` is the viewpoint).
    #[inline]
    pub fn toward(&self, p: [f64; 3]) -> [f64; 3] {
        let d = match *self {
            Viewpoint::Point(v) => [v[0] - p[0], v[1] - p[1], v[2] - p[2]],
            Viewpoint::Direction(d) => d,
        };
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if l > 0.0 {
            [d[0] / l, d[1] / l, d[2] / l]
        } else {
            [0.0; 3]
        }
    }
}
