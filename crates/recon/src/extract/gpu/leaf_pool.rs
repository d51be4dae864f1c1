//! The device's resident leaf grids: a pool of slots in one device buffer, kept by leaf id in
//! the crate's one LRU ([`Lru`]), so that a leaf shared by neighbouring tiles crosses the bus
//! once while it stays resident; and the upload of a blended tile's other tables (axis
//! weights, coarse values, bump weights, the lookup box from leaf cell to slot).

use super::buffers::ensure;
use super::{GpuExtractor, GpuResult, GpuStats};
use crate::exec::cache::Lru;
use crate::types::Blend;

/// Bytes of the leaf pool on a discrete GPU, an integrated one, and other adapters (at most
/// the buffer limit, at least twice a tile's leaves).
const POOL_DISCRETE: u64 = 1 << 30;
const POOL_INTEGRATED: u64 = 256 << 20;
const POOL_OTHER: u64 = 32 << 20;

/// Most slots of the leaf pool: a lookup entry is the slot in 24 bits and the leaf's exponent
/// above them.
const MAX_SLOTS: usize = (1 << 24) - 1;

/// No leaf in this cell of a blended tile's lookup box (`field.wgsl`).
const NO_LEAF: u32 = u32::MAX;

/// Words of `field.wgsl`'s parameters that are the same for all sub-blocks of a tile (from
/// `lox` on).
pub(super) type TileWords = [u32; 20];

/// The device's cache of leaf detail grids: `slots` grids of `dm³` values in one buffer.
///
/// Leaf ids map to slots in an [`Lru`] whose entries are a slot's bytes, with room for
/// `slots` of them; a new leaf takes a free slot (the lowest), else the slot of the least
/// recently used leaf. The leaves of the tile being built are the most recently used
/// entries, and the pool holds at least as many slots as a tile has leaves, so the one
/// evicted is never one of them ([`LeafPool::place`] checks it). At the end of a tile its
/// leaves are ordered by slot ([`LeafPool::end_tile`]), so leaves last used by the same tile
/// go lowest slot first.
pub(super) struct LeafPool {
    buf: Option<wgpu::Buffer>,
    /// Detail values per axis of a leaf grid.
    dm: usize,
    slots: usize,
    /// Bytes of a slot: `dm³` 16-bit values, padded to whole 32-bit words.
    slot_bytes: u64,
    /// Leaf id to slot.
    resident: Lru<u64, usize>,
    /// Slots holding no leaf, the lowest last.
    free: Vec<usize>,
    /// The slots and ids placed (found or inserted) since the tile began.
    placed: Vec<(usize, u64)>,
}

impl Default for LeafPool {
    fn default() -> LeafPool {
        LeafPool {
            buf: None,
            dm: 0,
            slots: 0,
            slot_bytes: 0,
            resident: Lru::new(0),
            free: Vec::new(),
            placed: Vec::new(),
        }
    }
}

impl LeafPool {
    /// An empty pool of `slots` slots of `slot_bytes` bytes for grids of `dm³` values.
    fn new(device: &wgpu::Device, dm: usize, slots: usize, slot_bytes: u64) -> LeafPool {
        use wgpu::BufferUsages as U;
        LeafPool {
            buf: Some(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("leaf grids"),
                size: slots as u64 * slot_bytes,
                usage: U::STORAGE | U::COPY_DST,
                mapped_at_creation: false,
            })),
            ..LeafPool::without_buffer(dm, slots, slot_bytes)
        }
    }

    /// The bookkeeping of [`LeafPool::new`], without the device buffer.
    fn without_buffer(dm: usize, slots: usize, slot_bytes: u64) -> LeafPool {
        LeafPool {
            buf: None,
            dm,
            slots,
            slot_bytes,
            resident: Lru::new(slots as u64 * slot_bytes),
            free: (0..slots).rev().collect(),
            placed: Vec::new(),
        }
    }

    /// The device buffer of the slots, once made.
    pub(super) fn buffer(&self) -> Option<wgpu::Buffer> {
        self.buf.clone()
    }

    /// Whether the pool holds grids of `dm³` values, in at least `leaves` slots.
    fn fits(&self, dm: usize, leaves: usize) -> bool {
        self.buf.is_some() && self.dm == dm && self.slots >= leaves
    }

    /// Start placing the leaves of a new tile.
    fn begin_tile(&mut self) {
        self.placed.clear();
    }

    /// End the tile: its leaves become the most recently used in order of slot.
    fn end_tile(&mut self) {
        self.placed.sort_unstable();
        for &(_, id) in &self.placed {
            self.resident.touch(&id);
        }
    }

    /// The slot of leaf `id` for the current tile, made its most recently used entry, and
    /// whether its grid must be written there (it was not resident).
    fn place(&mut self, id: u64) -> GpuResult<(usize, bool)> {
        if let Some(&slot) = self.resident.get(&id) {
            self.placed.push((slot, id));
            return Ok((slot, false));
        }
        let slot = match self.free.pop() {
            Some(s) => s,
            // The `placed` newest entries may be this tile's: only an older one may go.
            None if self.resident.len() > self.placed.len() => {
                let (_, s) = self.resident.pop_oldest().ok_or("the leaf pool is full")?;
                s
            }
            None => return Err("the leaf pool is full".to_string()),
        };
        for (_, s) in self.resident.insert(id, slot, self.slot_bytes) {
            self.free.push(s);
        }
        self.placed.push((slot, id));
        Ok((slot, true))
    }
}

/// The lowest of the (at most two) leaf cells whose grids reach node `g` with a non-zero
/// weight (detail offset `1..=dm−2`), and the highest (`field.wgsl`, `candidates`).
fn leaf_cells(g: i64, e: i64, ov: i64, dm: i64) -> (i64, i64) {
    let hi = (g + ov - 1).div_euclid(e);
    let lo = if g - (e * (hi - 1) - ov) <= dm - 2 {
        hi - 1
    } else {
        hi
    };
    (lo, hi)
}

/// The box of leaf cells whose grids can reach a blended tile's nodes: `field.wgsl` looks a
/// node's leaves up in it.
struct LeafBox {
    /// Lowest leaf cell.
    lo: [i64; 3],
    /// Leaf cells per axis.
    dims: [usize; 3],
}

impl LeafBox {
    fn of(b: &Blend<'_>) -> LeafBox {
        let dm = b.dm() as i64;
        let cells = |a: usize| {
            (
                leaf_cells(b.lo[a], b.e, b.ov, dm).0,
                leaf_cells(b.lo[a] + b.dims[a] as i64 - 1, b.e, b.ov, dm).1,
            )
        };
        let [(x0, x1), (y0, y1), (z0, z1)] = [cells(0), cells(1), cells(2)];
        LeafBox {
            lo: [x0, y0, z0],
            dims: [x1 - x0 + 1, y1 - y0 + 1, z1 - z0 + 1].map(|v| v as usize),
        }
    }

    /// The index of leaf cell `c` in the box, x fastest; `None` outside it.
    fn index(&self, c: [i64; 3]) -> Option<usize> {
        let mut at = [0; 3];
        for d in 0..3 {
            let v = c[d] - self.lo[d];
            if v < 0 || v as usize >= self.dims[d] {
                return None;
            }
            at[d] = v as usize;
        }
        Some((at[2] * self.dims[1] + at[1]) * self.dims[0] + at[0])
    }
}

impl GpuExtractor {
    /// Make a blended tile's leaf grids resident and upload its tables. The parameter words
    /// of `field.wgsl` from `lox` on; `None` when the device has no field pipeline or the
    /// tile's leaves do not fit the pool.
    pub(super) fn prepare_blend(
        &mut self,
        b: &Blend<'_>,
        stats: &mut GpuStats,
    ) -> GpuResult<Option<TileWords>> {
        if self.pipelines.field.is_none() {
            return Ok(None);
        }
        let dm = b.dm();
        // Two 16-bit details a word (`quantise_detail`).
        let slot_words = (dm * dm * dm).div_ceil(2);
        let slot_bytes = 4 * slot_words as u64;
        let max_slots = ((self.max_bytes / slot_bytes) as usize).min(MAX_SLOTS);
        let lbox = LeafBox::of(b);
        let leaves: Vec<_> = b
            .leaves
            .iter()
            .filter_map(|l| lbox.index(l.cell).map(|i| (i, l)))
            .collect();
        if leaves.len() > max_slots {
            return Ok(None);
        }
        if !self.pool.fits(dm, leaves.len()) {
            // Room for the leaves of many tiles: a leaf serves up to 8 tiles, not all close
            // in Morton order. Device memory of its own on a discrete GPU; host memory on
            // integrated and software adapters, so less there.
            let target = match self.info.device_type {
                wgpu::DeviceType::DiscreteGpu => POOL_DISCRETE,
                wgpu::DeviceType::IntegratedGpu => POOL_INTEGRATED,
                _ => POOL_OTHER,
            };
            let slots = (2 * leaves.len())
                .max((target / slot_bytes) as usize)
                .max(1)
                .min(max_slots);
            self.pool = LeafPool::new(&self.device, dm, slots, slot_bytes);
        }
        let pool = &mut self.pool;
        pool.begin_tile();
        let buf = pool.buffer().ok_or("no leaf pool")?;
        let mut table = vec![NO_LEAF; lbox.dims.iter().product()];
        for (i, l) in leaves {
            let (slot, fresh) = pool.place(l.id)?;
            if fresh {
                let at = slot as u64 * slot_bytes;
                self.queue
                    .write_buffer(&buf, at, bytemuck::cast_slice(l.detail));
                stats.upload_bytes += slot_bytes;
                stats.leaves_sent += 1;
            }
            table[i] = slot as u32 | l.shift << 24;
        }
        pool.end_tile();
        self.upload_blend_tables(b, &table, stats);
        Ok(Some(tile_words(b, &lbox, slot_words)))
    }

    /// Upload a blended tile's axis tables, coarse values, bump weights and lookup box.
    fn upload_blend_tables(&mut self, b: &Blend<'_>, table: &[u32], stats: &mut GpuStats) {
        use wgpu::BufferUsages as U;
        let mut axes: Vec<[u32; 4]> = Vec::with_capacity(b.dims.iter().sum());
        for ax in &b.axes {
            for i in 0..ax.c0.len() {
                axes.push([ax.c0[i], ax.w0[i] as u32, ax.w1[i] as u32, 0]);
            }
        }
        let cap = self.device_max_bytes;
        let bufs = &mut self.bufs;
        let usage = U::STORAGE | U::COPY_DST;
        let uploads: [(&mut Option<wgpu::Buffer>, &str, &[u8]); 4] = [
            (&mut bufs.axes, "axis tables", bytemuck::cast_slice(&axes)),
            (
                &mut bufs.coarse,
                "coarse values",
                bytemuck::cast_slice(&b.coarse),
            ),
            (&mut bufs.own, "bump weights", bytemuck::cast_slice(&b.own)),
            (&mut bufs.slots, "leaf lookup", bytemuck::cast_slice(table)),
        ];
        for (slot, label, bytes) in uploads {
            let buf = ensure(&self.device, slot, label, bytes.len() as u64, usage, cap);
            self.queue.write_buffer(&buf, 0, bytes);
            stats.upload_bytes += bytes.len() as u64;
        }
    }
}

/// The words of `field.wgsl`'s parameters from `lox` on, for tile `b` whose leaves are
/// looked up in `lbox`, with slots of `slot_words` words.
fn tile_words(b: &Blend<'_>, lbox: &LeafBox, slot_words: usize) -> TileWords {
    let lo = b.lo.map(|v| v as i32 as u32);
    let i = |v: i64| v as i32 as u32;
    [
        lo[0],
        lo[1],
        lo[2],
        i(b.e),
        i(b.ov),
        b.dm() as u32,
        i(lbox.lo[0]),
        i(lbox.lo[1]),
        i(lbox.lo[2]),
        lbox.dims[0] as u32,
        lbox.dims[1] as u32,
        lbox.dims[2] as u32,
        b.coarse_dims[0] as u32,
        b.coarse_dims[1] as u32,
        b.dims[0] as u32,
        (b.dims[0] + b.dims[1]) as u32,
        b.unit.to_bits(),
        b.coarse_shift(),
        slot_words as u32,
        0,
    ]
}

#[cfg(test)]
mod tests {
    use super::LeafPool;

    /// Places the leaves of one tile; `(slot, fresh)` of each, or the error.
    fn tile(pool: &mut LeafPool, ids: &[u64]) -> Result<Vec<(usize, bool)>, String> {
        pool.begin_tile();
        let got = ids.iter().map(|&id| pool.place(id)).collect();
        pool.end_tile();
        got
    }

    /// Free slots go first, lowest first; then the least recently used leaf's slot (lowest
    /// first among a tile's), never one placed for the tile being built; resident leaves are
    /// not sent again.
    #[test]
    fn leaves_are_replaced_least_recently_used_first_but_never_mid_tile() {
        let mut pool = LeafPool::without_buffer(5, 4, 252);
        let got = tile(&mut pool, &[10, 11, 12]).unwrap();
        assert_eq!(got, [(0, true), (1, true), (2, true)]);
        // 11 is used again: 10 is now the least recently used, then 12.
        let got = tile(&mut pool, &[11, 13]).unwrap();
        assert_eq!(got, [(1, false), (3, true)]);
        let got = tile(&mut pool, &[14, 11, 15]).unwrap();
        assert_eq!(got, [(0, true), (1, false), (2, true)]);
        // A full pool: older tiles' leaves go (13, 11, 15), not 14, which this tile placed
        // first; a tile with more new leaves than slots is refused.
        let got = tile(&mut pool, &[14, 16, 17, 18]).unwrap();
        assert_eq!(got, [(0, false), (3, true), (1, true), (2, true)]);
        // Leaves last used by the same tile go lowest slot first: 14, 17 (not 16).
        let got = tile(&mut pool, &[21, 22]).unwrap();
        assert_eq!(got, [(0, true), (1, true)]);
        let e = tile(&mut pool, &[19, 20, 21, 22, 23]).unwrap_err();
        assert!(e.contains("full"), "{e}");
    }
}
