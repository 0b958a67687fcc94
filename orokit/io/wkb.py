"""Points and polylines as Arrow arrays of WKB, straight from coordinate arrays.

What ``shapely.to_wkb`` writes for 2-D geometries (little-endian, ISO), without making
shapely objects: the GeoParquet and GeoPackage writers pass these arrays to Arrow and
GDAL as they are.
"""
from __future__ import annotations

import numpy as np

__all__ = ["point_wkb", "polyline_wkb"]

_POINT = np.dtype([("order", "u1"), ("kind", "<u4"), ("x", "<f8"), ("y", "<f8")])  # 21 bytes, packed


def _binary(n: int, data: np.ndarray, size: int):
    import pyarrow as pa

    if n * size + 1 > np.iinfo(np.int32).max:
        offsets = np.arange(0, size * n + 1, size, dtype=np.int64)
        return pa.Array.from_buffers(pa.large_binary(), n, [None, pa.py_buffer(offsets), pa.py_buffer(data)])
    offsets = np.arange(0, size * n + 1, size, dtype=np.int32)
    return pa.Array.from_buffers(pa.binary(), n, [None, pa.py_buffer(offsets), pa.py_buffer(data)])


def point_wkb(x: np.ndarray, y: np.ndarray):
    """2-D points (x[i], y[i]) as a ``pyarrow`` binary array of WKB."""
    n = len(x)
    rec = np.empty(n, _POINT)
    rec["order"], rec["kind"], rec["x"], rec["y"] = 1, 1, x, y
    return _binary(n, rec, _POINT.itemsize)


def polyline_wkb(x: np.ndarray, y: np.ndarray):
    """2-D LineStrings of k vertices each, from (n, k) arrays ``x``, ``y``, as a ``pyarrow`` binary array of WKB."""
    x, y = np.atleast_2d(x), np.atleast_2d(y)
    n, k = x.shape
    dtype = np.dtype([("order", "u1"), ("kind", "<u4"), ("count", "<u4"), ("xy", "<f8", (k, 2))])
    rec = np.empty(n, dtype)
    rec["order"], rec["kind"], rec["count"] = 1, 2, k
    rec["xy"][:, :, 0], rec["xy"][:, :, 1] = x, y
    return _binary(n, rec, dtype.itemsize)
