use super::*;
use crate::types::Cube;

/// The trim support is the finest level's coarse grid where its bits fit a 32nd of the
/// budget, halved where they do not, and never coarser than the dense solve's grid.
#[test]
fn the_trim_support_is_the_finest_coarse_grid_the_budget_allows() {
    let cube = Cube {
        origin: [0.0; 3],
        size: 2.0,
    };
    let g = 1u64 << 30;
    for (depth, mem, cells) in [
        (10, 64 << 20, 256),
        (11, 4 * g, 512),
        (12, 4 * g, 1024),
        (13, 4 * g, 1024),
        (13, 16 * g, 1024),
        (13, 32 * g, 2048),
        (13, 64 << 20, 256),
    ] {
        let levels =
            crate::recon::plan::levels(cube, depth, 1.0, 4.0, None, None, plan_budget(mem))
                .unwrap();
        let (fine, top) = (&levels[0], levels.last().unwrap());
        let (h, n) = support_grid(fine, top, mem);
        assert_eq!(
            n,
            cells.max(top.coarse_cells()),
            "depth {depth}, --mem {mem}"
        );
        assert_eq!(h * n as f64, cube.size);
        assert!(Support::bytes(n) <= mem / SUPPORT_BUDGET_DIVISOR || n == top.coarse_cells());
    }
}

/// At the least budget of every depth the levels' top coarse solve and leaf pass fit
/// their slices, and it is never below the floor.
#[test]
fn the_least_budget_plans_every_depth() {
    let cube = Cube {
        origin: [0.0; 3],
        size: 1.0,
    };
    for depth in 7..=13 {
        for screened in [false, true] {
            let least = least_mem(depth, screened);
            assert!(least >= MEM_FLOOR);
            let b = plan_budget(least);
            let alpha = if screened { 4.0 } else { 0.0 };
            let levels =
                crate::recon::plan::levels(cube, depth, 1.0, alpha, None, None, b).unwrap();
            let top = levels.last().unwrap();
            let need = Plan::needs(top.depth, top.coarse_ratio, screened);
            assert!(
                need.coarse <= b.coarse && need.leaf <= b.leaf,
                "depth {depth}: {levels:?}"
            );
            assert_eq!(
                top.coarse_field_bytes() + top.density_bytes() + top.leaf_scratch_bytes(),
                need.leaf
            );
        }
    }
}
