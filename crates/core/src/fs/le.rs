//! Little-endian records with a CRC-32 trailer: the small binary checkpoints a split ingest's
//! tasks leave for each other (counts, pack indices, normals results). Each is written whole
//! under a temporary name and renamed, and checked when read: a damaged one is an error
//! naming its file, never wrong numbers.

/// A record being written.
#[derive(Debug, Default)]
pub struct LeWriter {
    /// The bytes so far.
    pub bytes: Vec<u8>,
}

impl LeWriter {
    /// A record starting with `magic`.
    pub fn new(magic: &[u8]) -> LeWriter {
        LeWriter {
            bytes: magic.to_vec(),
        }
    }
    /// Append a `u64`.
    pub fn u64(&mut self, v: u64) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    /// Append a `u32`.
    pub fn u32(&mut self, v: u32) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    /// Append an `f64`, bit for bit.
    pub fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }
    /// Append an `f32`, bit for bit.
    pub fn f32(&mut self, v: f32) {
        self.u32(v.to_bits());
    }
    /// The record with its CRC-32 appended.
    pub fn finish(mut self) -> Vec<u8> {
        let crc = crc32fast::hash(&self.bytes);
        self.bytes.extend_from_slice(&crc.to_le_bytes());
        self.bytes
    }
}

/// A record being read; every read is `None` past its end.
#[derive(Debug)]
pub struct LeReader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> LeReader<'a> {
    /// The record `bytes` when it starts with `magic` and its CRC-32 trailer matches; its
    /// fields follow the magic.
    pub fn open(bytes: &'a [u8], magic: &[u8]) -> Option<LeReader<'a>> {
        let (body, crc) = bytes.split_at_checked(bytes.len().checked_sub(4)?)?;
        (crc32fast::hash(body).to_le_bytes() == crc && body.starts_with(magic)).then_some(
            LeReader {
                b: body,
                at: magic.len(),
            },
        )
    }
    /// Fields of `bytes` from the start, with no magic or trailer to check.
    pub fn raw(bytes: &'a [u8]) -> LeReader<'a> {
        LeReader { b: bytes, at: 0 }
    }
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let v = self.b.get(self.at..self.at + N)?.try_into().ok()?;
        self.at += N;
        Some(v)
    }
    /// The next `u64`.
    pub fn u64(&mut self) -> Option<u64> {
        self.take::<8>().map(u64::from_le_bytes)
    }
    /// The next `u32`.
    pub fn u32(&mut self) -> Option<u32> {
        self.take::<4>().map(u32::from_le_bytes)
    }
    /// The next `f64`.
    pub fn f64(&mut self) -> Option<f64> {
        self.u64().map(f64::from_bits)
    }
    /// The next `f32`.
    pub fn f32(&mut self) -> Option<f32> {
        self.u32().map(f32::from_bits)
    }
    /// Whether every byte was read.
    pub fn at_end(&self) -> bool {
        self.at == self.b.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_read_back_and_damage_is_refused() {
        let mut w = LeWriter::new(b"MAGIC");
        w.u64(7);
        w.f32(-1.5);
        w.f64(2.25);
        let b = w.finish();
        let mut r = LeReader::open(&b, b"MAGIC").unwrap();
        assert_eq!(
            (r.u64(), r.f32(), r.f64()),
            (Some(7), Some(-1.5), Some(2.25))
        );
        assert!(r.at_end() && r.u32().is_none());
        assert!(LeReader::open(&b, b"OTHER").is_none());
        for i in 0..b.len() {
            let mut d = b.clone();
            d[i] ^= 0x10;
            assert!(LeReader::open(&d, b"MAGIC").is_none(), "byte {i}");
        }
        assert!(LeReader::open(&b[..3], b"MAGIC").is_none());
    }
}
