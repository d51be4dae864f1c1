//! `spectrum`: the patch layout, power spectra of chosen patches and a summary (the
//! [`spectral`](crate::spectral) module docs give the math), from pass 1 of
//! [`spectral`](super::spectral) with the heights kept as approximated.

use std::path::Path;
use std::sync::Mutex;

use super::spectral::{SpectralParams, SpectralStats, Tally, check_store, needs_double, pass1};
use crate::error::{Error, Result};
use crate::exec::Ctx;
use crate::fs::atomic::{self, Durability};
use crate::io::ply_write::{PointFileOptions, PointPlyWriter};
use crate::spectral::patch::{PatchWork, Treatment};
use crate::store::Store;
use crate::types::{Attributes, PointBatch};

/// A drawn spectrum: cell, patch in cell, PNG bytes, grid size.
type Picture = (usize, usize, Vec<u8>, [u32; 2]);

/// Radial band edges of `spectrum`'s energy summary, relative to the Nyquist frequency.
pub const BAND_EDGES: [f64; 6] = [0.0, 0.125, 0.25, 0.5, 0.75, 1.5];

/// Least side of a spectrum image, pixels (small grids are enlarged).
const IMAGE_SIDE: usize = 128;

/// What `spectrum` wrote besides its statistics.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct SpectrumReport {
    /// The layout and height-field statistics.
    pub stats: SpectralStats,
    /// Band edges of `band_energy`.
    pub band_edges: Vec<f64>,
    /// Share of the height fields' energy (their mean plane removed) in each band, over all
    /// patches.
    pub band_energy: Vec<f64>,
    /// The power-spectrum images written, with their patches.
    pub images: Vec<SpectrumImage>,
}

/// One power-spectrum image.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct SpectrumImage {
    /// File name inside the output directory.
    pub file: String,
    /// Global patch number (as in the layout file).
    pub patch: u64,
    /// Store cell and patch within it.
    pub cell: usize,
    /// Grid size.
    pub grid: [u32; 2],
    /// Members.
    pub members: u32,
}

/// Analyse `store`'s patches: write `dir/layout.ply` (every point with its patch's number
/// and a colour for it), power-spectrum images (`dir/spectrum-*.png`) of the first patch of
/// `images` cells spread evenly over the store, and `dir/summary.json`.
pub fn spectrum(
    store: &Store,
    dir: &Path,
    images: usize,
    params: &SpectralParams,
    ctx: &Ctx,
) -> Result<SpectrumReport> {
    check_store(store)?;
    let n = store.manifest.cells.len();
    let chosen = chosen_patches(store, images, params.layout.patch_max);
    let mut tally = Tally::new(store);
    let staging = atomic::TempDir::create(dir)?;
    let opts = PointFileOptions {
        double: needs_double(&store.manifest.cube),
        scalar: Some("patch".to_string()),
    };
    let attrs = Attributes {
        normal: true,
        color: true,
        ..Attributes::default()
    };
    let mut layout_ply = PointPlyWriter::create_with(
        &staging.path().join("layout.ply"),
        tally.st.points_in,
        attrs,
        opts,
    )?;
    let energies: Mutex<Vec<(usize, usize, Vec<f64>)>> = Mutex::new(Vec::new());
    let pictures: Mutex<Vec<Picture>> = Mutex::new(Vec::new());
    let raw = |c: usize, k: usize, w: &mut PatchWork| {
        let g = &w.raw;
        let e = crate::spectral::filter::band_energy(
            &g.h,
            g.nu,
            g.nv,
            &BAND_EDGES,
            &mut w.fft,
            &mut w.filt,
        );
        if let Ok(mut v) = energies.lock() {
            v.push((c, k, e));
        }
        if chosen.contains(&(c, k)) {
            let img = power_png(&w.raw, &mut w.fft);
            if let Ok(mut v) = pictures.lock() {
                v.push((c, k, img, [g.nu as u32, g.nv as u32]));
            }
        }
    };
    let mut next_id = 0u64;
    let mut first_of_cell = vec![0u64; n];
    let mut members_of: std::collections::BTreeMap<(usize, usize), u32> = Default::default();
    let quiet = SpectralParams {
        resume: false,
        ..params.clone()
    };
    pass1(
        store,
        &Treatment::Keep,
        &quiet,
        ctx,
        &mut tally,
        |c, b, f| {
            first_of_cell[c] = next_id;
            for &(cc, k) in chosen.iter().filter(|x| x.0 == c) {
                members_of.insert((cc, k), f.patches.get(k).map_or(0, |p| p.members));
            }
            let mut out = PointBatch {
                pos: b.pos.clone(),
                normal: b.normal.clone(),
                ..Default::default()
            };
            let ids: Vec<f32> = f
                .patch_of
                .iter()
                .map(|&k| {
                    if k == u32::MAX {
                        -1.0
                    } else {
                        (next_id + k as u64) as f32
                    }
                })
                .collect();
            out.color = f
                .patch_of
                .iter()
                .map(|&k| {
                    if k == u32::MAX {
                        [32768; 4]
                    } else {
                        patch_colour(next_id + k as u64)
                    }
                })
                .collect();
            next_id += f.patches.len() as u64;
            layout_ply.write_with(&out, Some(&ids))
        },
        Some(&raw),
    )?;
    layout_ply.finish()?;
    let mut st = tally.finish();
    st.points_out = st.points_in;
    let mut e = energies.into_inner().unwrap_or_default();
    e.sort_by_key(|x| (x.0, x.1));
    let mut band = vec![0f64; BAND_EDGES.len() - 1];
    for (_, _, v) in &e {
        for (b, x) in band.iter_mut().zip(v) {
            *b += x;
        }
    }
    let total: f64 = band.iter().sum();
    if total > 0.0 {
        band.iter_mut().for_each(|b| *b /= total);
    }
    let mut pics = pictures.into_inner().unwrap_or_default();
    pics.sort_by_key(|p| (p.0, p.1));
    let mut report = SpectrumReport {
        stats: st,
        band_edges: BAND_EDGES.to_vec(),
        band_energy: band,
        images: Vec::new(),
    };
    for (c, k, png, grid) in pics {
        let id = first_of_cell[c] + k as u64;
        let file = format!("spectrum-{id:06}.png");
        atomic::write(&staging.path().join(&file), &png, Durability::Renamed)?;
        report.images.push(SpectrumImage {
            file,
            patch: id,
            cell: c,
            grid,
            members: members_of.get(&(c, k)).copied().unwrap_or(0),
        });
    }
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| Error::Internal(format!("summary.json: {e}")))?;
    atomic::write(
        &staging.path().join("summary.json"),
        json.as_bytes(),
        Durability::Renamed,
    )?;
    staging.commit(dir)?;
    Ok(report)
}

/// The patches (cell, patch in cell) whose spectra `spectrum` draws: `images` of them spread
/// over the cells in Morton order and over the patches within a cell (a cell's patch count is
/// estimated from its points and the largest patch size).
fn chosen_patches(store: &Store, images: usize, patch_max: usize) -> Vec<(usize, usize)> {
    let cells = &store.manifest.cells;
    let n = cells.len();
    if images == 0 || n == 0 {
        return Vec::new();
    }
    let per = images.div_ceil(n);
    let mut out = Vec::new();
    for i in 0..images.min(n) {
        let c = i * n / images.min(n);
        let stride = (cells[c].count as usize / patch_max.max(1) / per).max(1);
        out.extend((0..per).map(|j| (c, j * stride)));
    }
    out.truncate(images);
    out
}

/// A colour for patch `id`, far from its neighbours' (golden-ratio hues).
fn patch_colour(id: u64) -> [u16; 4] {
    let h = (id as f64 * 0.618_033_988_75).fract() * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    let c = |v: f64| (40000.0 * v + 20000.0) as u16;
    [c(r), c(g), c(b), 65535]
}

/// The log power spectrum of a grid's heights (mean removed), DC at the centre, as an 8-bit
/// grey PNG spanning six decades below its peak.
fn power_png(g: &crate::spectral::sda::Grid, fft: &mut crate::spectral::fft::Fft2) -> Vec<u8> {
    let mean = g.h.iter().sum::<f64>() / g.h.len().max(1) as f64;
    let h: Vec<f64> = g.h.iter().map(|x| x - mean).collect();
    let mut s = crate::spectral::fft::Spectrum::default();
    fft.forward(&h, g.nu, g.nv, &mut s);
    let p = s.power_image();
    let top = p.iter().copied().fold(0f64, f64::max).max(1e-300);
    let scale = (IMAGE_SIDE / g.nu.min(g.nv).max(1)).max(1);
    let (w, hh) = (g.nu * scale, g.nv * scale);
    let mut px = vec![0u8; w * hh];
    for y in 0..hh {
        for x in 0..w {
            let v = p[(y / scale) * g.nu + x / scale].max(top * 1e-6);
            px[y * w + x] = (255.0 * (1.0 + (v / top).log10() / 6.0))
                .round()
                .clamp(0.0, 255.0) as u8;
        }
    }
    let mut out = Vec::new();
    {
        let mut e = png::Encoder::new(&mut out, w as u32, hh as u32);
        e.set_color(png::ColorType::Grayscale);
        e.set_depth(png::BitDepth::Eight);
        if let Ok(mut wr) = e.write_header() {
            let _ = wr.write_image_data(&px);
        }
    }
    out
}
