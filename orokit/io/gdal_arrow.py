"""One vector layer from Arrow record batches through GDAL's C API, without holding the GIL.

``pyogrio.write_arrow`` holds Python's GIL while GDAL writes (measured: a Python thread
beside it gets ~10 % of its CPU), so two layers written from two threads take turns,
and so does every other Python thread. This module calls the same GDAL functions
(``OGR_L_CreateFieldFromArrowSchema``, ``OGR_L_WriteArrowBatch``) through ``ctypes``,
which releases the GIL during each call, on the GDAL library pyogrio loaded (the same
driver, options and bytes). :func:`gdal_library` is None when that library cannot be
found (another platform or build): callers then use pyogrio.
"""
from __future__ import annotations

import ctypes
import functools
from collections.abc import Iterable
from pathlib import Path
from typing import Any

__all__ = ["gdal_library", "write_arrow_layer"]


class _ArrowSchema(ctypes.Structure):
    pass


_ArrowSchema._fields_ = [
    ("format", ctypes.c_char_p), ("name", ctypes.c_char_p), ("metadata", ctypes.c_char_p),
    ("flags", ctypes.c_int64), ("n_children", ctypes.c_int64),
    ("children", ctypes.POINTER(ctypes.POINTER(_ArrowSchema))), ("dictionary", ctypes.POINTER(_ArrowSchema)),
    ("release", ctypes.c_void_p), ("private_data", ctypes.c_void_p),
]


class _ArrowArray(ctypes.Structure):
    pass


_ArrowArray._fields_ = [
    ("length", ctypes.c_int64), ("null_count", ctypes.c_int64), ("offset", ctypes.c_int64),
    ("n_buffers", ctypes.c_int64), ("n_children", ctypes.c_int64), ("buffers", ctypes.c_void_p),
    ("children", ctypes.c_void_p), ("dictionary", ctypes.c_void_p),
    ("release", ctypes.c_void_p), ("private_data", ctypes.c_void_p),
]

_RELEASE_SCHEMA = ctypes.CFUNCTYPE(None, ctypes.POINTER(_ArrowSchema))
_RELEASE_ARRAY = ctypes.CFUNCTYPE(None, ctypes.POINTER(_ArrowArray))
_OPTIONS = ctypes.POINTER(ctypes.c_char_p)
#: GDALOpenEx flags: GDAL_OF_UPDATE | GDAL_OF_VECTOR | GDAL_OF_VERBOSE_ERROR
_OPEN_UPDATE_VECTOR = 0x01 | 0x04 | 0x40
#: OGRwkbGeometryType codes of the geometry types written here
GEOMETRY_TYPES = {"Point": 1, "LineString": 2}


@functools.lru_cache(maxsize=1)
def gdal_library() -> ctypes.CDLL | None:
    """The GDAL library pyogrio loaded (its C functions declared), or None when it is not found."""
    import pyogrio  # loads GDAL and registers its drivers

    try:
        with open("/proc/self/maps") as maps:
            mapped = {line.rsplit(None, 1)[-1] for line in maps if "/libgdal" in line and ".so" in line}
    except OSError:
        return None
    # rasterio's wheel maps its own GDAL too: take pyogrio's (its wheel's pyogrio.libs), or the only one
    own = Path(pyogrio.__file__).resolve().parent.parent / "pyogrio.libs"
    ours = [p for p in mapped if Path(p).parent == own]
    path = ours[0] if len(ours) == 1 else (next(iter(mapped)) if len(mapped) == 1 else None)
    if path is None:
        return None
    try:
        lib = ctypes.CDLL(path)  # the loaded library (same handle); ctypes calls release the GIL
        sig = {
            "GDALAllRegister": (None, []),
            "GDALGetDriverByName": (ctypes.c_void_p, [ctypes.c_char_p]),
            "GDALCreate": (ctypes.c_void_p, [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_int,
                                             ctypes.c_int, ctypes.c_int, _OPTIONS]),
            "GDALOpenEx": (ctypes.c_void_p, [ctypes.c_char_p, ctypes.c_uint, ctypes.c_void_p, ctypes.c_void_p,
                                             ctypes.c_void_p]),
            "GDALClose": (ctypes.c_int, [ctypes.c_void_p]),
            "GDALDatasetCreateLayer": (ctypes.c_void_p, [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p,
                                                         ctypes.c_int, _OPTIONS]),
            "GDALDatasetStartTransaction": (ctypes.c_int, [ctypes.c_void_p, ctypes.c_int]),
            "GDALDatasetCommitTransaction": (ctypes.c_int, [ctypes.c_void_p]),
            "OGR_L_CreateFieldFromArrowSchema": (ctypes.c_bool, [ctypes.c_void_p, ctypes.POINTER(_ArrowSchema),
                                                                 _OPTIONS]),
            "OGR_L_WriteArrowBatch": (ctypes.c_bool, [ctypes.c_void_p, ctypes.POINTER(_ArrowSchema),
                                                      ctypes.POINTER(_ArrowArray), _OPTIONS]),
            "OSRNewSpatialReference": (ctypes.c_void_p, [ctypes.c_char_p]),
            "OSRSetFromUserInput": (ctypes.c_int, [ctypes.c_void_p, ctypes.c_char_p]),
            "OSRRelease": (None, [ctypes.c_void_p]),
            "CPLErrorReset": (None, []),
            "CPLGetLastErrorMsg": (ctypes.c_char_p, []),
        }
        for name, (restype, argtypes) in sig.items():
            fn = getattr(lib, name)
            fn.restype, fn.argtypes = restype, argtypes
    except (OSError, AttributeError):
        return None
    return lib


def _options(values: dict[str, str]) -> Any:
    items = [f"{k}={v}".encode() for k, v in values.items()]
    return (ctypes.c_char_p * (len(items) + 1))(*items, None)


def write_arrow_layer(path: Path, layer: str, schema: Any, batches: Iterable[Any], *, geometry_name: str,
                      geometry_type: str, crs: str | None, layer_options: dict[str, str],
                      driver: str = "GPKG") -> None:
    """Write ``batches`` (pyarrow RecordBatches of ``schema``) as a new layer of ``path``.

    What ``pyogrio.write_arrow`` does for a new layer (the file is created, or opened in
    update mode when it exists; one transaction), with the GIL released inside GDAL.
    ``geometry_name``: the WKB column; ``crs``: anything ``OSRSetFromUserInput`` reads.

    Raises
    ------
    OSError
        GDAL failed (its message).
    """
    lib = gdal_library()
    if lib is None:
        raise OSError("GDAL's C library was not found in this process")

    def fail(what: str) -> OSError:
        msg = lib.CPLGetLastErrorMsg()
        return OSError(f"{path}: {what}" + (f": {msg.decode(errors='replace')}" if msg else ""))

    lib.CPLErrorReset()
    name = str(path).encode()
    if path.exists():
        ds = lib.GDALOpenEx(name, _OPEN_UPDATE_VECTOR, None, None, None)
    else:
        drv = lib.GDALGetDriverByName(driver.encode())
        ds = lib.GDALCreate(drv, name, 0, 0, 0, 0, None) if drv else None
    if not ds:
        raise fail("cannot open or create the file")
    srs = None
    c_schema = _ArrowSchema()
    try:
        if crs is not None:
            srs = lib.OSRNewSpatialReference(None)
            if lib.OSRSetFromUserInput(srs, crs.encode()) != 0:
                raise fail(f"unknown CRS {crs!r}")
        lyr = lib.GDALDatasetCreateLayer(ds, layer.encode(), srs, GEOMETRY_TYPES[geometry_type],
                                         _options(layer_options))
        if not lyr:
            raise fail(f"cannot create the layer {layer!r}")
        schema._export_to_c(ctypes.addressof(c_schema))
        for i in range(c_schema.n_children):
            child = c_schema.children[i]
            if child.contents.name.decode() == geometry_name:
                continue
            if not lib.OGR_L_CreateFieldFromArrowSchema(lyr, child, None):
                raise fail(f"cannot create the field {child.contents.name.decode()!r}")
        started = lib.GDALDatasetStartTransaction(ds, 0) == 0
        write_options = _options({"GEOMETRY_NAME": geometry_name, "GEOMETRY_ENCODING": "WKB"})
        for batch in batches:
            c_array = _ArrowArray()
            batch._export_to_c(ctypes.addressof(c_array))
            try:
                if not lib.OGR_L_WriteArrowBatch(lyr, ctypes.byref(c_schema), ctypes.byref(c_array), write_options):
                    raise fail(f"cannot write the layer {layer!r}")
            finally:
                if c_array.release:  # GDAL may have taken it (then release is NULL)
                    _RELEASE_ARRAY(c_array.release)(ctypes.byref(c_array))
        if started and lib.GDALDatasetCommitTransaction(ds) != 0:
            raise fail("cannot commit the layer")
    finally:
        if c_schema.release:
            _RELEASE_SCHEMA(c_schema.release)(ctypes.byref(c_schema))
        if srs:
            lib.OSRRelease(srs)
        closed = lib.GDALClose(ds)
    if closed != 0:
        raise fail("cannot close the file")
