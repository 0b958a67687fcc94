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
from helpers.dems import build_dem

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MIRROR = REPO_ROOT.parent / "shared" / "data"


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
