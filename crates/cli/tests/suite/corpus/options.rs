//! The corpus's bad options: each refused before any work, naming the option.

use super::*;

/// Bad options and output paths, on a good input: usage errors, found before any work.
pub(super) fn option_cases(c: &mut Corpus) {
    let good = c.write(
        "opt_input",
        "good.xyz",
        "0 0 0\n1 0 0\n0 1 0\n0 0 1\n".as_bytes(),
    );
    let cases: [(&str, &str, &[&str], &str); 18] = [
        ("opt_depth_low", "o.ply", &["--depth", "2"], "--depth 2"),
        (
            "opt_coarse_depth_deep",
            "o.ply",
            &["--depth", "9", "--coarse-depth", "8"],
            "--coarse-depth 8: expected 4 to 7",
        ),
        (
            "opt_coarse_depth_shallow",
            "o.ply",
            &["--coarse-depth", "3"],
            "--coarse-depth 3",
        ),
        ("opt_depth_high", "o.ply", &["--depth", "14"], "--depth 14"),
        (
            "opt_tile_not_pow2",
            "o.ply",
            &["--tile", "100"],
            "--tile 100",
        ),
        ("opt_tile_zero", "o.ply", &["--tile", "0"], "--tile 0"),
        (
            "opt_threads_huge",
            "o.ply",
            &["--threads", "100000"],
            "--threads",
        ),
        ("opt_mem_word", "o.ply", &["--mem", "lots"], "--mem"),
        ("opt_mem_zero", "o.ply", &["--mem", "0"], "--mem"),
        ("opt_smooth_neg", "o.ply", &["--smooth=-1"], "--smooth"),
        ("opt_error_nan", "o.ply", &["--error", "NaN"], "--error"),
        (
            "opt_point_weight_nan",
            "o.ply",
            &["--point-weight", "NaN"],
            "--point-weight",
        ),
        (
            "opt_viewpoint_two",
            "o.ply",
            &["--viewpoint", "1,2"],
            "--viewpoint",
        ),
        (
            "opt_neighbours_two",
            "o.ply",
            &["--neighbours", "2"],
            "--neighbours",
        ),
        ("opt_gpu_word", "o.ply", &["--gpu", "maybe"], "--gpu"),
        (
            "opt_gpu_solve_word",
            "o.ply",
            &["--gpu-solve", "maybe"],
            "--gpu-solve",
        ),
        ("opt_out_off", "o.off", &[], "o.off"),
        ("opt_out_no_dir", "missing/o.ply", &[], "missing"),
    ];
    for (name, out, extra, named) in cases {
        c.usage(name, &good, out, extra, named);
    }
    let input_out = c.dir("opt_out_is_input").join("in.ply");
    std::fs::copy(&good, &input_out).unwrap();
    let args: Vec<String> = ["reconstruct", s(&input_out), "-o", s(&input_out)]
        .iter()
        .map(|a| a.to_string())
        .collect();
    c.cases.push(Case {
        name: "opt_out_is_input".into(),
        args,
        file: "in.ply".into(),
        loc: NONE,
        out: None,
        pending: None,
        dir: c.dir("opt_out_is_input"),
        code: 2,
    });
}
