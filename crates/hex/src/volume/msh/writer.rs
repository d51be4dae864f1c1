//! Writing gmsh MSH 4.1 ASCII: one volume entity with its bounding box, one node block, one
//! element block and one `$ElementData` per cell field.

use std::io::Write;

use crate::volume::{Cell, fmt_f64};

/// Write `verts` and `cells` as gmsh MSH 4.1 ASCII: one volume entity, one node block, one
/// element block, one `$ElementData` per field of `cell_data`.
pub(in crate::volume) fn write<const K: usize>(
    w: &mut impl Write,
    verts: &[[f64; 3]],
    cells: &[[u32; K]],
    kind: Cell,
    cell_data: &[(&str, &[f64])],
) -> std::io::Result<()> {
    let etype = match kind {
        Cell::Tet => 4,
        Cell::Hex => 5,
    };
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in verts {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if verts.is_empty() {
        lo = [0.0; 3];
        hi = [0.0; 3];
    }
    let (nv, nc) = (verts.len(), cells.len());
    writeln!(w, "$MeshFormat\n4.1 0 8\n$EndMeshFormat")?;
    writeln!(w, "$Entities\n0 0 0 1")?;
    writeln!(
        w,
        "1 {} {} {} {} {} {} 0 0",
        fmt_f64(lo[0]),
        fmt_f64(lo[1]),
        fmt_f64(lo[2]),
        fmt_f64(hi[0]),
        fmt_f64(hi[1]),
        fmt_f64(hi[2])
    )?;
    writeln!(w, "$EndEntities")?;
    writeln!(w, "$Nodes\n1 {nv} {} {nv}", nv.min(1))?;
    writeln!(w, "3 1 0 {nv}")?;
    for i in 1..=nv {
        writeln!(w, "{i}")?;
    }
    for p in verts {
        writeln!(w, "{} {} {}", fmt_f64(p[0]), fmt_f64(p[1]), fmt_f64(p[2]))?;
    }
    writeln!(w, "$EndNodes")?;
    writeln!(w, "$Elements\n1 {nc} {} {nc}", nc.min(1))?;
    writeln!(w, "3 1 {etype} {nc}")?;
    for (i, c) in cells.iter().enumerate() {
        write!(w, "{}", i + 1)?;
        for v in c {
            write!(w, " {}", v + 1)?;
        }
        writeln!(w)?;
    }
    writeln!(w, "$EndElements")?;
    for (name, values) in cell_data {
        writeln!(w, "$ElementData\n1\n\"{name}\"\n1\n0\n3\n0\n1\n{nc}")?;
        for (i, v) in values.iter().enumerate() {
            writeln!(w, "{} {}", i + 1, fmt_f64(*v))?;
        }
        writeln!(w, "$EndElementData")?;
    }
    Ok(())
}
