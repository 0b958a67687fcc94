"""Read any GDAL raster as an elevation ``xarray.DataArray`` in metres.

:func:`read_dem` is the single entry point through which orokit reads elevation data:
GeoTIFF/COG, SRTM ``.hgt`` (georeference from the file name, GDAL SRTMHGT driver),
ESRI ASCII grids, VRT mosaics, 16-bit PNG, and anything else rasterio opens.
"""
from __future__ import annotations

import contextlib
import logging
import math
import os
import threading
import warnings
import weakref
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, cast

import numpy as np
import rasterio
import rasterio.errors
from numpy.typing import NDArray
from pyproj import CRS
from rasterio.enums import Resampling
from rasterio.transform import Affine
from rasterio.windows import Window

from orokit._typing import PathLike
from orokit.errors import CRSError, InputError, OrokitWarning, UnitsError
from orokit.geodesy import cell_size_attrs, parse_crs
from orokit.io._units import TO_METRES, is_known_units, normalize_units

if TYPE_CHECKING:
    import xarray as xr

logger = logging.getLogger(__name__)

__all__ = ["read_dem", "read_dem_array", "DemArray", "read_raster_band", "raster_cell_count"]

ChunksLike = int | str | Sequence[int] | Mapping[str, int] | None
CellSizeLike = float | tuple[float, float] | None


#: elevations (metres) beyond these are not terrain anywhere on Earth (Challenger Deep is
#: about -10,935 m, Everest 8,849 m): such cells are void markers and read as nodata
PLAUSIBLE_MIN_M = -12_000.0
PLAUSIBLE_MAX_M = 9_000.0
#: raw values that tools write for voids without always declaring them as nodata
VOID_SENTINELS = (-9999.0, -32768.0, -32767.0, -99999.0)
#: more distinct values above any elevation on Earth than this, in a file without elevation units, are a range of
#: elevations in another unit (feet), not void markers (a file has one or two: 9999, 32767, 65535)
MAX_VOID_MARKERS = 16
#: SRTM .hgt tiles: (rows, cols) for 2-byte samples
_HGT_SHAPES = ((1201, 1201), (3601, 3601), (1801, 3601))
#: threads reading a whole raster (row stripes, one GDAL handle each) and rows a stripe has at least
READ_THREADS = min(4, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)
READ_MIN_ROWS = 512
#: formats whose rows GDAL reads at any offset (a PNG or an ASCII grid is decoded from its start: one thread)
READ_SPLIT_DRIVERS = frozenset({"GTiff", "COG", "SRTMHGT", "EHdr", "ENVI", "VRT"})


def _is_virtual(path: str) -> bool:
    return path.startswith("/vsi") or "://" in path


def _source_identity(path: str, files: list[str], mosaic_dir: str | None) -> tuple[Any, ...]:
    """What names a raster's pixels in its dask name (and so in a checkpoint's fingerprint): the real path of
    the file, or of the folder of tiles (not its temporary VRT, new in every run), and the real path, size
    and modification time of every file read (a VRT's sources too), however the path was spelled."""
    if _is_virtual(path):
        return (path,)
    own = os.path.realpath(path)
    read = {own} if mosaic_dir is None else set()
    read |= {os.path.realpath(f) for f in files if not _is_virtual(f)} - ({own} if mosaic_dir is not None else set())
    stamps = []
    for f in sorted(read):
        st = os.stat(f)
        stamps.append((f, st.st_mtime_ns, st.st_size))
    return (own if mosaic_dir is None else os.path.realpath(mosaic_dir), tuple(stamps))


@contextlib.contextmanager
def _open(path: str, *, what: str = "") -> Iterator[rasterio.io.DatasetReader]:
    """Open ``path`` with rasterio, mapping GDAL failures to :class:`InputError`."""
    with _open_dataset(path, what=what) as src:
        yield src


class _OpeningHere:
    """The message test of a warnings filter ignoring rasterio's ``NotGeoreferencedWarning`` only in a
    thread inside :func:`_open_dataset` (a raster without georeference gets its grid from the caller).

    ``warnings.catch_warnings`` would swap the process's filters and ``showwarning`` around each open:
    not thread-safe (an open in a dask or reader thread could put back another thread's filters or
    warning recorder for good, or drop them). This filter is put in front of every filter that would
    take the warning and left there; it matches no warning of another thread or outside the open (a
    caller's own ``rasterio.open`` warns).
    """

    def __init__(self) -> None:
        self._local = threading.local()
        self.entry = ("ignore", self, rasterio.errors.NotGeoreferencedWarning, None, 0)

    def match(self, text: str) -> bool:  # how the warnings module tests a filter's message
        return bool(getattr(self._local, "active", False))

    def __deepcopy__(self, memo: dict[int, Any]) -> _OpeningHere:  # a copy of the filters keeps this one
        return self

    #: what scikit-learn's ``Parallel`` replays in its workers (``warnings.filterwarnings(message=
    #: f.pattern)``; this attribute was missing: AttributeError): a regex matching no message, since no open
    #: of this thread is active there
    pattern = "(?!)"

    def __reduce__(self) -> tuple[Any, ...]:  # sent to another process: that process's own filter
        return (_not_georeferenced_filter, ())

    def _behind_a_catching_filter(self, filters: list[Any]) -> bool:
        """Whether this filter is missing from ``filters`` or behind one whose category takes the warning."""
        for entry in filters:
            if entry is self.entry:
                return False
            if issubclass(rasterio.errors.NotGeoreferencedWarning, entry[2]):
                return True
        return True

    @contextlib.contextmanager
    def active(self) -> Iterator[None]:
        filters = cast("list[Any]", warnings.filters)  # a list (typeshed: a Sequence)
        # put first only when needed (first open, filters reset, or one added since that catches this
        # warning): code that pushes a filter of another category and pops index 0 afterwards (POT's
        # ``get_params``) then pops its own even when an open ran between the two
        if self._behind_a_catching_filter(filters):
            with contextlib.suppress(ValueError):
                filters.remove(self.entry)
            filters.insert(0, self.entry)
        self._local.active = True
        try:
            yield
        finally:
            self._local.active = False


_NOT_GEOREFERENCED = _OpeningHere()


def _not_georeferenced_filter() -> _OpeningHere:
    return _NOT_GEOREFERENCED


def _open_dataset(path: str, *, what: str = "") -> rasterio.io.DatasetReader:
    """``rasterio.open(path)``, mapping GDAL failures to :class:`InputError`; the caller closes it."""
    try:
        with _NOT_GEOREFERENCED.active():
            src = rasterio.open(path)
    except rasterio.errors.RasterioIOError as exc:
        if path.lower().endswith(".hgt") and not _is_virtual(path) and Path(path).is_file():
            size = Path(path).stat().st_size
            expected = " or ".join(f"{2 * r * c:,} bytes ({r} x {c} samples)" for r, c in _HGT_SHAPES)
            raise InputError(
                f"cannot read SRTM tile {path}: it has {size:,} bytes, expected {expected}. The file is "
                "truncated or not an SRTM tile; download it again."
            ) from exc
        raise InputError(
            f"cannot read raster {path}{what}: {str(exc).rstrip('.')}. Check that the file is complete and in a format GDAL "
            "reads (GeoTIFF/COG, SRTM .hgt, ESRI ASCII .asc, VRT, PNG)."
        ) from exc
    return src


class _WindowHandles(threading.local):
    """Per thread: the dataset a windowed read opened last, kept open for the next window.

    Opening parses the whole file header; for a VRT mosaic that is every source (0.04 s at
    49 x 49 tiles, 0.1 s at 98 x 98), and a chunk read with its halo takes nine windows, so
    reopening cost more than the reading. The handle is reused only while the file's
    size, time and inode are unchanged; one per thread (GDAL handles are not thread-safe).
    """

    def __init__(self) -> None:
        self.path: str | None = None
        self.stamp: tuple[int, int, int] | None = None
        self.src: rasterio.io.DatasetReader | None = None

    def get(self, path: str, what: str) -> rasterio.io.DatasetReader:
        try:
            st = os.stat(path)
            stamp: tuple[int, int, int] | None = (st.st_size, st.st_mtime_ns, st.st_ino)
        except OSError:  # /vsi paths, URLs: no reuse
            stamp = None
        if self.src is not None and stamp is not None and self.path == path and self.stamp == stamp:
            return self.src
        self.close()
        src = _open_dataset(path, what=what)
        if stamp is not None:  # kept open for the next window
            self.path, self.stamp, self.src = path, stamp, src
        return src

    def close(self) -> None:
        if self.src is not None:
            self.src.close()
        self.path = self.stamp = self.src = None


_WINDOW_HANDLES = _WindowHandles()


def window_source(data: Any) -> Any:
    """The reader behind ``data``, a dask array :func:`read_dem` made and nothing changed since (same name),
    or None: ``source[r0:r1, c0:c1]`` reads that window of the file straight away, converted as the
    array's chunks are (one GDAL read, no dask graph: computing a slice of the array optimises the whole
    raster's graph, O(chunks) per window)."""
    return _READERS.get(getattr(data, "name", None) or "")


#: the reader of each dask array :func:`read_dem` made, by the array's name (:func:`window_source`); the array's
#: graph holds the reader, so an entry lives as long as an array of that name
_READERS: weakref.WeakValueDictionary[str, Any] = weakref.WeakValueDictionary()


@dataclass(frozen=True)
class _BandReader:
    """Array-like view of one raster band converted to float32 metres with NaN nodata.

    ``dask.array.from_array`` slices it chunk by chunk, so only the requested window
    is ever read; it holds no open file handle and pickles for dask.distributed.
    """

    path: str
    band: int
    shape: tuple[int, int]
    native_dtype: str
    nodata: float | None
    factor: float  # metres per input unit, times the band scale
    offset_m: float  # band offset, in metres
    units_assumed: bool = False  # the file declares no elevation units: metres assumed
    dtype: np.dtype = np.dtype(np.float32)
    ndim: int = 2

    def _in_place(self, dtype: np.dtype) -> bool:
        """float32 metres are converted in place (a copy would double the peak memory)."""
        return np.dtype(dtype) == np.float32 and self.factor == 1.0 and self.offset_m == 0.0

    def _convert(self, raw: NDArray[Any], where: str = "") -> NDArray[np.float32]:
        out = None if self._in_place(raw.dtype) else np.empty(raw.shape, np.float32)
        self._warn_implausible(*self._fill(raw, out), where)
        return raw if out is None else out

    def _fill(self, raw: NDArray[Any], out: NDArray[np.float32] | None) -> tuple[int, list[NDArray[Any]]]:
        """``raw`` as float32 metres with NaN nodata into ``out`` (None: in place, float32 metres only).

        By row blocks, so the float64 intermediate of integer inputs stays small. Returns
        the number of implausible cells made nodata and their distinct raw values.
        """
        inplace = out is None
        n_bad = 0
        bad_values = []
        step = max(1, (1 << 20) // max(1, raw.shape[-1]))  # ~1 M cells: each bool temporary ~1 MB
        for r0 in range(0, raw.shape[0], step):
            blk = raw[r0:r0 + step]
            valid = np.ones(blk.shape, dtype=bool)
            if self.nodata is not None:
                if np.isnan(self.nodata):
                    valid &= ~np.isnan(blk)
                else:
                    valid &= blk != _native_sentinel(self.nodata, blk.dtype)
            if blk.dtype.kind == "f":
                valid &= np.isfinite(blk)
            # undeclared void markers (-9999, -32768...) are never terrain: nodata, reported
            undeclared = None
            for v in VOID_SENTINELS:
                if self.nodata is not None and v == self.nodata:
                    continue
                native = _native_sentinel(v, blk.dtype)
                if isinstance(native, np.float64) and blk.dtype.kind in "iu":
                    continue  # cannot occur in this dtype
                hit = blk == native
                undeclared = hit if undeclared is None else (undeclared | hit)
            if undeclared is not None:
                undeclared &= valid
            if inplace:
                z = blk
            else:
                # integer inputs (uint16 PNGs, int16 SRTM with -32768 voids) go through
                # float64: no overflow, exact for every 32-bit integer value.
                z = blk.astype(np.float64)
                if self.factor != 1.0:
                    z *= self.factor
                if self.offset_m != 0.0:
                    z += self.offset_m
            with np.errstate(invalid="ignore"):
                implausible = valid & ((z < PLAUSIBLE_MIN_M) | (z > PLAUSIBLE_MAX_M))
            if undeclared is not None:
                implausible |= undeclared
            k = int(np.count_nonzero(implausible))
            if k:
                n_bad += k
                bad_values.append(np.unique(blk[implausible]))
                valid &= ~implausible
            z[~valid] = np.nan
            if out is not None:
                out[r0:r0 + step] = z
        return n_bad, bad_values

    def _warn_implausible(self, n_bad: int, bad_values: list[NDArray[Any]], where: str) -> None:
        """Warn about cells read as nodata for their values; refuse a file without elevation units whose
        values run on past any elevation on Earth (a range of values, not a few void markers: not metres)."""
        if n_bad:
            values = np.unique(np.concatenate(bad_values))
            if self.units_assumed:
                metres = values.astype(np.float64) * self.factor + self.offset_m
                high = metres[metres > PLAUSIBLE_MAX_M]
                if high.size > MAX_VOID_MARKERS:
                    raise UnitsError(
                        f"{self.path}{where} declares no elevation units, so they were read as metres, but it holds "
                        f"{high.size} different values above {PLAUSIBLE_MAX_M:g} m (up to {high.max():g}): a range of "
                        "elevations, not void markers, so its unit is not the metre (in feet the highest would be "
                        f"{high.max() * TO_METRES['ft']:.0f} m). Pass --z-units ft (z_units='ft') if it is in feet, or "
                        "--z-units m to read it as metres with those cells as nodata."
                    )
            shown = ", ".join(f"{v:g}" for v in values[:3]) + (", ..." if len(values) > 3 else "")
            warnings.warn(
                f"{self.path}{where}: {n_bad} cells hold void markers or values beyond any elevation on Earth "
                f"({shown} {'' if self.factor == 1.0 else 'in the file units '}; plausible: {PLAUSIBLE_MIN_M:g} to "
                f"{PLAUSIBLE_MAX_M:g} m) and the file declares no such nodata; they are read as nodata. Declare the "
                "nodata value in the file (gdal_edit.py -a_nodata) or check the elevation units (--z-units).",
                OrokitWarning,
                stacklevel=4,
            )

    def read(self, window: Window | None = None, out_shape: tuple[int, int] | None = None) -> NDArray[np.float32]:
        if window is None and out_shape is None:
            return self._read_all()
        where = "" if window is None else f" (rows {window.row_off}:{window.row_off + window.height}, cols {window.col_off}:{window.col_off + window.width})"
        if out_shape is not None:
            with _open(self.path, what=where) as src:
                try:
                    raw = src.read(self.band, out_shape=out_shape, resampling=Resampling.nearest)
                except rasterio.errors.RasterioError as exc:
                    raise self._read_error(exc, where) from exc
            return self._convert(raw, where)
        # a window (a dask chunk): the thread's handle of this file stays open for the next one
        src = _WINDOW_HANDLES.get(self.path, where)
        try:
            raw = src.read(self.band, window=window)
        except rasterio.errors.RasterioError as exc:
            _WINDOW_HANDLES.close()
            raise self._read_error(exc, where) from exc
        finally:
            if _WINDOW_HANDLES.src is not src:
                src.close()
        return self._convert(raw, where)

    def _read_error(self, exc: Exception, where: str) -> InputError:
        return InputError(
            f"cannot read the pixels of {self.path}{where}: {str(exc).rstrip('.')}. The file is probably truncated or "
            "corrupt; download it again (orokit data fetch) or re-export it."
        )

    def _read_all(self) -> NDArray[np.float32]:
        """The whole band, in row stripes read and converted by parallel threads (one GDAL handle each).

        Stripes start on block rows, so no block is read twice; each stripe's handle is closed
        once read (its blocks leave GDAL's cache).
        """
        h, w = self.shape
        raw = np.empty(self.shape, np.dtype(self.native_dtype))
        out = raw if self._in_place(raw.dtype) else np.empty(self.shape, np.float32)
        with _open(self.path) as src:
            block_rows = max(1, int(src.block_shapes[self.band - 1][0]))
            seekable = src.driver in READ_SPLIT_DRIVERS
        k = max(1, min(READ_THREADS, h // max(block_rows, READ_MIN_ROWS))) if seekable else 1
        cuts = sorted({min(h, -(-(i * h // k) // block_rows) * block_rows) for i in range(k)} | {h})

        def stripe(r0: int, r1: int) -> tuple[int, list[NDArray[Any]]]:
            with _open(self.path) as src:
                try:
                    src.read(self.band, window=Window(0, r0, w, r1 - r0), out=raw[r0:r1])
                except rasterio.errors.RasterioError as exc:
                    raise self._read_error(exc, "") from exc
            return self._fill(raw[r0:r1], None if out is raw else out[r0:r1])

        if len(cuts) == 2:
            parts = [stripe(0, h)]
        else:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(len(cuts) - 1) as pool:
                parts = list(pool.map(stripe, cuts[:-1], cuts[1:]))
        del raw
        self._warn_implausible(sum(p[0] for p in parts), [v for p in parts for v in p[1]], "")
        return out

    def __getitem__(self, key: Any) -> NDArray[np.float32]:
        if not isinstance(key, tuple):
            key = (key,)
        key = key + (slice(None),) * (2 - len(key))
        rs, cs = (k.indices(n) if isinstance(k, slice) else None for k, n in zip(key, self.shape))
        if rs is None or cs is None or rs[2] != 1 or cs[2] != 1:
            # generic indexing (rare): read everything and let numpy index
            return self.read()[key]
        r0, r1, _ = rs
        c0, c1, _ = cs
        if r1 <= r0 or c1 <= c0:
            return np.empty((max(r1 - r0, 0), max(c1 - c0, 0)), dtype=np.float32)
        return self.read(Window(c0, r0, c1 - c0, r1 - r0))


def _native_sentinel(nodata: float, dtype: np.dtype) -> Any:
    """The nodata value expressed in the raster's own dtype (compared once, at read)."""
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        if float(nodata).is_integer() and info.min <= nodata <= info.max:
            return dtype.type(int(nodata))
        return np.float64(nodata)  # cannot occur in this dtype: compare in float64 (never equal)
    if dtype.kind == "f":
        return dtype.type(nodata)
    return nodata


def _normalize_cell_size(cell_size_m: Any) -> tuple[float, float]:
    try:
        if np.ndim(cell_size_m) == 0:
            dx = dy = float(cell_size_m)
        else:
            dx, dy = (float(v) for v in cell_size_m)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"cell_size_m must be a positive number of metres or a pair (dx, dy), got {cell_size_m!r}."
        ) from exc
    if not (math.isfinite(dx) and math.isfinite(dy) and dx > 0 and dy > 0):
        raise InputError(f"cell_size_m must be positive and finite (metres), got {cell_size_m!r}.")
    return dx, dy


def _normalize_chunks(chunks: ChunksLike, shape: tuple[int, int]) -> tuple[tuple[int, ...], tuple[int, ...]]:
    from dask.array.core import normalize_chunks

    if isinstance(chunks, Mapping):
        unknown = set(chunks) - {"y", "x"}
        if unknown:
            raise InputError(f"chunks keys must be 'y' and/or 'x', got {sorted(chunks)!r}.")
        chunks = (chunks.get("y", -1), chunks.get("x", -1))
    elif isinstance(chunks, bool):
        chunks = "auto"
    try:
        return normalize_chunks(chunks, shape=shape, dtype=np.float32)
    except (ValueError, TypeError) as exc:
        raise InputError(f"invalid chunks={chunks!r} for a raster of shape {shape}: {exc}") from exc


def read_raster_band(source: PathLike, *, what: str = "raster") -> xr.DataArray:
    """The single band of any raster, as stored (no unit conversion), nodata masked to NaN.

    For inputs that are not elevations (control maps: density, type codes); CRS and
    transform as in the file (none for a plain image). ``what`` names the input in errors.

    Raises
    ------
    InputError
        Unreadable file, or more than one band.
    """
    import rioxarray
    import xarray as xr

    try:
        da = rioxarray.open_rasterio(source, masked=True)
    except Exception as exc:  # noqa: BLE001 - rasterio errors vary
        raise InputError(f"cannot read {what} {str(source)!r}: {exc}") from exc
    if not isinstance(da, xr.DataArray):
        raise InputError(f"{what} {str(source)!r} holds several subdatasets; give a single-band raster")
    if "band" in da.dims:
        if da.sizes["band"] != 1:
            raise InputError(f"{what} {str(source)!r} has {da.sizes['band']} bands; give a single-band raster")
        da = da.squeeze("band", drop=True)
    return da


def read_dem(
    source: PathLike,
    *,
    z_units: str | None = None,
    cell_size_m: CellSizeLike = None,
    band: int | None = None,
    chunks: ChunksLike = None,
    nodata: float | None = None,
    crs: Any = None,
) -> xr.DataArray:
    """Read an elevation raster as float32 metres with NaN nodata, CRS and transform.

    Parameters
    ----------
    source
        Path of any raster GDAL reads (GeoTIFF/COG, SRTM ``.hgt``/``.hgt.zip`` named
        like ``N32W098.hgt``, ESRI ASCII grid, VRT mosaic, 16-bit PNG...), a GDAL
        virtual path (``/vsizip/...``, ``/vsicurl/...``), or a directory of tiles
        (mosaicked by geotransform through a VRT, see :mod:`orokit.io.mosaic`).
    z_units
        Elevation units of the file: ``"m"``, ``"ft"`` (x 0.3048 exactly) or
        ``"us-ft"``. Default: the band's unit metadata if any, else metres for a
        raster with a CRS. Required for rasters without CRS that declare no units
        (the PNG DEMs).
    cell_size_m
        Cell size in metres (a number, or ``(dx, dy)``) for a raster without
        georeference: it then gets a local metric grid with origin (0, 0) at the
        north-west corner and y decreasing downwards. Refused for geographic CRS and
        when it disagrees with the file's own transform.
    band
        1-based band number; required when the raster has several bands.
    chunks
        None reads the band into memory. Otherwise the result is a lazy dask array
        with these chunks (int, ``(y, x)``, ``{"y": .., "x": ..}`` or ``"auto"``);
        only windows of the file are read, when computed.
    nodata
        Nodata value overriding the file's own. It is compared with the raw values
        in the file's dtype, before any conversion.
    crs
        CRS to assign to a raster that has none (EPSG code, WKT, pyproj CRS). A raster
        with a CRS keeps it; a different ``crs`` is an error.

    Returns
    -------
    xarray.DataArray
        Dims ``("y", "x")`` with cell-centre coordinates, dtype float32, metres, NaN
        where nodata; ``rio.crs`` / ``rio.transform()`` set (CRS None for a local
        grid). ``attrs``: ``units`` ("m"), ``source``, ``z_units_in`` (units of the
        file), ``z_units_assumed`` (True when metres were assumed), ``local_grid``
        (True when the raster had no CRS and gets a local metric grid),
        ``cell_size_m`` ((dx, dy) in metres) or, on a geographic CRS, ``cell_size_deg``
        ((dx, dy) in degrees), ``band``, ``nodata_in`` (the raw
        sentinel or None).

    Raises
    ------
    InputError
        Missing, unreadable, truncated or corrupt file; empty or all-nodata raster;
        several bands without ``band``; bad ``cell_size_m``/``chunks``; rotated grids.
    UnitsError
        Unknown units string, or no units known for an ungeoreferenced raster.
    CRSError
        No georeference and no ``cell_size_m``; ``cell_size_m`` with a geographic CRS or
        conflicting with the file; ``crs`` conflicting with the file's CRS.

    Notes
    -----
    1. The file is opened once to read its metadata (size, bands, dtype, CRS,
       transform, nodata, units, scale/offset); VRT sources are checked to exist.
    2. Nodata cells are found by comparing the raw values with the sentinel in the
       native dtype (so -32768 in int16 and -3.4e38 in float32 both match exactly),
       plus non-finite floats. Integer inputs are converted through float64, so
       uint16/int16 never overflow. Feet are converted once, here (x 0.3048).
    3. Rasters without CRS are labelled ``local_grid=True``: distances on them are
       plain metres (see :mod:`orokit.geodesy`); no geographic feature is implied.
    4. With ``chunks``, an all-nodata raster is detected from a decimated sample and,
       only if that sample is empty, a streamed pass over the chunks.

    Examples
    --------
    >>> import numpy as np, rasterio, tempfile, os
    >>> from rasterio.transform import Affine
    >>> path = os.path.join(tempfile.mkdtemp(), "dem.tif")
    >>> with rasterio.open(path, "w", driver="GTiff", width=3, height=2, count=1, dtype="int16",
    ...                    crs="EPSG:32633", transform=Affine(30, 0, 500000, 0, -30, 4000000), nodata=-32768) as dst:
    ...     dst.write(np.array([[1, 2, 3], [4, -32768, 6]], dtype="int16"), 1)
    >>> dem = read_dem(path)
    >>> dem.dims, str(dem.dtype), dem.attrs["units"], int(dem.isnull().sum())
    (('y', 'x'), 'float32', 'm', 1)
    """
    return cast("xr.DataArray", _read_dem(source, z_units=z_units, cell_size_m=cell_size_m, band=band,
                                          chunks=chunks, nodata=nodata, crs=crs))


@dataclass(frozen=True)
class DemArray:
    """A DEM read into memory without xarray (:func:`read_dem_array`).

    The same pixels, georeference and ``attrs`` as :func:`read_dem`'s DataArray, for
    callers that need neither xarray nor dask (``orokit analyze`` in memory starts
    faster and smaller without them). ``transform`` is the affine transform and
    ``crs`` the CRS (None on a local metric grid).
    """

    values: NDArray[np.float32]
    transform: Affine
    crs: CRS | None
    attrs: dict[str, Any]
    dims: ClassVar[tuple[str, str]] = ("y", "x")
    chunks: ClassVar[None] = None

    @property
    def data(self) -> NDArray[np.float32]:
        return self.values

    def release(self) -> None:
        """Drop the pixels: ``values`` becomes a read-only all-NaN view of the same shape and dtype
        (float32 for integer pixels, which have no NaN; no memory); the georeference and ``attrs``
        stay. For a caller whose analysis no longer needs them (:func:`orokit.analysis.analyze`
        with ``release_dem=True``)."""
        dtype = self.values.dtype if np.issubdtype(self.values.dtype, np.floating) else np.dtype(np.float32)
        empty = np.broadcast_to(np.array(np.nan, dtype=dtype), self.values.shape)
        object.__setattr__(self, "values", empty)  # frozen: the fields keep their meaning, the pixels go

    @property
    def shape(self) -> tuple[int, int]:
        return self.values.shape

    @property
    def ndim(self) -> int:
        return 2


def read_dem_array(
    source: PathLike,
    *,
    z_units: str | None = None,
    cell_size_m: CellSizeLike = None,
    band: int | None = None,
    nodata: float | None = None,
    crs: Any = None,
) -> DemArray:
    """:func:`read_dem` into memory as a :class:`DemArray` (no xarray, rioxarray or dask).

    Same arguments (but ``chunks``), checks, errors, warnings, pixels and attrs.

    Examples
    --------
    >>> import numpy as np, rasterio, tempfile, os
    >>> from rasterio.transform import Affine
    >>> path = os.path.join(tempfile.mkdtemp(), "dem.tif")
    >>> with rasterio.open(path, "w", driver="GTiff", width=3, height=2, count=1, dtype="int16",
    ...                    crs="EPSG:32633", transform=Affine(30, 0, 500000, 0, -30, 4000000), nodata=-32768) as dst:
    ...     dst.write(np.array([[1, 2, 3], [4, -32768, 6]], dtype="int16"), 1)
    >>> dem = read_dem_array(path)
    >>> dem.shape, str(dem.values.dtype), dem.transform.a, dem.crs.to_epsg(), int(np.isnan(dem.values).sum())
    ((2, 3), 'float32', 30.0, 32633, 1)
    """
    return cast(DemArray, _read_dem(source, z_units=z_units, cell_size_m=cell_size_m, band=band, chunks=None,
                                    nodata=nodata, crs=crs, as_array=True))


def _read_dem(
    source: PathLike,
    *,
    z_units: str | None,
    cell_size_m: CellSizeLike,
    band: int | None,
    chunks: ChunksLike,
    nodata: float | None,
    crs: Any,
    as_array: bool = False,
) -> xr.DataArray | DemArray:
    """:func:`read_dem` (``as_array``: :func:`read_dem_array`)."""
    path = os.fspath(source)
    mosaic_dir: str | None = None  # a folder of tiles, read through a temporary VRT
    if not _is_virtual(path):
        p = Path(path)
        if not p.exists():
            raise InputError(f"DEM file not found: {path}. Check the path (or fetch it: orokit data fetch NAME).")
        if p.is_dir():
            # a directory of tiles: mosaic them by geotransform in a VRT (read lazily with chunks=)
            import atexit
            import shutil
            import tempfile

            from orokit.io.mosaic import build_vrt

            folder = tempfile.mkdtemp(prefix="orokit-mosaic-")
            # a lazy DEM reads the VRT as long as it lives, at most until the process ends: removed then
            # (by this process only: a forked child that exits leaves it to its parent)
            pid = os.getpid()

            def remove_mosaic() -> None:
                if os.getpid() == pid:
                    shutil.rmtree(folder, ignore_errors=True)

            atexit.register(remove_mosaic)
            mosaic_dir = path
            path = os.fspath(build_vrt(p, Path(folder) / f"{p.name}.vrt"))
            p = Path(path)
        if p.stat().st_size == 0:
            raise InputError(f"DEM file {path} is empty (0 bytes); download or export it again.")

    with _open(path) as src:
        if src.driver == "AAIGrid" and not _is_virtual(path):
            _check_ascii_grid(path, src.width, src.height)
        width, height, count = src.width, src.height, src.count
        file_crs = CRS.from_user_input(src.crs) if src.crs else None
        file_transform = src.transform
        has_gcps = bool(src.gcps[0])
        dtypes = src.dtypes
        nodatavals = src.nodatavals
        band_units = src.units
        scales, offsets = src.scales, src.offsets
        files = list(src.files) if src.driver == "VRT" else []
        driver = src.driver

    if width == 0 or height == 0:
        raise InputError(f"raster {path} is empty ({height} rows x {width} columns).")

    # -- band ---------------------------------------------------------------------
    if band is None:
        if count != 1:
            raise InputError(
                f"raster {path} has {count} bands; choose the elevation band with band=1..{count} (CLI: --band)."
            )
        band = 1
    if isinstance(band, bool) or not isinstance(band, (int, np.integer)) or not 1 <= int(band) <= count:
        raise InputError(f"band={band!r} is not valid for {path}, which has {count} band(s) (1-based: 1..{count}).")
    band = int(band)
    native = np.dtype(dtypes[band - 1])
    if native.kind not in "iuf":
        raise InputError(f"band {band} of {path} has dtype {native}, which is not a real-valued elevation type.")

    # -- VRT sources --------------------------------------------------------------
    for f in files[1:]:
        if not _is_virtual(f) and not Path(f).exists():
            raise InputError(f"VRT mosaic {path} refers to a missing source file {f}; fix or rebuild the VRT.")

    # -- units --------------------------------------------------------------------
    file_units = (band_units[band - 1] or "").strip() if band_units else ""
    z_assumed = False
    if z_units is not None:
        zu = normalize_units(z_units)
        if file_units and is_known_units(file_units) and normalize_units(file_units) != zu:
            warnings.warn(
                f"{path} declares elevation units {file_units!r} but z_units={z_units!r} was given; using {zu!r}.",
                OrokitWarning,
                stacklevel=2,
            )
    elif file_units:
        if not is_known_units(file_units):
            raise UnitsError(
                f"{path} declares elevation units {file_units!r}, which orokit does not know; pass z_units='m' or "
                "'ft' (CLI: --z-units) to say what they are."
            )
        zu = normalize_units(file_units)
    elif file_crs is not None:
        zu, z_assumed = "m", True
        logger.info("%s declares no elevation units; assuming metres (pass z_units to override)", path)
    else:
        raise UnitsError(
            f"{path} has no CRS and no elevation units, so its units are unknown; pass z_units='ft' or 'm' "
            "(CLI: --z-units). The orokit PNG datasets are in feet: orokit.data.open_dataset_dem(name) knows it."
        )

    # -- georeference -------------------------------------------------------------
    user_crs = parse_crs(crs)
    if file_crs is not None and user_crs is not None and not file_crs.equals(user_crs):
        raise CRSError(
            f"{path} already has CRS {file_crs.to_string()!r}; crs={user_crs.to_string()!r} conflicts with it. "
            "A raster with a CRS keeps it: drop crs=, or reproject the file (gdalwarp) first."
        )
    eff_crs = file_crs or user_crs
    has_transform = file_transform != Affine.identity()
    if has_gcps and not has_transform:
        raise CRSError(f"{path} is georeferenced by ground control points only; warp it first (gdalwarp).")
    if file_transform.b != 0 or file_transform.d != 0:
        raise InputError(f"{path} has a rotated grid (transform {tuple(file_transform)[:6]}); warp it first (gdalwarp).")

    if cell_size_m is not None:
        dx, dy = _normalize_cell_size(cell_size_m)
        if eff_crs is not None and eff_crs.is_geographic:
            raise CRSError(
                f"cell_size_m={cell_size_m!r} (metres) conflicts with the geographic CRS {eff_crs.to_string()!r} of "
                f"{path}: cells of a geographic grid are not square in metres. Drop cell_size_m; distances are "
                "computed geodesically (orokit.geodesy)."
            )
        if has_transform:
            fdx, fdy = abs(file_transform.a), abs(file_transform.e)
            if not (math.isclose(fdx, dx, rel_tol=1e-6) and math.isclose(fdy, dy, rel_tol=1e-6)):
                raise CRSError(
                    f"cell_size_m={cell_size_m!r} conflicts with the cells of {path} ({fdx:g} x {fdy:g} CRS units); "
                    "drop cell_size_m, the file's own georeference is used."
                )
            transform = file_transform
        else:
            transform = Affine(dx, 0.0, 0.0, 0.0, -dy, 0.0)
    elif has_transform:
        transform = file_transform
        if eff_crs is None:
            logger.info("%s has a transform but no CRS; treating it as a local metric grid", path)
    else:
        raise CRSError(
            f"{path} has no georeference (no CRS, no transform), so its cell size is unknown; pass "
            "cell_size_m=<metres> (CLI: --cell-size) to read it on a local metric grid."
        )
    if eff_crs is not None and eff_crs.is_geographic and not has_transform:
        raise CRSError(f"cannot place the ungeoreferenced raster {path} in the geographic CRS {eff_crs.to_string()!r}.")
    if eff_crs is not None and eff_crs.is_geographic:
        lats = (transform.f, transform.f + transform.e * height)
        worst = max(lats, key=abs)
        if abs(worst) > 90.0 + 1e-9 * max(1.0, abs(transform.e)):
            raise CRSError(
                f"{path} reaches latitude {worst:.6g} degrees (rows span {min(lats):.6g} to {max(lats):.6g}) in "
                f"the geographic CRS {eff_crs.to_string()!r}; latitudes lie within +-90. The transform (origin "
                "or cell size) is wrong, or the CRS is not geographic: fix the georeference (gdal_edit.py)."
            )

    # -- nodata / scaling ---------------------------------------------------------
    nd = nodata if nodata is not None else nodatavals[band - 1]
    nd = None if nd is None else float(nd)
    scale = 1.0 if scales[band - 1] is None else float(scales[band - 1])
    offset = 0.0 if offsets[band - 1] is None else float(offsets[band - 1])
    to_m = TO_METRES[zu]
    reader = _BandReader(
        path=path,
        band=band,
        shape=(height, width),
        native_dtype=native.str,
        nodata=nd,
        factor=to_m * scale,
        offset_m=to_m * offset,
        units_assumed=z_assumed,
    )

    # -- pixels -------------------------------------------------------------------
    if chunks is None:
        data: Any = reader.read()
        if np.isnan(np.fmax.reduce(data, axis=None)):  # all NaN (read made +-inf NaN); no bool per cell
            raise InputError(_all_nodata_message(path, nd))
    else:
        import dask.array as dsa
        from dask.base import tokenize

        norm = _normalize_chunks(chunks, (height, width))
        name = "read_dem-" + tokenize(_source_identity(path, files, mosaic_dir), band, nd, reader.factor,
                                      reader.offset_m, norm)
        data = dsa.from_array(reader, chunks=norm, name=name, lock=False, asarray=False, meta=np.empty((0, 0), np.float32))
        _READERS[name] = reader  # the same name means the same file, band and conversion
        sample = reader.read(out_shape=(min(height, 256), min(width, 256)))
        if not np.isfinite(sample).any() and not bool(dsa.isfinite(data).any().compute()):
            raise InputError(_all_nodata_message(path, nd))

    t = transform
    x = t.c + t.a * (np.arange(width) + 0.5)
    y = t.f + t.e * (np.arange(height) + 0.5)
    attrs = {
        "units": "m",
        "source": path,
        "driver": driver,
        "z_units_in": zu,
        "z_units_assumed": z_assumed,
        "local_grid": eff_crs is None,
        **cell_size_attrs(t, eff_crs),
        "band": band,
        "nodata_in": nd,
        "long_name": "elevation",
    }
    if as_array:
        logger.info("read %s: %d x %d cells, %s, units %s -> m", path, height, width,
                    eff_crs.to_string() if eff_crs is not None else "local metric grid", zu)
        return DemArray(data, transform, eff_crs, attrs)
    import rioxarray  # noqa: F401  (registers the .rio accessor)
    import xarray as xr

    dem = xr.DataArray(data, dims=("y", "x"), coords={"y": y, "x": x}, name="elevation", attrs=attrs)
    # in place: rioxarray's default copies the whole array (deeply) at each call
    if eff_crs is not None:
        dem.rio.write_crs(eff_crs, inplace=True)
    dem.rio.write_transform(transform, inplace=True)
    dem.rio.write_nodata(np.nan, encoded=False, inplace=True)
    logger.info(
        "read %s: %d x %d cells, %s, units %s -> m%s",
        path, height, width, eff_crs.to_string() if eff_crs is not None else "local metric grid", zu,
        "" if chunks is None else f", chunks {tuple(len(c) for c in dem.chunks or ())} blocks",
    )
    return dem


def raster_cell_count(path: PathLike) -> int | None:
    """Number of cells of a raster file (header only), or None when GDAL cannot open it."""
    try:
        with _open(str(path)) as ds:  # no NotGeoreferencedWarning for a PNG (read_dem handles it)
            return int(ds.width) * int(ds.height)
    except Exception:  # noqa: BLE001 - read_dem reports unreadable inputs with a proper message
        return None


def _all_nodata_message(path: str, nd: float | None) -> str:
    return (
        f"raster {path} has no valid cells: every cell is nodata (nodata={nd}) or not finite. "
        "Check the nodata value (nodata=...) or the file."
    )


def _check_ascii_grid(path: str, ncols: int, nrows: int) -> None:
    """Refuse an ESRI ASCII grid whose body disagrees with its header.

    GDAL reads the values as one stream, so a row holding more (or fewer) values than
    ``ncols`` silently shifts every following row: the grid would be scrambled.
    """
    n_lines = 0
    total = 0
    with open(path, "rb") as fh:
        for line in fh:
            parts = line.split()
            if not parts:
                continue
            head = parts[0].lower()
            if n_lines == 0 and head[:1].isalpha():  # header: ncols, nrows, xllcorner, ..., nodata_value
                continue
            n_lines += 1
            total += len(parts)
            if len(parts) != ncols:
                raise InputError(
                    f"ESRI ASCII grid {path}: data row {n_lines} holds {len(parts)} values but the header says "
                    f"ncols {ncols}; every row must hold ncols values (GDAL would re-wrap the rows and scramble "
                    "the grid). Fix the header or the rows."
                )
    if n_lines != nrows:
        raise InputError(
            f"ESRI ASCII grid {path}: {n_lines} data rows but the header says nrows {nrows}; fix the header or "
            "the file (truncated?)."
        )
