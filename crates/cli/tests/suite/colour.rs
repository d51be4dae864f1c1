//! Colours carried from input points to output vertices, read back by an independent reader.

use std::path::Path;

use super::common::*;

/// Run a Python snippet with plyfile on `mesh`; return its stdout.
fn py(script: &str, mesh: &Path) -> String {
    let o = std::process::Command::new("python3")
        .args(["-c", script, s(mesh)])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).trim().to_string()
}

/// The colour of a point of the unit sphere: a smooth function of position.
fn colour_at(p: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|a| (p[a] * 0.5 + 0.5) * 255.0)
}

#[test]
fn vertex_colours_follow_the_input_points() {
    let d = tempfile::tempdir().unwrap();
    // An oriented, coloured sphere as XYZ text with 9 columns.
    let xyz = d.path().join("c.xyz");
    let mut t = String::new();
    let n = 40_000;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let p = [
            r * (golden * i as f64).cos(),
            r * (golden * i as f64).sin(),
            z,
        ];
        let c = colour_at(p).map(|v| v.round() as u8);
        t += &format!(
            "{} {} {} {} {} {} {} {} {}\n",
            p[0], p[1], p[2], p[0], p[1], p[2], c[0], c[1], c[2]
        );
    }
    std::fs::write(&xyz, t).unwrap();
    let a = d.path().join("a.ply");
    let b = d.path().join("b.ply");
    ok(&[
        "reconstruct",
        s(&xyz),
        "-o",
        s(&a),
        "--depth",
        "7",
        "--threads",
        "1",
    ]);
    ok(&[
        "reconstruct",
        s(&xyz),
        "-o",
        s(&b),
        "--depth",
        "7",
        "--threads",
        "2",
        "--tile",
        "32",
    ]);
    // Same colours whatever the threads and tiles (vertex order follows the tiles).
    let m = scanflow::io::mesh_read::read_mesh(&a).unwrap();
    assert!(m.vertices.len() > 10_000);
    assert_eq!(
        std::fs::read(&a).unwrap(),
        std::fs::read(&{
            let c = d.path().join("c.ply");
            ok(&[
                "reconstruct",
                s(&xyz),
                "-o",
                s(&c),
                "--depth",
                "7",
                "--threads",
                "2",
            ]);
            c
        })
        .unwrap()
    );
    if !has_plyfile() {
        return;
    }
    let script = "import sys, plyfile\nd = plyfile.PlyData.read(sys.argv[1])\nv = d['vertex']\nprint([p.val_dtype for p in v.properties][3:])\nbad = 0\nfor x, y, z, r, g, b in zip(v['x'], v['y'], v['z'], v['red'], v['green'], v['blue']):\n    w = [(c * 0.5 + 0.5) * 255 for c in (x, y, z)]\n    bad += max(abs(w[0] - r), abs(w[1] - g), abs(w[2] - b)) > 12\nprint(len(v), bad)";
    // The same coloured vertices for tiles of 32 and of the default size.
    let digest = "import sys, plyfile, numpy as np, hashlib\nv = plyfile.PlyData.read(sys.argv[1])['vertex']\nrows = sorted(zip(*(v[p].tolist() for p in ('x', 'y', 'z', 'red', 'green', 'blue'))))\nprint(len(rows), hashlib.sha256(repr(rows).encode()).hexdigest())";
    assert_eq!(py(digest, &a), py(digest, &b));
    for mesh in [&a, &b] {
        let out = py(script, mesh);
        let mut lines = out.lines();
        assert_eq!(lines.next(), Some("['u1', 'u1', 'u1']"), "{out}");
        let nums: Vec<usize> = lines
            .next()
            .unwrap()
            .split(' ')
            .map(|x| x.parse().unwrap())
            .collect();
        assert!(nums[0] > 10_000, "{out}");
        assert!(
            nums[1] * 100 <= nums[0],
            "{out}: more than 1% of vertices off by > 12/255"
        );
    }
}

#[test]
fn autzen_lidar_gives_an_open_coloured_terrain() {
    let Some(las) = shared("lidar/autzen_trim.las") else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("autzen.ply");
    ok(&[
        "reconstruct",
        s(&las),
        "--trim",
        "--depth",
        "8",
        "-o",
        s(&out),
    ]);
    let m = scanflow::io::mesh_read::read_mesh(&out).unwrap();
    let c = scanflow::metrics::check_mesh(&m);
    assert!(c.boundary_edges > 0 && !c.watertight, "{c:?}");
    if !has_plyfile() {
        return;
    }
    // Colours as an independent reader sees them: varied, 8-bit colour scaled (not ~0),
    // and faces looking up (the LAS is seen from the air).
    let script = "import sys, plyfile, numpy as np\nd = plyfile.PlyData.read(sys.argv[1])\nv = d['vertex']\nc = np.stack([v['red'], v['green'], v['blue']], 1)\nP = np.stack([v['x'], v['y'], v['z']], 1).astype(float)\nF = np.stack(d['face']['vertex_indices'])\nn = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])\nprint(len(np.unique(c, axis=0)), int(c.max()), n[:, 2].sum() / np.linalg.norm(n, axis=1).sum())";
    let got = py(script, &out);
    // Closed (no --trim), most vertices lie far from every point (under the terrain): their
    // colours still do not depend on the tiles.
    let digest = "import sys, plyfile, hashlib\nv = plyfile.PlyData.read(sys.argv[1])['vertex']\nrows = sorted(zip(*(v[p].tolist() for p in ('x', 'y', 'z', 'red', 'green', 'blue'))))\nprint(len(rows), hashlib.sha256(repr(rows).encode()).hexdigest())";
    let closed: Vec<String> = ["16", "64"]
        .iter()
        .map(|t| {
            let o = d.path().join(format!("closed{t}.ply"));
            ok(&[
                "reconstruct",
                s(&las),
                "--depth",
                "7",
                "--tile",
                t,
                "-o",
                s(&o),
            ]);
            py(digest, &o)
        })
        .collect();
    assert_eq!(closed[0], closed[1]);
    let v: Vec<f64> = got.split(' ').map(|x| x.parse().unwrap()).collect();
    assert!(v[0] >= 20.0, "{got}: distinct colours");
    assert!(v[1] > 150.0, "{got}: colours were not scaled to 8 bits");
    assert!(v[2] > 0.8, "{got}: the terrain does not face up");
    // Intensity too, as a float `scalar_intensity` property (CloudCompare's scalar-field name,
    // which MeshLab does not take for the colour) with varied values.
    let inten = py(
        "import sys, plyfile, numpy as np\nv = plyfile.PlyData.read(sys.argv[1])['vertex']\nprint(v['scalar_intensity'].dtype, len(np.unique(v['scalar_intensity'])), float(v['scalar_intensity'].max()))",
        &out,
    );
    let parts: Vec<&str> = inten.split(' ').collect();
    assert_eq!(parts[0], "float32", "{inten}");
    assert!(parts[1].parse::<usize>().unwrap() >= 20, "{inten}");
}
