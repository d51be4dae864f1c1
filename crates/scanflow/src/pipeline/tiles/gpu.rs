//! GPU extraction of a wave of tiles: the fields built and marching cubes run on the device
//! while the pool fits and writes the tiles already extracted; the device's totals for the log.

use super::*;

/// What a wave's GPU extraction shares between the feeding thread and the pool.
pub(super) struct GpuWave<'w, 'a> {
    pub(super) job: &'w TileJob<'w>,
    pub(super) points: &'w SharedPoints<'a>,
    pub(super) loaded: &'w [LoadedTile],
    pub(super) near_pts: &'w [Option<NearPoints>],
    pub(super) geom: &'w GridGeom,
}

/// Extract a wave on the GPU: a thread feeds the device tile after tile (fields built there
/// from the leaf grids) while the pool finishes the tiles it has extracted (fit, colour, trim,
/// checkpoint). Results come back in the wave's order.
pub(super) fn extract_gpu(
    w: &GpuWave,
    g: &mut GpuExtractor,
    gpu_totals: &mut GpuTotals,
    pool: &rayon::ThreadPool,
) -> Result<Vec<Result<(u64, TileMesh)>>> {
    type Slot = Mutex<Option<Result<(u64, TileMesh)>>>;
    let job = w.job;
    let plan = job.plan;
    let own = pou::leaf_weights(plan.leaf_voxels as i64, plan.overlap_voxels as i64);
    let done: Vec<Slot> = w.loaded.iter().map(|_| Mutex::new(None)).collect();
    let start = Instant::now();
    let (tx, rx) = crossbeam_channel::bounded::<(usize, Result<TileMesh>)>(GPU_QUEUE);
    std::thread::scope(|s| -> Result<()> {
        let (loaded, own, geom) = (w.loaded, &own, w.geom);
        let gpu_totals = &mut *gpu_totals;
        s.spawn(move || {
            for (i, (_, lo, ds)) in loaded.iter().enumerate() {
                let Some(ds) = ds else { continue };
                let mut mesh = TileMesh::default();
                // The host side of the GPU call uses rayon: keep it on our pool.
                let t0 = Instant::now();
                let b = tile_blend(plan, own, job.coarse, job.unit, *lo, ds);
                gpu_totals.blend += t0.elapsed().as_secs_f64();
                let r = b.and_then(|b| {
                    pool.install(|| g.extract_blend(&b, job.iso as f32, geom, &mut mesh))
                        .map(|st| {
                            gpu_totals.add(&st);
                            mesh
                        })
                });
                if tx.send((i, r)).is_err() {
                    break;
                }
            }
        });
        for (i, (tt, _, ds)) in loaded.iter().enumerate() {
            if let (None, Ok(mut d)) = (ds, done[i].lock()) {
                *d = Some(read_tile(&tile_path(job.tiles_dir, *tt)).map(|m| (*tt, m)));
            }
        }
        pool.in_place_scope(|sc| {
            for (i, r) in rx {
                let (done, near_pts, points) = (&done, w.near_pts, w.points);
                sc.spawn(move |_| {
                    let tt = loaded[i].0;
                    let r = r.and_then(|m| finish_tile(job, points, tt, m, &near_pts[i]));
                    if let Ok(mut d) = done[i].lock() {
                        *d = Some(r);
                    }
                });
            }
        });
        Ok(())
    })?;
    gpu_totals.waves += start.elapsed().as_secs_f64();
    Ok(done
        .into_iter()
        .map(|d| {
            d.into_inner()
                .ok()
                .flatten()
                .unwrap_or_else(|| Err(Error::Internal("a tile was not extracted".into())))
        })
        .collect())
}

/// What the GPU did over a run, for the log.
#[derive(Debug, Default)]
pub(super) struct GpuTotals {
    tiles: u64,
    on_device: u64,
    fell_back: u64,
    leaves_sent: u64,
    bytes: u64,
    upload: f64,
    kernels: f64,
    download: f64,
    host: f64,
    /// The feeding thread's time building blend tables on the host.
    blend: f64,
    /// Wall time of the waves' GPU extraction (feeding and finishing together).
    waves: f64,
}

impl GpuTotals {
    fn add(&mut self, s: &crate::extract::GpuStats) {
        self.tiles += 1;
        self.on_device += s.field_on_gpu as u64;
        self.fell_back += s.fell_back as u64;
        self.leaves_sent += s.leaves_sent;
        self.bytes += s.upload_bytes;
        self.upload += s.upload_secs;
        self.kernels += s.kernel_secs;
        self.download += s.download_secs;
        self.host += s.host_secs;
    }

    pub(super) fn log(&self) {
        log::info!(
            "GPU: {} tiles in {:.2} s (upload {:.2} s, kernels {:.2} s, read-back {:.2} s, host \
             {:.2} s; blend tables on the host {:.2} s) of the waves' {:.2} s, {} with the field \
             built on the device, {} on the CPU after a GPU failure; {} leaf grids and {:.1} MB \
             sent",
            self.tiles,
            self.upload + self.kernels + self.download + self.host,
            self.upload,
            self.kernels,
            self.download,
            self.host,
            self.blend,
            self.waves,
            self.on_device,
            self.fell_back,
            self.leaves_sent,
            self.bytes as f64 / 1e6
        );
    }
}
