"""Mosaics of raster tiles as GDAL VRT files (placed by geotransform, never concatenated).

``build_vrt`` checks that the tiles share CRS, cell size, data type, nodata and a
common grid, then writes a VRT whose sources sit at their georeferenced offsets
(SRTM tiles that repeat their edge rows/columns simply overlap). Reading the VRT
with ``read_dem(..., chunks=N)`` gives a lazy dask array: only the windows a chunk
needs are read.
"""
from __future__ import annotations

import logging
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from orokit._typing import PathLike
from orokit.errors import InputError
from orokit.io.atomic import write_text_atomic

logger = logging.getLogger(__name__)

__all__ = ["build_vrt", "tile_paths"]

_GDAL_TYPES = {
    "uint8": "Byte", "int8": "Int8", "uint16": "UInt16", "int16": "Int16", "uint32": "UInt32",
    "int32": "Int32", "float32": "Float32", "float64": "Float64",
}
_PATTERNS = ("*.tif", "*.tiff", "*.hgt", "*.hgt.zip", "*.flt", "*.asc", "*.bil", "*.img")


def tile_paths(directory: PathLike) -> list[Path]:
    """Raster tiles of a directory (GeoTIFF, SRTM .hgt/.hgt.zip, EHdr, ASCII grid...)."""
    d = Path(directory)
    paths = sorted({p for pat in _PATTERNS for p in d.glob(pat)})
    if not paths:
        raise InputError(f"no raster tiles ({', '.join(_PATTERNS)}) in {d}")
    return paths


def _gdal_path(p: Path) -> str:
    s = str(p.resolve())
    return f"/vsizip/{s}/{p.name[:-4]}" if s.endswith(".hgt.zip") else s


def build_vrt(tiles: PathLike | list[PathLike], vrt_path: PathLike) -> Path:
    """Write a VRT mosaic of ``tiles`` (a list of files or a directory) to ``vrt_path``.

    Raises :class:`InputError` when tiles disagree on CRS, cell size, data type,
    band count or nodata, or do not lie on one grid.
    """
    import rasterio

    paths = tile_paths(tiles) if not isinstance(tiles, (list, tuple)) else [Path(t) for t in tiles]
    if not paths:
        raise InputError("build_vrt needs at least one tile")
    infos = []
    for p in paths:
        try:
            with rasterio.open(_gdal_path(p)) as ds:
                infos.append((p, ds.crs, ds.transform, ds.width, ds.height, ds.dtypes[0], ds.nodata, ds.count))
        except rasterio.errors.RasterioIOError as exc:
            raise InputError(f"cannot read tile {p}: {exc}") from exc
    _, crs0, t0, _, _, dt0, nd0, cnt0 = infos[0]
    for p, crs, t, w, h, dt, nd, cnt in infos[1:]:
        if crs != crs0:
            raise InputError(f"tile {p} has CRS {crs}, but {infos[0][0]} has {crs0}; reproject the tiles first")
        if not (np.isclose(t.a, t0.a) and np.isclose(t.e, t0.e)) or t.b or t.d:
            raise InputError(f"tile {p} has cell size ({t.a}, {t.e}), expected ({t0.a}, {t0.e})")
        if dt != dt0 or cnt != cnt0:
            raise InputError(f"tile {p} is {cnt} x {dt}, expected {cnt0} x {dt0}")
        if not (nd == nd0 or (nd is not None and nd0 is not None and np.isnan(nd) and np.isnan(nd0))):
            raise InputError(f"tile {p} has nodata {nd}, expected {nd0}")
    if dt0 not in _GDAL_TYPES:
        raise InputError(f"unsupported tile data type {dt0}")
    a, e = t0.a, t0.e
    x0 = min(i[2].c for i in infos)
    y0 = max(i[2].f for i in infos)
    x1 = max(i[2].c + i[3] * a for i in infos)
    y1 = min(i[2].f + i[4] * e for i in infos)
    width = int(round((x1 - x0) / a))
    height = int(round((y1 - y0) / e))
    sources = []
    for p, _, t, w, h, _, _, _ in infos:
        ox, oy = (t.c - x0) / a, (t.f - y0) / e
        if abs(ox - round(ox)) > 1e-6 or abs(oy - round(oy)) > 1e-6:
            raise InputError(f"tile {p} is not aligned on the grid of {infos[0][0]} (offset {ox:.3f}, {oy:.3f} cells)")
        nd_xml = "" if nd0 is None else f"<NODATA>{nd0!r}</NODATA>"
        sources.append(
            f'    <ComplexSource><SourceFilename relativeToVRT="0">{escape(_gdal_path(p))}</SourceFilename>'
            f"<SourceBand>1</SourceBand>"
            f'<SrcRect xOff="0" yOff="0" xSize="{w}" ySize="{h}"/>'
            f'<DstRect xOff="{int(round(ox))}" yOff="{int(round(oy))}" xSize="{w}" ySize="{h}"/>{nd_xml}'
            f"</ComplexSource>"
        )
    srs = f"<SRS>{escape(crs0.to_wkt())}</SRS>" if crs0 is not None else ""
    nodata = "" if nd0 is None else f"<NoDataValue>{nd0!r}</NoDataValue>"
    xml = (
        f'<VRTDataset rasterXSize="{width}" rasterYSize="{height}">{srs}\n'
        f"  <GeoTransform>{x0!r}, {a!r}, 0.0, {y0!r}, 0.0, {e!r}</GeoTransform>\n"
        f'  <VRTRasterBand dataType="{_GDAL_TYPES[dt0]}" band="1">{nodata}\n'
        + "\n".join(sources)
        + "\n  </VRTRasterBand>\n</VRTDataset>\n"
    )
    out = write_text_atomic(vrt_path, xml)
    logger.info("wrote VRT mosaic %s: %d tiles, %d x %d cells", out, len(paths), width, height)
    return out
