//! The coarse pass of `reconstruct`: the sampling density, then one streamed pass over the
//! store that splats the samples into the dense coarse grid, measures their noise and
//! solves it (or reads its checkpoint back).

use super::*;

/// The permit of what the coarse pass leaves for the rest of the run: the coarse solution,
/// the sampling density and the support's bits (`support_n` voxels an edge).
pub(super) fn acquire_coarse_results(plan: &Plan, support_n: u64, ctx: &Ctx) -> Result<Permit> {
    ctx.budget.acquire_now(
        plan.coarse_field_bytes() + plan.density_bytes() + Support::bytes(support_n),
        "the coarse solution, the sampling density and the trim support",
    )
}

/// What the coarse pass leaves: the coarse solution (its permit held while it lives), the
/// occupied leaf cells, and which voxels of the trim support hold points ([`support_grid`]).
pub(super) struct CoarsePass {
    pub(super) field: CoarseField,
    /// Every sample's share of the surface ([`crate::recon::density`]).
    pub(super) density: Arc<DensityGrid>,
    pub(super) _permit: Permit,
    pub(super) occupied: BTreeSet<CellKey>,
    pub(super) support: Support,
    pub(super) iterations: u32,
    /// The screening weight of the run (`standard`'s or `auto`'s choice, or the one given).
    pub(super) point_weight: f64,
    /// The Gaussian's width of the run, in voxels of each grid (measured, or the one given).
    pub(super) sigma_vox: f64,
    /// The samples' noise, measured beside the splat.
    pub(super) noise: NoiseStats,
}

/// The next wave of store cells from `*i` (advanced past them) up to `end`: at most `wave`
/// cells, within half of what the budget has free at `bytes(cell)` each, at least one; with
/// their bytes.
pub(super) fn cell_wave(
    i: &mut usize,
    end: usize,
    wave: usize,
    bytes: &impl Fn(usize) -> u64,
    ctx: &Ctx,
) -> (Vec<usize>, u64) {
    let free = ctx.budget.total().saturating_sub(ctx.budget.used());
    let (mut ids, mut sum) = (Vec::with_capacity(wave), 0u64);
    while *i < end && ids.len() < wave {
        let b = bytes(*i);
        if !ids.is_empty() && sum + b > free / 2 {
            break;
        }
        ids.push(*i);
        sum += b;
        *i += 1;
    }
    (ids, sum)
}

/// Points in a chunk of a split run's coarse pass, at least (whole store cells, in order):
/// the work item its shards claim, a fraction of a second of reading. Store cells of
/// ingest's default size make a chunk each.
pub(super) const COARSE_CHUNK_POINTS: u64 = 1 << 17;

/// The chunks of the store's cells a split run's coarse pass claims: consecutive cells, each
/// chunk closed once it holds [`COARSE_CHUNK_POINTS`]. A function of the store alone.
pub(super) fn coarse_chunks(store: &Store) -> Vec<Range<usize>> {
    let mut chunks = Vec::new();
    let (mut from, mut points) = (0, 0u64);
    for (i, c) in store.manifest.cells.iter().enumerate() {
        points += c.count;
        if points >= COARSE_CHUNK_POINTS {
            chunks.push(from..i + 1);
            (from, points) = (i + 1, 0);
        }
    }
    if from < store.manifest.cells.len() {
        chunks.push(from..store.manifest.cells.len());
    }
    chunks
}

/// How one of the coarse pass's two reads of the store computes, sizes, checkpoints and
/// sums its parts (one per store cell).
pub(super) struct CellParts<'a, P> {
    kind: CoarsePartKind,
    /// Bytes a store cell's read and part may hold at once, at most.
    cell_bytes: &'a (dyn Fn(usize) -> u64 + Sync),
    /// The part of store cell `i`.
    part: &'a (dyn Fn(usize) -> Result<P> + Sync),
    /// Bytes a part holds.
    size: fn(&P) -> u64,
    write: fn(&std::path::Path, &[P]) -> Result<()>,
    read: fn(&std::path::Path) -> Result<Vec<P>>,
}

/// One read of the store by the coarse pass: the part of every store cell, given to `add` in
/// cell order. One process reads the cells in waves and adds each wave's parts. A split run's
/// shards compute chunks of cells ([`coarse_chunks`]) as claimed work items, checkpointed in
/// the leaf directory, taking over in a second pass what other shards left undone (as the
/// leaf pass does); then every shard reads every chunk back and adds them in order. So `add`
/// sees the same parts in the same order wherever they were computed: the sums, and the
/// bits, are one process's for any shard count.
pub(super) fn over_cells<P: Send>(
    store: &Store,
    params: &ReconParams,
    dirs: &WorkDir,
    how: CellParts<P>,
    mut add: impl FnMut(Vec<P>) -> Result<()>,
    ctx: &Ctx,
) -> Result<()> {
    let wave = 2 * ctx.threads();
    let run = |cells: Range<usize>, sink: &mut dyn FnMut(Vec<P>) -> Result<()>| -> Result<()> {
        let mut i = cells.start;
        while i < cells.end {
            let (ids, bytes) = cell_wave(&mut i, cells.end, wave, &how.cell_bytes, ctx);
            // The coarse grid's permit is held: admitted without waiting (`tiles::admit_now`).
            let _permit = tiles::admit_now(ctx, bytes);
            let parts: Vec<P> = ctx.pool.install(|| {
                ids.par_iter()
                    .map(|&j| (how.part)(j))
                    .collect::<Result<_>>()
            })?;
            sink(parts)?;
        }
        Ok(())
    };
    if !params.run.shard.is_split() {
        return run(0..store.manifest.cells.len(), &mut add);
    }
    let chunks = coarse_chunks(store);
    let claims = Claims::new(&dirs.claims);
    let path = |c: usize| coarse_part_path(&dirs.leaves, how.kind, c);
    let mut here = 0;
    for &claiming in params.run.shard.passes() {
        for c in params.run.shard.order(chunks.len()) {
            if path(c).exists()
                || (claiming && !claims.take(&format!("{}-{c}", how.kind.name()))?)
            {
                continue;
            }
            let (mut held, mut permits) = (Vec::new(), Vec::new());
            run(chunks[c].clone(), &mut |parts| {
                permits.push(tiles::admit_now(ctx, parts.iter().map(how.size).sum()));
                held.extend(parts);
                Ok(())
            })?;
            (how.write)(&path(c), &held)?;
            here += 1;
        }
    }
    log::info!(
        "{}: {here} of {} chunks of store cells read here, the others' parts read back",
        how.kind.name(),
        chunks.len()
    );
    for c in 0..chunks.len() {
        let parts = (how.read)(&path(c))?;
        let _permit = tiles::admit_now(ctx, parts.iter().map(how.size).sum());
        add(parts)?;
    }
    Ok(())
}

/// Nodes per axis that the points of store cell `i` reach on a grid of `nodes` nodes over
/// the cube, at most (its octree cell's share of the grid, and a few for the kernels).
pub(super) fn cell_nodes(store: &Store, i: usize, nodes: u64) -> u64 {
    let level = store.manifest.cells[i].key.level();
    ((nodes >> level.min(63)) + 4).min(nodes + 1)
}

/// Pass 0: every point's sampling density, splatted onto a grid at the coarse spacing; each
/// store cell into a part of its own, the parts added in parallel over z-slabs of the grid
/// (the sums are integers: the same grid in any order, [`over_cells`]).
pub(super) fn density_pass(
    store: &Store,
    plan: &Plan,
    params: &ReconParams,
    dirs: &WorkDir,
    ctx: &Ctx,
) -> Result<DensityGrid> {
    let m = &store.manifest;
    // Charged with the coarse solve's scratch (`Plan::needs`).
    let mut grid = DensityGrid::new(&plan.cube, plan.coarse_cells());
    let layout = grid.layout();
    let stage = ctx.progress.stage("density", Some(m.point_count), "points");
    let nodes = plan.coarse_cells() + 1;
    let cell_bytes =
        |i: usize| m.cells[i].count * BATCH_POINT_BYTES + 4 * cell_nodes(store, i, nodes).pow(3);
    let part = |i: usize| {
        let b = store.read_cell(i)?;
        stage.inc(b.len() as u64);
        Ok(layout.part(&b.pos))
    };
    let how = CellParts {
        kind: CoarsePartKind::Density,
        cell_bytes: &cell_bytes,
        part: &part,
        size: DensityBox::bytes,
        write: write_density_parts,
        read: read_density_parts,
    };
    over_cells(
        store,
        params,
        dirs,
        how,
        |parts| {
            let parts: Vec<&DensityBox> = parts.iter().collect();
            ctx.pool.install(|| grid.add_parts(&parts));
            Ok(())
        },
        ctx,
    )?;
    grid.finish();
    stage.finish(None);
    Ok(grid)
}

/// Pass 1: splat every point into the coarse grid of `plan` (the top level), each normal
/// weighed by its sample's share of the surface (pass 0); collect the occupied leaf cells of
/// `fine` (the finest level), the noise in its voxels, the support's voxels holding points, and
/// the moments that refuse planar and linear inputs; solve. Each store cell's share
/// ([`CellSplat`]: its splat and screening aggregates apart from the grids, and the rest) is
/// computed on its own, in parallel; the shares are added in cell order, the grids' in
/// parallel over z-slabs ([`grid::add_boxes`], [`ScreenBuilder::add_parts`]), so the
/// bits are the same for any thread and shard count ([`over_cells`]).
pub(super) fn coarse_pass(
    store: &Store,
    fine: &Plan,
    plan: &Plan,
    params: &ReconParams,
    dirs: &WorkDir,
    ctx: &Ctx,
) -> Result<CoarsePass> {
    let m = &store.manifest;
    let cgrid = plan.coarse_grid();
    let (support_h, support_n) = support_grid(fine, plan, ctx.budget.total());
    let permit = ctx.budget.acquire_now(
        plan.coarse_scratch_bytes() + plan.density_bytes() + Support::bytes(support_n),
        "the coarse global solve and the sampling density",
    )?;
    let density = Arc::new(density_pass(store, plan, params, dirs, ctx)?);
    let stage = ctx.progress.stage("splat", Some(m.point_count), "points");
    let mut v = vec![[0f32; 3]; cgrid.len()];
    let mut occupied = BTreeSet::new();
    // Relative to the cube's corner, as the tile meshes it trims (`pipeline::tiles`).
    let origin = plan.cube.origin;
    let mut support = Support::new([0.0; 3], support_h, support_n);
    let locate = support.layout();
    let mut moments = Moments::new(m.bounds.min);
    // The samples aggregated per coarse voxel for the screening: one entry per occupied coarse
    // voxel, admitted as it grows.
    let screened = plan.point_weight > 0.0;
    let mut noise = NoiseStats::default();
    let mut screen = ScreenBuilder::with_slabs(&cgrid, ctx.threads());
    let mut screen_permit: Option<Permit> = None;
    let noise_every = screen::noise_cell_stride(m.point_count);
    let nodes = cgrid.n as u64;
    let cell_bytes = |i: usize| {
        let box_bytes = grid::SplatBox::bytes_within(cell_nodes(store, i, nodes));
        let screen_bytes = if screened {
            SCREEN_PART_ENTRY_BYTES * m.cells[i].count.min(box_bytes / 12)
        } else {
            0
        };
        m.cells[i].count * (BATCH_POINT_BYTES + NOISE_KEY_BYTES) + box_bytes + screen_bytes
    };
    // A store cell's share: its noise statistics, moments, occupied leaves and support
    // beside its splat and screening aggregates.
    let part = |j: usize| -> Result<CellSplat> {
        let mut b = store.read_cell(j)?;
        let noise = if j.is_multiple_of(noise_every) {
            NoiseStats::of(&b.pos, &b.normal, fine.cube.origin, fine.spacing)
        } else {
            NoiseStats::default()
        };
        weigh_normals(&mut b, plan.confidence, &density);
        let mut moments = Moments::new(m.bounds.min);
        // A cell's points are near each other: runs of one voxel or leaf are kept once as
        // they come, the rest once sorted.
        let (mut marks, mut leaves) = (Vec::new(), Vec::new());
        for p in &b.pos {
            let i = locate.index([0, 1, 2].map(|a| p[a] - origin[a])) as u64;
            if marks.last() != Some(&i) {
                marks.push(i);
            }
            let k = CellKey::new(fine.leaf_level, fine.cube.cell_coords(*p, fine.leaf_level));
            if leaves.last() != Some(&k) {
                leaves.push(k);
            }
            moments.add(*p);
        }
        marks.sort_unstable();
        marks.dedup();
        leaves.sort_unstable();
        leaves.dedup();
        stage.inc(b.len() as u64);
        Ok(CellSplat {
            splat: grid::splat_box(&cgrid, &b.pos, &b.normal),
            screen: if screened {
                ScreenBuilder::part(&cgrid, &b.pos)
            } else {
                Vec::new()
            },
            noise,
            moments: moments.sums(),
            marks,
            leaves,
        })
    };
    let how = CellParts {
        kind: CoarsePartKind::Splat,
        cell_bytes: &cell_bytes,
        part: &part,
        size: CellSplat::bytes,
        write: write_splat_parts,
        read: read_splat_parts,
    };
    let add = |parts: Vec<CellSplat>| -> Result<()> {
        for r in &parts {
            noise.add(r.noise);
            moments.merge(&Moments::with_sums(m.bounds.min, r.moments));
            r.marks.iter().for_each(|&i| support.mark_index(i as usize));
            occupied.extend(&r.leaves);
        }
        let boxes: Vec<&grid::SplatBox> = parts.iter().map(|r| &r.splat).collect();
        ctx.pool.install(|| grid::add_boxes(&cgrid, &boxes, &mut v));
        if screened {
            let aggregates: Vec<&[_]> = parts.iter().map(|r| &r.screen[..]).collect();
            ctx.pool.install(|| screen.add_parts(&aggregates));
            let held = screen_permit.as_ref().map_or(0, |p| p.bytes());
            if screen.bytes() > held {
                // Doubled ahead, as the map grows.
                screen_permit = Some(ctx.budget.acquire_now(
                    2 * screen.bytes(),
                    "the screening samples of the coarse solve",
                )?);
            }
        }
        Ok(())
    };
    over_cells(store, params, dirs, how, add, ctx)?;
    stage.finish(None);
    moments.check_not_flat(&store.dir)?;
    let stage = ctx.progress.stage("coarse", None, "solves");
    let point_weight = params.solve.point_weight.alpha(&noise);
    let sigma_vox = smoothing_on(
        params,
        &noise,
        density.sample_spacing(),
        plan.coarse_spacing(),
    );
    let screen = screen.finish(point_weight);
    let solved = Plan { sigma_vox, ..*plan };
    let (field, conv) = ctx.pool.install(|| solve_coarse(&solved, v, &screen));
    drop(screen);
    drop(screen_permit);
    // From here on only the solution and the density grid are held (the plan counted on
    // them for the leaf pass).
    drop(permit);
    let permit = acquire_coarse_results(plan, support_n, ctx)?;
    stage.finish(None);
    Ok(CoarsePass {
        field,
        density,
        _permit: permit,
        occupied,
        support,
        iterations: conv.iterations,
        point_weight,
        sigma_vox,
        noise,
    })
}

/// The Gaussian's width for a grid of spacing `h` (input units), in its voxels: `--smooth`
/// for samples of the measured `noise` lying `spacing` apart (input units).
pub(super) fn smoothing_on(
    params: &ReconParams,
    noise: &NoiseStats,
    spacing: Option<f64>,
    h: f64,
) -> f64 {
    params.solve.smoothing.voxels(noise, spacing.map(|s| s / h))
}

/// The coarse pass ([`coarse_pass`]) checkpointed in the work directory; or, where a resumed
/// run's predecessor or another shard left that checkpoint, its results read back, bit for
/// bit what the pass gives (the checkpoint lives beside the leaves', so it is dropped with
/// them when the plan changes). A shard that starts after another finished the pass, a
/// requeued task and a resumed run so skip the two reads of every point.
pub(super) fn coarse_or_checkpoint(
    store: &Store,
    fine: &Plan,
    plan: &Plan,
    params: &ReconParams,
    dirs: &WorkDir,
    ctx: &Ctx,
) -> Result<CoarsePass> {
    let path = coarse_path(&dirs.leaves);
    let found = params
        .run
        .reuses_checkpoints()
        .then(|| read_coarse(&path))
        .transpose()?
        .flatten();
    if let Some(c) = found {
        let bad = |what: &str| {
            Error::input(
                &path,
                format!("corrupt coarse checkpoint: {what} does not fit the plan"),
            )
        };
        let (support_h, support_n) = support_grid(fine, plan, ctx.budget.total());
        let permit = acquire_coarse_results(plan, support_n, ctx)?;
        if c.field.len() as u64 != plan.coarse_nodes.pow(3) {
            return Err(bad("the coarse solution"));
        }
        let density =
            DensityGrid::with_counts(&plan.cube, plan.coarse_cells(), c.density.into_owned())
                .ok_or_else(|| bad("the sampling density"))?;
        let support = Support::with_bits([0.0; 3], support_h, support_n, c.support.into_owned())
            .ok_or_else(|| bad("the support"))?;
        if c.occupied.iter().any(|k| k.level() != fine.leaf_level) {
            return Err(bad("an occupied leaf"));
        }
        // A function of the statistics read back, as the pass computed it.
        let sigma_vox = smoothing_on(
            params,
            &c.noise,
            density.sample_spacing(),
            plan.coarse_spacing(),
        );
        log::info!(
            "{}: the coarse pass's results read back ({} occupied leaves)",
            path.display(),
            c.occupied.len()
        );
        return Ok(CoarsePass {
            field: CoarseField::new(plan, c.field.into_owned()),
            density: Arc::new(density),
            _permit: permit,
            occupied: c.occupied.into_iter().collect(),
            support,
            iterations: c.iterations,
            point_weight: c.point_weight,
            sigma_vox,
            noise: c.noise,
        });
    }
    let c = coarse_pass(store, fine, plan, params, dirs, ctx)?;
    let field = c
        .field
        .dense_values()
        .ok_or_else(|| Error::Internal("the coarse pass gave a level's field".into()))?;
    write_coarse(
        &path,
        &CoarseCheckpoint {
            iterations: c.iterations,
            point_weight: c.point_weight,
            noise: c.noise,
            field: field.into(),
            density: c.density.counts().into(),
            support: c.support.bits().into(),
            occupied: c.occupied.iter().copied().collect(),
        },
    )?;
    Ok(c)
}
