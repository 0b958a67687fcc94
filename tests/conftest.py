"""Shared pytest fixtures of orokit.

- ``make_dem(array, res=30.0, crs="EPSG:32633", nodata=None, origin=None)``: a small
  georeferenced DEM (``xarray.DataArray`` like :func:`orokit.io.dem.read_dem` returns).
- ``real_data(name) -> Path``: local path of a manifest dataset/file, fetched through
  ``OROKIT_DATA_MIRROR`` (default: ``../shared/data`` beside the repository when it
  exists) into the cache. When the data cannot be obtained the test FAILS if the
  environment variable ``CI`` is set, and is skipped otherwise.
- ``data_mirror -> Path``: the mirror directory itself, same fail/skip rule.

Tests using real data are marked ``@pytest.mark.realdata``.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MIRROR = REPO_ROOT.parent / "shared" / "data"


def build_dem(
    array: Any,
    res: float | tuple[float, float] = 30.0,
    crs: Any = "EPSG:32633",
    nodata: float | None = None,
    origin: tuple[float, float] | None = None,
):
    """Build a DEM DataArray with dims (y, x), transform and CRS.

    ``array`` keeps its dtype (integers stay integers) unless ``nodata`` is given:
    then cells equal to ``nodata`` become NaN in a float copy, as ``read_dem`` does.
    ``res`` is the cell size in CRS units (a number or ``(dx, dy)``); ``origin`` is
    the (west, north) corner, by default (500000, 4000000) for projected CRS,
    (10, 46) degrees for geographic CRS and (0, 0) for ``crs=None`` (local grid).
    Row 0 is the northern row.
    """
    import rioxarray  # noqa: F401
    import xarray as xr
    from pyproj import CRS
    from rasterio.transform import Affine

    from orokit.geodesy import cell_size_key

    a = np.asarray(array)
    if a.ndim != 2:
        raise ValueError(f"make_dem needs a 2-D array, got shape {a.shape}")
    if nodata is not None:
        a = a.astype(np.float64 if a.dtype.kind in "iub" else a.dtype, copy=True)
        a[a == nodata] = np.nan
    dx, dy = (float(res), float(res)) if np.ndim(res) == 0 else (float(res[0]), float(res[1]))
    c = None if crs is None else CRS.from_user_input(crs)
    if origin is None:
        origin = (0.0, 0.0) if c is None else ((10.0, 46.0) if c.is_geographic else (500000.0, 4000000.0))
    west, north = origin
    transform = Affine(dx, 0.0, west, 0.0, -dy, north)
    ny, nx = a.shape
    da = xr.DataArray(
        a,
        dims=("y", "x"),
        coords={"y": north - dy * (np.arange(ny) + 0.5), "x": west + dx * (np.arange(nx) + 0.5)},
        name="elevation",
        attrs={
            "units": "m",
            "source": "make_dem",
            "z_units_in": "m",
            "z_units_assumed": False,
            "local_grid": c is None,
            cell_size_key(c is not None and c.is_geographic): (dx, dy),
            "band": 1,
            "nodata_in": nodata,
        },
    )
    if c is not None:
        da = da.rio.write_crs(c)
    da = da.rio.write_transform(transform)
    return da


@pytest.fixture
def make_dem() -> Callable[..., Any]:
    """The :func:`build_dem` helper (see the module docstring)."""
    return build_dem


def _unavailable(msg: str) -> None:
    full = f"{msg}\nSet OROKIT_DATA_MIRROR to a copy of the orokit data (e.g. ../shared/data) or allow downloads."
    if os.environ.get("CI"):
        pytest.fail(f"CI: real data missing (tests must not skip in CI): {full}", pytrace=False)
    pytest.skip(full)


def _mirror() -> Path | None:
    env = os.environ.get("OROKIT_DATA_MIRROR")
    if env:
        return Path(env).expanduser().resolve()
    return DEFAULT_MIRROR if DEFAULT_MIRROR.is_dir() else None


@pytest.fixture(scope="session")
def data_mirror() -> Path:
    """The real-data mirror directory (fails in CI / skips elsewhere when absent)."""
    m = _mirror()
    if m is None or not m.is_dir():
        _unavailable(f"no data mirror directory (OROKIT_DATA_MIRROR={os.environ.get('OROKIT_DATA_MIRROR')!r}).")
    return m  # type: ignore[return-value]


@pytest.fixture(scope="session")
def real_data() -> Callable[[str], Path]:
    """Callable ``real_data(name) -> Path`` for a dataset name or manifest file path."""
    from orokit.data import fetch_file, load_manifest
    from orokit.errors import DataError

    manifest = load_manifest()
    mirror = _mirror()
    state: dict[str, str] = {}

    def get(name: str) -> Path:
        ds, entry = manifest.find_file(name)  # an unknown name is a bug in the test: let it raise
        if "down" in state:
            _unavailable(state["down"])
        try:
            return fetch_file(entry, mirror=mirror if mirror is not None else False)
        except (DataError, OSError) as exc:
            if mirror is None:  # network unavailable: do not retry for every test
                state["down"] = f"cannot download real data: {exc}"
            _unavailable(f"cannot obtain {name!r} ({entry.path}): {exc}")
            raise  # pragma: no cover - _unavailable always raises

    return get


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--update-golden", action="store_true", default=False,
                     help="Rewrite the golden files of tests/golden/ from the current code (review the diff).")


@pytest.fixture
def update_golden(request: pytest.FixtureRequest) -> bool:
    """True when pytest runs with ``--update-golden``."""
    return bool(request.config.getoption("--update-golden"))
