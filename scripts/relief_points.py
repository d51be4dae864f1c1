"""Points on a sphere of radius 1 carrying a sinusoidal relief, with exact normals, and the
exact surface as `scanflow check --truth` reads it (the `bumpy` shape of `scanflow synth`,
whose amplitude and frequency are fixed there):

    r(u) = 1 + a sin(k u_x) sin(k u_y) sin(k u_z),   normal ∝ r u − ∇_S r

    python3 scripts/relief_points.py N AMPLITUDE FREQUENCY NOISE OUT.ply   (writes OUT.truth.json)

Directions are uniform on the unit sphere (for a relief of a few percent the area element
varies by about as much); NOISE is Gaussian, relative to the bounding-box diagonal, as in
`scanflow synth`.
"""
import json
import sys

import numpy as np

n, a, k, noise, out = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
rng = np.random.default_rng(1)
u = rng.normal(size=(n, 3))
u /= np.linalg.norm(u, axis=1)[:, None]
s, c = np.sin(k * u), np.cos(k * u)
r = 1 + a * s[:, 0] * s[:, 1] * s[:, 2]
grad = a * k * np.stack([c[:, 0] * s[:, 1] * s[:, 2], s[:, 0] * c[:, 1] * s[:, 2], s[:, 0] * s[:, 1] * c[:, 2]], 1)
grad_s = grad - u * (u * grad).sum(1)[:, None]
normal = r[:, None] * u - grad_s
normal /= np.linalg.norm(normal, axis=1)[:, None]
p = r[:, None] * u
e = 1 + a
diag = 2 * np.sqrt(3) * e
if noise > 0:
    p = p + rng.normal(size=p.shape) * noise * diag
with open(out, "wb") as f:
    f.write(("ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % n
             + "".join("property float %s\n" % x for x in ("x", "y", "z", "nx", "ny", "nz"))
             + "end_header\n").encode())
    f.write(np.hstack([p, normal]).astype("<f4").tobytes())
truth = {
    "shape": "bumpy",
    "params": {"radius": 1.0, "amplitude": a, "frequency": k},
    "noise": noise,
    "noise_sigma": noise * diag,
    "points": n,
    "seed": 1,
    "bounding_box": {"min": [-e] * 3, "max": [e] * 3},
    "sample_bounding_box": {"min": p.min(0).tolist(), "max": p.max(0).tolist()},
}
with open(out[: -len(".ply")] + ".truth.json", "w") as f:
    json.dump(truth, f, indent=2)
