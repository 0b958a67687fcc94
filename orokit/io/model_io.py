"""Files of the region classifier: models (skops + metadata) and feature tables (Parquet).

Models
------
``MODEL.skops`` is a :mod:`skops.io` archive (never pickle: a pickle can run arbitrary
code when loaded) holding ``{"pipeline": <scikit-learn estimator>, "metadata": <JSON
text>}``: the metadata (feature set, radius, eps, classes, versions, evaluation) lives
*inside* the model file. ``MODEL.skops.json`` beside it is a readable copy of the same
metadata plus ``sha256``, the checksum of the model file, so the checksum covers the
metadata too.

Loading refuses, with a message naming the file and the fix:

1. a missing model or sidecar, an empty file, a file that is not a zip archive (a
   pickle renamed ``.skops`` is named as such and never unpickled), a sidecar that is
   not JSON or has another format version;
2. a model whose sha256 differs from the sidecar's;
3. an archive that skops cannot read (truncated, corrupt), or that holds types other
   than scikit-learn / numpy / builtins;
4. a sidecar whose metadata differs from the metadata stored in the model (an edited
   sidecar: feature names, bins, radius...), listing the keys that differ.

Feature tables
--------------
One row per disk, Parquet, with the table's ``attrs`` (feature set, radius, eps...) as
JSON in the ``orokit`` schema metadata.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from orokit._typing import PathLike
from orokit.errors import InputError, SchemaError
from orokit.io.atomic import atomic_path, write_bytes_atomic
from orokit.io.hashing import sha256_bytes

__all__ = ["MODEL_FORMAT", "metadata_path", "save_model_file", "load_model_file", "write_feature_table",
           "read_feature_table", "write_disk_map"]

#: format of the model file + sidecar; another format is refused (retrain)
MODEL_FORMAT = "orokit-region-classifier/2"
_TRUSTED_PREFIXES = ("sklearn.", "numpy.", "builtins.")
_PICKLE_MAGIC = (b"\x80", b"(", b"c")


def metadata_path(path: PathLike) -> Path:
    """Sidecar path of a model file: ``MODEL.skops`` -> ``MODEL.skops.json``."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def _canonical(metadata: dict[str, Any]) -> str:
    return json.dumps(metadata, sort_keys=True, default=_json_default)


def save_model_file(pipeline: Any, metadata: dict[str, Any], path: PathLike) -> Path:
    """Write ``pipeline`` and ``metadata`` into ``path`` (skops) and the sidecar, atomically.

    The sidecar is written last, so a model without a matching sidecar is never loaded.
    """
    import skops.io as sio

    path = Path(path)
    if metadata.get("format") != MODEL_FORMAT:
        raise SchemaError(f"model metadata must have format {MODEL_FORMAT!r} (use orokit.classify.model)")
    md = json.loads(_canonical({k: v for k, v in metadata.items() if k != "sha256"}))
    from orokit.io.reproducible import canonical_skops

    # same model, same bytes: skops names arrays after memory addresses and stamps the clock
    blob = canonical_skops(sio.dumps({"pipeline": pipeline, "metadata": _canonical(md)}))
    side = dict(md, sha256=sha256_bytes(blob))
    write_bytes_atomic(path, blob)
    write_bytes_atomic(metadata_path(path), json.dumps(side, indent=2, sort_keys=True).encode())
    return path


def _refuse_non_zip(path: Path, blob: bytes) -> None:
    if len(blob) == 0:
        raise InputError(f"model file {path} is empty (0 bytes); train it again with `orokit train`")
    if not blob.startswith(b"PK"):
        if blob[:1] in _PICKLE_MAGIC:
            raise InputError(f"model file {path} looks like a Python pickle, not a skops archive; orokit never "
                             f"loads pickles (they can run code). Train a model with `orokit train`")
        raise InputError(f"model file {path} is not a skops archive (no zip header); train it again with "
                         f"`orokit train`")


def load_model_file(path: PathLike, *, check_hash: bool = True) -> tuple[Any, dict[str, Any]]:
    """Read and verify a model written by :func:`save_model_file`.

    Returns
    -------
    (pipeline, metadata)
        The estimator and the metadata stored inside the model file.

    Raises
    ------
    InputError
        Missing, empty, non-zip, corrupt or replaced files; untrusted types.
    SchemaError
        Another format version, or a sidecar that differs from the stored metadata.
    """
    import skops.io as sio

    path = Path(path)
    mpath = metadata_path(path)
    if not path.is_file():
        raise InputError(f"model file {path} does not exist; train one with `orokit train`")
    if not mpath.is_file():
        raise InputError(f"model {path} has no metadata file {mpath.name}; orokit only loads models saved by "
                         f"`orokit train` (skops + metadata)")
    try:
        side = json.loads(mpath.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SchemaError(f"model metadata {mpath} is not valid JSON ({exc}); train the model again") from exc
    if not isinstance(side, dict):
        raise SchemaError(f"model metadata {mpath} is not a JSON object; train the model again")
    if side.get("format") != MODEL_FORMAT:
        raise SchemaError(f"model {path} has format {side.get('format')!r} (orokit {side.get('orokit_version')}); "
                          f"this orokit reads {MODEL_FORMAT!r}: retrain with `orokit train`")
    blob = path.read_bytes()
    digest = sha256_bytes(blob)
    if check_hash and side.get("sha256") != digest:
        raise InputError(f"model {path} does not match the sha256 in {mpath.name} (expected {side.get('sha256')}, "
                         f"got {digest}): corrupted or replaced file; train it again")
    _refuse_non_zip(path, blob)
    try:
        untrusted = sio.get_untrusted_types(data=blob)
    except Exception as exc:  # noqa: BLE001 - zipfile/json/KeyError: any unreadable archive
        raise InputError(f"model file {path} is corrupt or truncated ({type(exc).__name__}: {exc}); train it again "
                         f"with `orokit train`") from exc
    bad = [t for t in untrusted if not t.startswith(_TRUSTED_PREFIXES)]
    if bad:
        raise InputError(f"model {path} contains types that are not scikit-learn/numpy: {bad}; refusing to load")
    try:
        obj = sio.loads(blob, trusted=untrusted)
    except Exception as exc:  # noqa: BLE001 - skops raises many types on a damaged archive
        raise InputError(f"model file {path} is corrupt ({type(exc).__name__}: {exc}); train it again") from exc
    if not (isinstance(obj, dict) and "pipeline" in obj and isinstance(obj.get("metadata"), str)):
        raise SchemaError(f"model file {path} does not hold an orokit model (pipeline + metadata); train it again")
    try:
        md = json.loads(obj["metadata"])
    except json.JSONDecodeError as exc:
        raise SchemaError(f"model file {path}: stored metadata is not JSON ({exc}); train it again") from exc
    side_md = json.loads(_canonical({k: v for k, v in side.items() if k != "sha256"}))
    if side_md != md:
        keys = sorted(k for k in set(md) | set(side_md) if md.get(k) != side_md.get(k))
        raise SchemaError(f"model metadata {mpath} differs from the metadata stored in {path.name} (keys {keys}): "
                          f"the sidecar was edited; restore it or train the model again")
    return obj["pipeline"], md


def _json_default(o: Any) -> Any:
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.bool_):
        return bool(o)
    return str(o)


def write_feature_table(features: pd.DataFrame, path: PathLike) -> Path:
    """Write a feature table as Parquet (atomic), its ``attrs`` as JSON in the ``orokit`` schema metadata."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    table = pa.Table.from_pandas(features, preserve_index=False)
    md = dict(table.schema.metadata or {})
    md[b"orokit"] = json.dumps(features.attrs, default=_json_default).encode()
    table = table.replace_schema_metadata(md)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
    return path


def read_feature_table(path: PathLike) -> pd.DataFrame:
    """Read a feature table written by :func:`write_feature_table` (``attrs`` restored).

    The caller checks the columns against the recorded feature set
    (:func:`orokit.classify.features.check_feature_table`).
    """
    import pyarrow.parquet as pq

    path = Path(path)
    if not path.exists():
        raise InputError(f"feature table {path} does not exist; create it with `orokit features`")
    try:
        table = pq.read_table(path)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises several types
        raise InputError(f"cannot read feature table {path}: {exc}; create it with `orokit features`") from exc
    md = (table.schema.metadata or {}).get(b"orokit")
    if md is None:
        raise SchemaError(f"{path} has no orokit feature metadata; create it with `orokit features`")
    df = table.to_pandas()
    try:
        df.attrs = json.loads(md)
    except json.JSONDecodeError as exc:
        raise SchemaError(f"{path}: orokit feature metadata is not JSON ({exc})") from exc
    return df


def write_disk_map(disks: Any, path: PathLike) -> Path:
    """Write classified disk polygons (:func:`orokit.classify.predict.disk_map`) as a GeoPackage
    layer ``disks`` (atomic)."""
    path = Path(path)
    if path.suffix.lower() != ".gpkg":
        raise InputError(f"--map {path}: the disk map is a GeoPackage; give a file name ending in .gpkg")
    import warnings

    with atomic_path(path) as tmp, warnings.catch_warnings():
        if disks.crs is None:  # a DEM on a local grid: coordinates are metres of that grid, no CRS to record
            warnings.filterwarnings("ignore", message=".*'crs' was not provided.*")
        disks.to_file(tmp, layer="disks", driver="GPKG")
    return path
