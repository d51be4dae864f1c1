//! The leaf pass of `reconstruct`: the occupied leaves solved in parallel waves under the
//! budget, checkpointed, and their iso-value summed in Morton order.

use super::*;

/// Bytes a leaf of `plan` reads of one level above it ([`CoarseField::local`]): the details
/// of the (at most 8) leaves of that level near it, and their blend on a window of
/// `(E/r + 4)³` nodes (8 bytes a node for the sum, 4 for the values).
pub(super) fn window_bytes(plan: &Plan) -> u64 {
    let m = plan.detail_n() as u64;
    let w = plan.leaf_voxels / plan.coarse_ratio + 4;
    8 * 2 * m * m * m + 12 * w * w * w
}

/// What the leaf pass leaves: every occupied leaf, the refined ones, how many were reused, the
/// iso-value and the blend's fixed-point unit.
pub(super) struct LeafPass {
    pub(super) all: Vec<CellKey>,
    pub(super) refined: BTreeSet<CellKey>,
    pub(super) reused: usize,
    pub(super) iso: f64,
    pub(super) unit: f32,
    pub(super) solved: usize,
    pub(super) iterations: u64,
    /// What the leaves read.
    pub(super) read: SampleReads,
}

/// The samples a leaf pass's solved leaves read, each as often as a leaf's box holds it.
#[derive(Default)]
pub(super) struct SampleReads {
    /// Samples, one by one and summed alike.
    pub(super) points: u64,
    /// Of which summed per voxel.
    pub(super) summed: u64,
    /// The voxel sums holding those.
    pub(super) sums: u64,
}

impl SampleReads {
    /// Count a leaf's gathered samples.
    fn add(&mut self, p: &LeafPoints) {
        let summed: u64 = p.voxels.iter().map(|v| v.count as u64).sum();
        self.points += p.pos.len() as u64 + summed;
        self.summed += summed;
        self.sums += p.voxels.len() as u64;
    }
}

/// Pass 2: the occupied leaves of the coarse pass (taken from it), in Morton order, solved
/// in parallel waves, spilled to the work directory. Leaves checkpointed already (by a
/// resumed run, or by another shard) are summed from their checkpoints' headers. A shard
/// visits the leaves in its order ([`Shard::order`]); the iso-value is summed in Morton order
/// whoever solved each leaf.
#[allow(clippy::too_many_arguments)]
pub(super) fn leaf_pass(
    store: &Store,
    plan: &Plan,
    params: &ReconParams,
    leaves: BTreeSet<CellKey>,
    coarse: &CoarseField,
    unit: f32,
    dirs: &WorkDir,
    src: &mut PointSource,
    stage_name: &str,
    ctx: &Ctx,
) -> Result<LeafPass> {
    let leaves: Vec<CellKey> = leaves.into_iter().collect();
    // A solve, and the window of the levels above it reads: each level's details near it.
    let fine_bytes = plan.leaf_scratch_bytes() + coarse.levels() as u64 * window_bytes(plan);
    let stage = ctx
        .progress
        .stage(stage_name, Some(leaves.len() as u64), "leaves");
    let (mut solved, mut iterations) = (0, 0u64);
    let mut read = SampleReads::default();
    let rule = LeafRule {
        tolerance: params.solve.error * store.manifest.bounds.diagonal(),
        min_points: params.solve.least_leaf_points(plan.leaf_voxels),
    };
    let solvers = LeafSolvers::new(plan).with_gpu(params.run.gpu_solve)?;
    let reuse = params.run.reuses_checkpoints();
    let claims = Claims::new(&dirs.claims);
    let order = params.run.shard.order(leaves.len());
    let mut outcomes: Vec<Option<LeafOutcome>> = vec![None; leaves.len()];
    // With the fine solves on a GPU a worker waits for its leaf's batch (a third of its time
    // on an H100 with 16 cores): twice the workers keep the cores busy meanwhile, and more
    // leaves wait at once, so the device's batches grow. The budget still bounds the
    // solves at once.
    let gpu_pool = match solvers.gpu_stats() {
        Some(_) => Some(crate::exec::pool(2 * ctx.threads())?),
        None => None,
    };
    let pool = gpu_pool.as_ref().unwrap_or(&ctx.pool);
    let workers = pool.current_num_threads();
    let wave = 2 * workers;
    let solver = WaveSolver {
        plan,
        unit,
        solvers: &solvers,
        coarse,
        rule: &rule,
        dirs,
        stage: &stage,
        pool,
        fine_bytes,
    };
    // Room for a whole wave of solves and its points (as much as twice the plan's cache).
    let reads = src.begin_pass(workers as u64 * fine_bytes, ctx);
    for &claiming in params.run.shard.passes() {
        let mut next = 0;
        loop {
            let pick = WavePick {
                order: &order,
                leaves: &leaves,
                outcomes: &outcomes,
                reuse,
                claims: claiming.then_some(&claims),
                dirs,
            };
            let wave_idx = pick.next(&mut next, wave)?;
            if wave_idx.is_empty() {
                break;
            }
            let keys: Vec<CellKey> = wave_idx.iter().map(|&i| leaves[i]).collect();
            let gathered = src.gather_wave(&ctx.pool, &keys)?;
            let mut todo = Vec::with_capacity(wave_idx.len());
            for (&i, p) in wave_idx.iter().zip(gathered) {
                read.add(&p);
                todo.push((leaves[i], p));
            }
            let res = solver.solve_wave(&todo, ctx)?;
            for (r, &i) in res.into_iter().zip(&wave_idx) {
                let d = r?;
                iterations += d.iterations as u64;
                solved += d.detail.is_some() as usize;
                outcomes[i] = Some((d.iso_sum, d.iso_count, d.detail.is_some()));
            }
        }
    }
    let reused = read_unvisited(&leaves, &mut outcomes, dirs, ctx)?;
    stage.inc(reused as u64);
    let (iso_sum, iso_count, refined) = sum_outcomes(outcomes, &leaves)?;
    log_gpu_solves(&solvers);
    src.end_pass(reads, stage_name);
    stage.finish(None);
    let iso = if iso_count > 0 {
        iso_sum / iso_count as f64
    } else {
        0.0
    };
    if !iso.is_finite() {
        return Err(Error::input(
            &store.dir,
            format!(
                "no surface: the field's iso-value (its mean at the input points) is {iso}; the solve gave no usable field for these points"
            ),
        ));
    }
    Ok(LeafPass {
        all: leaves,
        refined,
        reused,
        iso,
        unit,
        solved,
        iterations,
        read,
    })
}

/// What a leaf's solve left for the pass's sums: its iso-value sum and count, and whether it
/// was refined.
pub(super) type LeafOutcome = (f64, u64, bool);

/// The choice of a wave's leaves: in the shard's order, those without an outcome, no
/// checkpoint to reuse and (when claiming) a claim taken.
pub(super) struct WavePick<'a> {
    order: &'a [usize],
    leaves: &'a [CellKey],
    outcomes: &'a [Option<LeafOutcome>],
    reuse: bool,
    claims: Option<&'a Claims>,
    dirs: &'a WorkDir,
}

impl WavePick<'_> {
    /// Up to `wave` leaves from `next` on (advanced past those looked at).
    fn next(&self, next: &mut usize, wave: usize) -> Result<Vec<usize>> {
        let mut wave_idx = Vec::with_capacity(wave);
        while *next < self.order.len() && wave_idx.len() < wave {
            let (i, k) = (self.order[*next], self.leaves[self.order[*next]]);
            *next += 1;
            if self.outcomes[i].is_some()
                || (self.reuse && leaf_path(&self.dirs.leaves, k).exists())
            {
                continue;
            }
            if let Some(claims) = self.claims
                && !claims.take(&format!("L{}", k.file_name()))?
            {
                continue;
            }
            wave_idx.push(i);
        }
        Ok(wave_idx)
    }
}

/// What every solve of the leaf pass shares.
pub(super) struct WaveSolver<'a> {
    plan: &'a Plan,
    unit: f32,
    solvers: &'a LeafSolvers,
    coarse: &'a CoarseField,
    rule: &'a LeafRule,
    dirs: &'a WorkDir,
    stage: &'a Stage,
    pool: &'a rayon::ThreadPool,
    /// A solve's scratch and the window of the levels above it.
    fine_bytes: u64,
}

impl WaveSolver<'_> {
    /// Solve and checkpoint a wave's leaves in parallel, in groups that fit the budget: at
    /// most one solve a worker, and no more at once than fit in what is free (at least one).
    fn solve_wave(
        &self,
        todo: &[(CellKey, LeafPoints)],
        ctx: &Ctx,
    ) -> Result<Vec<Result<LeafDetail>>> {
        let (fine_bytes, workers) = (self.fine_bytes, self.pool.current_num_threads());
        let pts_bytes: u64 = todo.iter().map(|(_, p)| p.bytes()).sum();
        let free = ctx.budget.total().saturating_sub(ctx.budget.used());
        let at_once =
            (free.saturating_sub(pts_bytes) / fine_bytes.max(1)).clamp(1, workers as u64) as usize;
        let bytes = fine_bytes * todo.len().min(at_once) as u64 + pts_bytes;
        // Over the whole budget it is an error that names the sizes; otherwise it is
        // admitted without waiting on the permits this thread holds.
        let _permit = if bytes > ctx.budget.total() {
            Some(ctx.budget.acquire(bytes, "a wave of leaf solves")?)
        } else {
            tiles::admit_now(ctx, bytes)
        };
        let group = if at_once < workers {
            at_once
        } else {
            todo.len().max(1)
        };
        let mut res: Vec<Result<LeafDetail>> = Vec::with_capacity(todo.len());
        for g in todo.chunks(group) {
            res.extend(self.pool.install(|| {
                g.par_iter()
                    .map(|(k, p)| {
                        let d = refine_leaf(
                            self.plan,
                            self.unit,
                            self.solvers,
                            *k,
                            p,
                            self.coarse,
                            self.rule,
                        )?;
                        write_leaf(&self.dirs.leaves, *k, &d)?;
                        self.stage.inc(1);
                        Ok(d)
                    })
                    .collect::<Vec<_>>()
            }));
        }
        Ok(res)
    }
}

/// The leaves solved before (a resumed run) or by other shards: their outcomes from their
/// checkpoints' headers. Returns how many.
pub(super) fn read_unvisited(
    leaves: &[CellKey],
    outcomes: &mut [Option<LeafOutcome>],
    dirs: &WorkDir,
    ctx: &Ctx,
) -> Result<usize> {
    let rest: Vec<usize> = (0..leaves.len())
        .filter(|&i| outcomes[i].is_none())
        .collect();
    let sums: Vec<Result<LeafSummary>> = ctx.pool.install(|| {
        rest.par_iter()
            .map(|&i| read_leaf_summary(&dirs.leaves, leaves[i]))
            .collect()
    });
    for (&i, r) in rest.iter().zip(sums) {
        let d = r?;
        outcomes[i] = Some((d.iso_sum, d.iso_count, d.has_detail));
    }
    Ok(rest.len())
}

/// The iso-value's sum and count and the refined leaves, in Morton order, as one process sums
/// them: the same iso-value for any shard count.
pub(super) fn sum_outcomes(
    outcomes: Vec<Option<LeafOutcome>>,
    leaves: &[CellKey],
) -> Result<(f64, u64, BTreeSet<CellKey>)> {
    let (mut iso_sum, mut iso_count) = (0.0, 0u64);
    let mut refined = BTreeSet::new();
    for (o, k) in outcomes.into_iter().zip(leaves) {
        let (s, c, is_refined) =
            o.ok_or_else(|| Error::Internal(format!("leaf {k:?} was not visited")))?;
        iso_sum += s;
        iso_count += c;
        if is_refined {
            refined.insert(*k);
        }
    }
    Ok((iso_sum, iso_count, refined))
}

/// The GPU leaf solves' figures, in the log, when the device solved them.
pub(super) fn log_gpu_solves(solvers: &LeafSolvers) {
    if let Some((name, g)) = solvers.gpu_stats() {
        log::info!(
            "GPU leaf solves on {name}: {} leaves in {} batches ({:.1} a batch, {} submissions), device thread busy {:.2} s (upload {:.2} s, kernels and flag reads {:.2} s, read-back {:.2} s), idle {:.2} s; workers: host side {:.2} s, waiting {:.2} s{}",
            g.leaves,
            g.batches,
            g.leaves as f64 / g.batches.max(1) as f64,
            g.submissions,
            g.busy_s,
            g.upload_s,
            g.kernel_s,
            g.read_s,
            g.idle_s,
            g.host_s,
            g.wait_s,
            if g.failed > 0 {
                format!(
                    ", {} leaves solved on the CPU after a GPU failure",
                    g.failed
                )
            } else {
                String::new()
            }
        );
    }
}
