"""Cost of the Monte Carlo of DEM error against one analysis (issue 16: N = 20 within 20x).

Writes the n x n mosaic of a real DEM as ``vs_kirmse.py`` does (default 6 x 6 of
himalaya-everest: 15.1 M cells), then times, as whole processes with ``/usr/bin/time -v``:
``orokit analyze`` (defaults: isolation on) and the same with ``--dem-error 2m --samples N
--error-corr 500m --seed 0``. Prints wall and CPU seconds, both ratios and peak RSS, and
records ``reports/benchmarks/dem_error.json`` with the load average.

Run:  .venv/bin/python benchmarks/dem_error.py [--tiles 6] [--samples 20] [--dem himalaya-everest]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from vs_kirmse import EPS_FT, FT, mosaic, orokit_command, timed, write_geotiff_m  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tiles", type=int, default=6)
    ap.add_argument("--samples", type=int, default=20)
    ap.add_argument("--dem", default="himalaya-everest")
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--no-record", action="store_true")
    a = ap.parse_args()
    from orokit.data import open_dataset_dem

    tmp = tempfile.TemporaryDirectory(prefix="orokit-dem-error-") if a.workdir is None else None
    work = Path(tmp.name) if tmp else a.workdir
    work.mkdir(parents=True, exist_ok=True)
    try:
        z_ft = mosaic(np.rint(np.asarray(open_dataset_dem(a.dem).values, np.float64) / FT), a.tiles)
        tif = write_geotiff_m(z_ft, work / "mosaic.tif")
        load = [os.getloadavg()[0]]
        single = timed(orokit_command(tif, work / "single", isolation=True))
        load.append(os.getloadavg()[0])
        mc_cmd = orokit_command(tif, work / "mc", isolation=True) + [
            "--dem-error", "2m", "--samples", str(a.samples), "--error-corr", "500m", "--seed", "0"]
        mc = timed(mc_cmd)
        load.append(os.getloadavg()[0])
        res = {"dem": a.dem, "tiles": a.tiles, "cells": int(z_ft.size), "samples": a.samples,
               "eps_ft": EPS_FT, "single": single, "monte_carlo": mc,
               "wall_ratio": mc["seconds"] / single["seconds"], "cpu_ratio": mc["cpu_s"] / single["cpu_s"],
               "load_average_1min_during": load}
        print(f"{z_ft.size / 1e6:.1f} M cells, {a.samples} samples, {os.cpu_count()} cores, "
              f"load {min(load):.1f}-{max(load):.1f}")
        print(f"analysis:    {single['seconds']:7.1f} s wall {single['cpu_s']:7.1f} s CPU {single['rss_mb']:6.0f} MB")
        print(f"Monte Carlo: {mc['seconds']:7.1f} s wall {mc['cpu_s']:7.1f} s CPU {mc['rss_mb']:6.0f} MB")
        print(f"ratio: {res['wall_ratio']:.1f}x wall, {res['cpu_ratio']:.1f}x CPU (target: <= 20x)")
        if not a.no_record:
            from _record import record

            print(f"recorded in {record('dem_error', res)}")
    finally:
        if tmp is not None:
            tmp.cleanup()


if __name__ == "__main__":
    main()
