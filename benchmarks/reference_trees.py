"""Compare orokit's peaks with the reference Divide Trees of the 13 PNG DEMs.

The reference trees (``<name>.txt`` beside each PNG, from Argudo et al. 2019, made with a
modified Kirmse program) were not finalised: they keep low peaks linked to the DEM
edges (runoffs) for later merging, and their elevations are off by 1-2 ft. So:

* ``ref->ours@0``: share of reference peaks at or next to (Chebyshev distance <= 1
  cell) one of orokit's peaks at eps = 0 (every peak);
* ``ref->ours@100ft``: same against orokit's peaks with prominence >= 100 ft or not
  exact (an upper bound that terrain beyond the edge could still lower);
* ``ours@100ft->ref``: share of orokit's exact peaks with prominence >= 100 ft + 2 ft
  that sit at or next to a reference peak.

Usage: ``python benchmarks/reference_trees.py [DATA_DIR]`` (default ../shared/data).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

FT = 0.3048


from orokit.validate.reference import near_share  # noqa: E402


def compare(png: Path, txt: Path, cell_size_m: float) -> dict[str, float]:
    """Shares (see the module docstring) for one DEM and its reference tree."""
    import orokit
    from orokit.io.dem import read_dem
    from orokit.io.divide_tree_io import read_divide_tree_txt

    dem = read_dem(png, z_units="ft", cell_size_m=cell_size_m)
    ref = read_divide_tree_txt(txt, height=dem.shape[0])
    t0 = time.perf_counter()
    peaks = orokit.analyze(dem, min_prominence_m=0.0, isolation=False).peaks
    seconds = time.perf_counter() - t0
    ref_rc = ref.peaks[["row", "col"]].to_numpy()
    ours = peaks[["row", "col"]].to_numpy()
    prom = peaks["prominence"].to_numpy()
    exact = peaks["prominence_exact"].to_numpy(bool)
    upper = ours[(prom >= 100 * FT) | ~exact]
    strong = ours[(prom >= 102 * FT) & exact]
    return {
        "ref_peaks": len(ref_rc),
        "our_peaks": len(ours),
        "ref->ours@0": near_share(ref_rc, ours, dem.shape),
        "ref->ours@100ft": near_share(ref_rc, upper, dem.shape),
        "ours@100ft->ref": near_share(strong, ref_rc, dem.shape),
        "seconds": seconds,
    }


def main(data_dir: str | None = None) -> None:
    root = Path(data_dir or Path(__file__).resolve().parents[2] / "shared" / "data") / "dems"
    pngs = sorted(root.glob("*.png"))
    if not pngs:
        raise SystemExit(f"no DEMs under {root}")
    print(f"{'dem':20s} {'ref':>5s} {'ours@0':>7s} {'ref->ours@0':>12s} {'ref->ours@100ft':>16s} {'ours@100ft->ref':>16s}")
    for png in pngs:
        cell = 30.87 if png.stem == "pyrenees" else 92.61
        r = compare(png, png.with_suffix(".txt"), cell)
        print(
            f"{png.stem:20s} {r['ref_peaks']:5d} {r['our_peaks']:7d} {r['ref->ours@0']:12.3f} "
            f"{r['ref->ours@100ft']:16.3f} {r['ours@100ft->ref']:16.3f}"
        )


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
