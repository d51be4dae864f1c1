//! The GPU paths (Mesa's lavapipe in CI): extraction identical to the CPU, leaf solves within rounding.

use super::*;

#[test]
fn gpu_and_cpu_write_identical_files() {
    if scanflow::extract::gpu::adapter_names().is_empty() {
        eprintln!(
            "skipped: wgpu finds no adapter (no Vulkan driver; install mesa-vulkan-drivers for lavapipe)"
        );
        return;
    }
    let d = tempfile::tempdir().unwrap();
    for (shape, depth, extra) in [
        ("sphere", "7", None),
        ("torus", "7", Some("--trim")),
        ("bumpy", "8", None),
    ] {
        let ply = synth(d.path(), shape, 50_000, 0.0005);
        let cpu = d.path().join(format!("{shape}_cpu.ply"));
        let gpu = d.path().join(format!("{shape}_gpu.ply"));
        let mut a = vec!["--depth", depth, "--gpu", "off"];
        let mut b = vec!["--depth", depth, "--gpu", "on"];
        if let Some(x) = extra {
            a.push(x);
            b.push(x);
        }
        recon(&ply, &cpu, &a);
        recon(&ply, &gpu, &b);
        assert_eq!(
            std::fs::read(&cpu).unwrap(),
            std::fs::read(&gpu).unwrap(),
            "{shape}"
        );
    }
}

/// `--gpu-solve on` (Mesa's lavapipe in CI): the leaves solved on the device give a mesh
/// within rounding of the CPU's (the device sums in float32), and the same bytes for any
/// thread count.
#[test]
fn gpu_solve_stays_within_rounding_of_the_cpu() {
    if scanflow::extract::gpu::adapter_names().is_empty() {
        eprintln!(
            "skipped: wgpu finds no adapter (no Vulkan driver; install mesa-vulkan-drivers for lavapipe)"
        );
        return;
    }
    use scanflow::metrics::{Reference, ReferenceParams, mesh_to_reference};
    let d = tempfile::tempdir().unwrap();
    let ply = synth(d.path(), "bumpy", 20_000, 0.0005);
    let cpu = d.path().join("cpu.ply");
    recon(&ply, &cpu, &["--depth", "7"]);
    let mut meshes = Vec::new();
    for t in ["1", "2"] {
        let out = d.path().join(format!("gpu{t}.ply"));
        let o = run(&[
            "reconstruct",
            s(&ply),
            "-o",
            s(&out),
            "--progress",
            "none",
            "--depth",
            "7",
            "--gpu-solve",
            "on",
            "--threads",
            t,
        ]);
        let log = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{log}");
        assert!(log.contains("GPU leaf solves on"), "{log}");
        meshes.push(std::fs::read(&out).unwrap());
    }
    assert!(meshes[0] == meshes[1], "the GPU solve depends on --threads");
    let (a, b) = (
        read_mesh(&cpu).unwrap(),
        read_mesh(&d.path().join("gpu1.ply")).unwrap(),
    );
    assert_ne!(
        std::fs::read(&cpu).unwrap(),
        meshes[0],
        "not solved on the device"
    );
    let dist = mesh_to_reference(&b, Reference::Mesh(&a), &ReferenceParams::default());
    let worst = dist.to_reference.max.max(dist.from_reference.max) / dist.diagonal;
    assert!(worst < 1e-5, "{dist:?}");
    let c = check_mesh(&b);
    assert!(c.watertight && c.components == 1, "{c:?}");
}
