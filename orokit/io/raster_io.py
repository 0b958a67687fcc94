"""Writers of rendered terrain: COG GeoTIFF, hillshade preview PNG, TIN as PLY."""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import xarray as xr

from orokit._typing import PathLike
from orokit.errors import InputError
from orokit.io.atomic import atomic_open, atomic_path
from orokit.raster.shade import hillshade
from orokit.raster.tin import TIN

__all__ = ["write_cog", "write_hillshade_png", "write_tin_ply"]


def write_cog(dem: xr.DataArray, path: PathLike, *, tags: dict[str, Any] | None = None) -> None:
    """Write ``dem`` as a Cloud-Optimized GeoTIFF (deflate, NaN nodata) with provenance tags.

    The band's unit is set to ``dem.attrs['units']`` (metres), so
    :func:`orokit.io.dem.read_dem` (and ``orokit analyze`` / ``classify``) read the file
    without ``z_units``, also when it has no CRS (a local metric grid: the transform is
    kept). The CRS is written when ``dem`` has one. Dataset tags: units, generator,
    orokit version, parameters, seed, local_grid, timings, plus ``tags``. Written
    atomically (temporary file beside ``path``, then renamed).
    """
    import rasterio

    units = str(dem.attrs.get("units", "m"))
    if units != "m":
        raise InputError(f"write_cog writes elevations in metres; the raster's units are {units!r}")
    all_tags = {k: str(v) for k, v in dem.attrs.items() if k in (
        "units", "generator", "orokit_version", "parameters", "seed", "local_grid", "timings")}
    all_tags.update({k: str(v) for k, v in (tags or {}).items()})
    z = np.asarray(dem.values, dtype=np.float32)
    if z.ndim != 2:
        raise InputError(f"write_cog writes one 2-D band; got an array of shape {z.shape}")
    profile = {"driver": "COG", "width": z.shape[1], "height": z.shape[0], "count": 1, "dtype": "float32",
               "crs": dem.rio.crs, "transform": dem.rio.transform(), "nodata": np.nan,
               "compress": "DEFLATE", "predictor": 3,
               "num_threads": "ALL_CPUS"}  # compression on every core: the same file bytes, less wall time
    with atomic_path(path) as tmp:
        with rasterio.open(tmp, "w", **profile) as dst:
            dst.write(z, 1)
            dst.units = ("m",)
            dst.set_band_description(1, "elevation")
            dst.update_tags(**all_tags)


def write_hillshade_png(dem: xr.DataArray, path: PathLike, *, max_size: int = 2048) -> None:
    """Grey hillshade preview PNG (downsampled to at most ``max_size`` pixels a side).

    The shading is :func:`orokit.raster.shade.hillshade` (cell sizes in metres,
    light from the north-west); NaN cells are black.
    """
    from affine import Affine
    from PIL import Image

    step = max(int(math.ceil(max(dem.shape) / max_size)), 1)
    small = dem
    if step > 1:
        small = dem.isel(y=slice(None, None, step), x=slice(None, None, step))
        small = small.rio.write_transform(dem.rio.transform() @ Affine.scale(step))
    hs = np.nan_to_num(hillshade(small), nan=0.0)
    img = Image.fromarray((hs * 255).astype(np.uint8), mode="L")
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG")


def write_tin_ply(tin: TIN, path: PathLike) -> None:
    """Write a TIN as an ASCII PLY mesh (vertices x y z, triangular faces)."""
    with atomic_open(path, "w") as fh:
        fh.write("ply\nformat ascii 1.0\ncomment orokit TIN\n")
        fh.write(f"element vertex {tin.xy.shape[0]}\nproperty double x\nproperty double y\nproperty double z\n")
        fh.write(f"element face {tin.n_triangles}\nproperty list uchar int vertex_indices\nend_header\n")
        np.savetxt(fh, np.column_stack([tin.xy, tin.z]), fmt="%.3f")
        np.savetxt(fh, np.column_stack([np.full(tin.n_triangles, 3), tin.triangles]), fmt="%d")
