//! Where welded tiles go: the streamed mesh writer (or the merge's), the vertices'
//! attributes and their area-weighted normal sums, summed once a vertex's last tile is welded.

use super::*;

/// What the output's vertices carry from the tiles.
#[derive(Debug, Clone, Copy)]
pub(in crate::pipeline) struct VertexAttrs {
    pub color: bool,
    pub intensity: bool,
    pub density: bool,
}

/// The welder and the writer of a run's mesh: tiles in, in Morton order; vertices and
/// triangles out as soon as they are final (with their normals once their last triangle is
/// known).
pub(in crate::pipeline) struct MeshSink {
    writer: std::cell::RefCell<MeshWriter>,
    welder: Welder,
    /// The cube's lower corner, which the writer adds back to the tiles' positions.
    origin: [f64; 3],
    geom: GridGeom,
    tile: u64,
    ntiles_axis: u64,
    spacing: f64,
    /// Vertex normals being summed, with `--out-normals`.
    normals: Option<NormalSums>,
    /// The picture being drawn, with `--preview` or `--report`.
    preview: Option<Preview>,
    /// Small islands are dropped when the mesh is written (`--trim-islands`).
    islands: bool,
}

/// The area-weighted normals of the vertices whose triangles are not all welded yet.
///
/// A vertex's normal is the sum of its triangles' cross products `(b − a) × (c − a)`, each
/// taken from the corner with the smallest edge key and the sum taken in sorted order, so it
/// is the same number whichever tile holds which triangle (any `--tile`, any shard count).
/// A vertex is complete when the welder releases it ([`Welder::released`]); until then it
/// holds its triangles' vectors (memory follows the welder's frontier).
#[derive(Default)]
pub(super) struct NormalSums {
    /// Each incomplete vertex's triangle vectors, by global index.
    pending: HashMap<u64, Vec<[f64; 3]>>,
}

impl NormalSums {
    /// Add the triangles of `mesh` (its vertices' global indices `global`), then give the
    /// writer the normals of the vertices `done`.
    fn add(
        &mut self,
        mesh: &TileMesh,
        global: &[u64],
        done: impl IntoIterator<Item = u64>,
        writer: &mut MeshWriter,
    ) -> Result<()> {
        for t in &mesh.triangles {
            let t = t.map(|i| i as usize);
            // From the corner with the smallest key, winding kept.
            let r = (0..3)
                .min_by_key(|&k| mesh.keys[t[k]].0)
                .expect("three corners");
            let [a, b, c] = [t[r], t[(r + 1) % 3], t[(r + 2) % 3]].map(|i| mesh.positions[i]);
            let n = cross(sub(b, a), sub(c, a));
            for &i in &t {
                self.pending.entry(global[i]).or_default().push(n);
            }
        }
        self.release(done, writer)
    }

    /// Give the writer the normals of the vertices `done`.
    fn release(
        &mut self,
        done: impl IntoIterator<Item = u64>,
        writer: &mut MeshWriter,
    ) -> Result<()> {
        for g in done {
            let mut ns = self.pending.remove(&g).unwrap_or_default();
            ns.sort_by(|p, q| {
                (p[0].total_cmp(&q[0]))
                    .then(p[1].total_cmp(&q[1]))
                    .then(p[2].total_cmp(&q[2]))
            });
            let s = ns.iter().fold([0f64; 3], |s, n| add(s, *n));
            let len = norm(s);
            let unit = if len > 0.0 && len.is_finite() {
                s.map(|x| (x / len) as f32)
            } else {
                [0.0; 3]
            };
            writer.normal(g, unit)?;
        }
        Ok(())
    }
}

impl MeshSink {
    /// A sink writing `out` for tiles of `plan`, its vertices carrying `attrs`.
    pub(in crate::pipeline) fn create(
        plan: &Plan,
        bounds: &Aabb,
        attrs: VertexAttrs,
        out: &MeshTarget,
    ) -> Result<MeshSink> {
        // Vertices are written in float32 only where it keeps the input's resolution
        // (georeferenced coordinates get float64; see `io::mesh_write`).
        let format = VertexFormat {
            normals: out.normals,
            density: attrs.density,
            ..VertexFormat::for_cube(
                plan.cube.origin,
                plan.cube.size,
                attrs.color,
                attrs.intensity,
            )
        };
        let mut writer = MeshWriter::create(&out.path, out.format, format)?;
        if let Some(r) = out.islands {
            writer.drop_islands(r);
        }
        Ok(MeshSink {
            writer: std::cell::RefCell::new(writer),
            islands: out.islands.is_some(),
            welder: Welder::new(),
            origin: plan.cube.origin,
            geom: GridGeom {
                origin: [0.0; 3],
                h: plan.spacing,
                n: plan.fine_cells,
            },
            tile: plan.tile,
            ntiles_axis: plan.fine_cells / plan.tile,
            spacing: plan.spacing,
            normals: out.normals.then(NormalSums::default),
            preview: out.preview.map(|side| Preview::new(bounds, side)),
        })
    }

    /// Weld tile `tt`'s mesh (tiles come in increasing Morton order) and write what is final.
    pub(in crate::pipeline) fn add(&mut self, tt: u64, mesh: &TileMesh) -> Result<()> {
        let (geom, tile, n, origin) = (self.geom, self.tile, self.ntiles_axis, self.origin);
        let last_tile = |key: EdgeKey| -> u64 {
            let (node, _axis) = geom.decode_edge(key);
            morton3(node.map(|v| (v / tile).min(n - 1) as u32))
        };
        // Both welder callbacks write to the one writer.
        let writer = &self.writer;
        self.welder.add_tile(
            tt,
            mesh,
            last_tile,
            |_, i, p| {
                writer.borrow_mut().vertex_with(
                    [0, 1, 2].map(|d| p[d] + origin[d]),
                    mesh.colors.get(i).copied(),
                    mesh.intensity.get(i).copied(),
                    mesh.density.get(i).copied(),
                )
            },
            |tri| writer.borrow_mut().triangle(tri),
        )?;
        if let Some(sums) = self.normals.as_mut() {
            let (global, done) = (self.welder.tile_indices(), self.welder.released());
            sums.add(
                mesh,
                global,
                done.iter().copied(),
                &mut self.writer.borrow_mut(),
            )?;
        }
        if let Some(pv) = self.preview.as_mut() {
            let world = |i: u32| {
                let p = mesh.positions[i as usize];
                [0, 1, 2].map(|d| p[d] + origin[d])
            };
            for t in &mesh.triangles {
                let colors = (!mesh.colors.is_empty()).then(|| t.map(|i| mesh.colors[i as usize]));
                pv.triangle(t.map(world), colors);
            }
        }
        Ok(())
    }

    /// Complete the mesh: vertices, faces and the welder's largest frontier. A mesh without a
    /// triangle is an error naming `input` (nothing appears under the output's name).
    pub(in crate::pipeline) fn finish(
        self,
        input: &Path,
        iso: f64,
        depth: u32,
        ctx: &Ctx,
    ) -> Result<TileStats> {
        let mut writer = self.writer.into_inner();
        // Vertices whose last tiles held no surface are complete now.
        if let Some(mut sums) = self.normals {
            sums.release(self.welder.held(), &mut writer)?;
        }
        if writer.triangles() == 0 {
            // Dropping the writer removes its temporary files.
            return Err(Error::input(
                input,
                format!(
                    "no surface: the field never crosses its iso-value {iso} inside the cube, so the mesh would be empty (do the points and normals describe a surface? at depth {depth}, a voxel is {:e} across)",
                    self.spacing
                ),
            ));
        }
        let _permit = match self.islands {
            true => Some(ctx.budget.acquire(
                crate::io::islands::BYTES_PER_VERTEX * writer.vertices(),
                &format!(
                    "the connected pieces of the mesh ({})",
                    crate::error::Setting::TrimIslands
                ),
            )?),
            false => None,
        };
        let ws = writer.finish()?;
        Ok(TileStats {
            vertices: ws.vertices,
            faces: ws.faces,
            tiles: 0,
            peak_frontier: self.welder.peak_frontier(),
            preview: self.preview,
        })
    }
}
