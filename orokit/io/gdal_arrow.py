"""One vector layer from Arrow record batches through GDAL's C API, without holding the GIL.

``pyogrio.write_arrow`` holds Python's GIL while GDAL writes (measured: a Python thread
beside it gets ~10 % of its CPU), so two layers written from two threads take turns,
and so does every other Python thread. This module calls the same GDAL functions
(``OGR_L_CreateFieldFromArrowSchema``, ``OGR_L_WriteArrowBatch``) through ``ctypes``,
which releases the GIL during each call, on the GDAL library rasterio loaded (orokit
reads every raster with it: writing through it loads no second GDAL, ~34 MiB resident with
pyogrio, shapely and geopandas). :func:`gdal_library` falls back on pyogrio's library when
rasterio's is not found or lacks the GeoPackage driver, and is None when neither is found
(another platform or build): callers then use pyogrio.
"""
from __future__ import annotations

import contextlib
import ctypes
import functools
import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

__all__ = ["gdal_library", "thread_config_option", "write_arrow_layer"]


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
GEOMETRY_TYPES = {"Point": 1, "LineString": 2, None: 100}  # None: a table without geometry (wkbNone)


_SIGNATURES: dict[str, tuple[Any, list[Any]]] = {
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
    "CPLGetConfigOption": (ctypes.c_char_p, [ctypes.c_char_p, ctypes.c_char_p]),
    "CPLGetThreadLocalConfigOption": (ctypes.c_char_p, [ctypes.c_char_p, ctypes.c_char_p]),
    "CPLSetThreadLocalConfigOption": (None, [ctypes.c_char_p, ctypes.c_char_p]),
    "CPLPushErrorHandler": (None, [ctypes.c_void_p]),
    "CPLPopErrorHandler": (None, []),
    "GDALAllRegister": (None, []),
}
#: a GDAL configuration option set through rasterio (or pyogrio) to tell its library from other loaded ones
_PROBE = "OROKIT_GDAL_ARROW_PROBE"


def _loaded_libraries() -> list[str]:
    """Paths of the GDAL libraries mapped into this process (Linux; others: none), first seen first."""
    paths: list[str] = []
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                name = line.rsplit(None, 1)[-1]
                if "/libgdal" in name and ".so" in name and name not in paths:
                    paths.append(name)
    except OSError:
        return []
    return paths


_FIND = threading.Lock()  # one search, also when two writer threads ask first at once


def gdal_library() -> ctypes.CDLL | None:
    """The GDAL library rasterio uses (its C functions declared), else pyogrio's, or None when neither is found.

    Several GDALs may be loaded at once (rasterio's and pyogrio's wheels bundle their own,
    of other versions, with their own drivers and settings): the one whose configuration
    rasterio sets is taken (drivers registered, PROJ's data found as rasterio finds it);
    pyogrio's (imported only then) when that one has no GeoPackage driver.
    """
    with _FIND:
        return _find_library()


@functools.lru_cache(maxsize=1)
def _find_library() -> ctypes.CDLL | None:
    import rasterio
    from rasterio._env import del_gdal_config, set_gdal_config

    with rasterio.Env():  # GDAL's drivers registered, its and PROJ's data paths set (they stay)
        pass
    lib = _probe(lambda key, value: set_gdal_config(key, value), del_gdal_config)
    if lib is not None:
        lib.GDALAllRegister()
        if lib.GDALGetDriverByName(b"GPKG"):
            return lib
    import pyogrio  # loads its GDAL and registers its drivers

    return _probe(lambda key, value: pyogrio.set_gdal_config_options({key: value}),
                  lambda key: pyogrio.set_gdal_config_options({key: None}))


def _probe(set_option: Callable[[str, str], None], unset_option: Callable[[str], None]) -> ctypes.CDLL | None:
    """The loaded GDAL library on which ``set_option`` sets a configuration option, its functions declared."""
    import uuid

    token = uuid.uuid4().hex
    set_option(_PROBE, token)
    try:
        for path in _loaded_libraries():
            try:
                lib = ctypes.CDLL(path)  # the loaded library (same handle); ctypes calls release the GIL
                for name, (restype, argtypes) in _SIGNATURES.items():
                    fn = getattr(lib, name)
                    fn.restype, fn.argtypes = restype, argtypes
            except (OSError, AttributeError):  # not loadable, or a GDAL without the Arrow interface (< 3.8)
                continue
            value = lib.CPLGetConfigOption(_PROBE.encode(), None)
            if value is not None and value.decode() == token:
                return lib
        return None
    finally:
        unset_option(_PROBE)


@contextlib.contextmanager
def thread_config_option(name: str, value: str) -> Iterator[bool]:
    """GDAL's configuration option ``name`` is ``value`` for the calling thread only while the block runs.

    Set on the GDAL library the writers use (:func:`gdal_library`) with
    ``CPLSetThreadLocalConfigOption``, so GDAL calls made by other threads (a caller's own
    writers) keep their settings; the thread's previous value is restored after. Yields
    False, setting nothing, when that library is not found.
    """
    lib = gdal_library()
    if lib is None:
        yield False
        return
    key = name.encode()
    before = lib.CPLGetThreadLocalConfigOption(key, None)  # a copy (bytes), or None when unset
    lib.CPLSetThreadLocalConfigOption(key, value.encode())
    try:
        yield True
    finally:
        lib.CPLSetThreadLocalConfigOption(key, before)


def _options(values: dict[str, str]) -> Any:
    items = [f"{k}={v}".encode() for k, v in values.items()]
    return (ctypes.c_char_p * (len(items) + 1))(*items, None)


def write_arrow_layer(path: Path, layer: str, schema: Any, batches: Iterable[Any], *, geometry_name: str | None,
                      geometry_type: str | None, crs: str | None, layer_options: dict[str, str],
                      driver: str = "GPKG") -> None:
    """Write ``batches`` (pyarrow RecordBatches of ``schema``) as a new layer of ``path``.

    What ``pyogrio.write_arrow`` does for a new layer (the file is created, or opened in
    update mode when it exists; one transaction), with the GIL released inside GDAL.
    ``geometry_name``: the WKB column (None with ``geometry_type`` None: a table without
    geometry); ``crs``: anything ``OSRSetFromUserInput`` reads.

    Raises
    ------
    OSError
        GDAL failed (its message).
    """
    lib = gdal_library()
    if lib is None:
        raise OSError("GDAL's C library was not found in this process")
    # GDAL's messages go into the OSError raised, not to stderr (a worker thread has no handler of
    # pyogrio's: GDAL's default one prints them); the handler stack is the calling thread's
    lib.CPLPushErrorHandler(ctypes.cast(lib.CPLQuietErrorHandler, ctypes.c_void_p))
    try:
        _write_layer(lib, path, layer, schema, batches, geometry_name=geometry_name, geometry_type=geometry_type,
                     crs=crs, layer_options=layer_options, driver=driver)
    finally:
        lib.CPLPopErrorHandler()


def _write_layer(lib: ctypes.CDLL, path: Path, layer: str, schema: Any, batches: Iterable[Any], *,
                 geometry_name: str | None, geometry_type: str | None, crs: str | None, layer_options: dict[str, str],
                 driver: str) -> None:
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
        write_options = _options({} if geometry_name is None else
                                 {"GEOMETRY_NAME": geometry_name, "GEOMETRY_ENCODING": "WKB"})
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
