"""Measure the hillslope and ridge profiles of real DEMs around their own Divide Trees.

Prints, per region and averaged, the tables of :mod:`orokit.raster.profiles`:

- hillslope ``f(u)``: median of (h(p) - h(r)) / (h(q) - h(r)) in 20 bins of
  ``u = d(p, R) / (d(p, R) + d(p, T))``, for 40 000 random cells p, with q / r the nearest
  ridge / river point of the renderer's skeleton and h the real ground;
- ridge ``g(t)``: median of (h(x) - h(saddle)) / (h(peak) - h(saddle)) at t = 0, 0.05, ..., 1
  along the straight line from each peak to its saddle (drops >= 50 m).

    python benchmarks/profiles.py [REGIONS]   # default: the tuning regions of benchmarks/realism.py
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def measure(name: str) -> tuple[np.ndarray, np.ndarray]:
    from scipy.spatial import cKDTree

    import orokit
    from orokit.data import open_dataset_dem
    from orokit.raster.refine import densify
    from orokit.raster.skeleton import build_skeleton
    from realism import _extent

    dem = open_dataset_dem(name)
    tree = orokit.analyze(dem, min_prominence_m=30.0, isolation=False).tree
    z = np.asarray(dem.values, float)
    t = dem.rio.transform()

    def real_at(xy):
        col = np.clip(((xy[:, 0] - t.c) / t.a).astype(int), 0, z.shape[1] - 1)
        row = np.clip(((xy[:, 1] - t.f) / t.e).astype(int), 0, z.shape[0] - 1)
        return z[row, col]

    sk = build_skeleton(tree, extent=_extent(dem), rng=0)
    rxy, _, _ = densify(sk.ridges, 50.0)
    vxy, _, _ = densify(sk.rivers, 50.0)
    rng = np.random.default_rng(0)
    rr, cc = rng.integers(0, z.shape[0], 40000), rng.integers(0, z.shape[1], 40000)
    p = np.column_stack([t.c + (cc + 0.5) * t.a, t.f + (rr + 0.5) * t.e])
    dT, iq = cKDTree(rxy).query(p)
    dR, ir = cKDTree(vxy).query(p)
    hp, hq, hr = z[rr, cc], real_at(rxy[iq]), real_at(vxy[ir])
    ok = (hq - hr) > 20
    f = (hp - hr)[ok] / (hq - hr)[ok]
    u = (dR / (dR + dT + 1e-9))[ok]
    idx = np.minimum((u * 20).astype(int), 19)
    hill = np.array([np.median(f[idx == k]) if (idx == k).sum() > 30 else np.nan for k in range(20)])
    n, nodes = sk.n_peaks, sk.node_xyz
    prof = []
    tt = np.linspace(0, 1, 21)
    for a, b, s in sk.edges[:800]:
        for pk in (a, b):
            P, S = nodes[pk], nodes[n + s]
            if P[2] - S[2] >= 50:
                xy = P[None, :2] + tt[:, None] * (S[None, :2] - P[None, :2])
                prof.append((real_at(xy) - S[2]) / (P[2] - S[2]))
    return hill, np.median(np.array(prof), axis=0)


def main() -> int:
    from realism import TUNE

    names = sys.argv[1].split(",") if len(sys.argv) > 1 else list(TUNE)
    hs, rs = [], []
    for name in names:
        h, r = measure(name)
        hs.append(h)
        rs.append(r)
        print(f"{name:18s} hillslope {np.round(h, 2).tolist()}\n{'':18s} ridge     {np.round(r, 2).tolist()}")
    print("mean hillslope", np.round(np.nanmean(hs, axis=0), 3).tolist())
    print("mean ridge    ", np.round(np.mean(rs, axis=0), 3).tolist())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
