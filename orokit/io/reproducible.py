"""Byte-reproducible outputs: the same inputs and seed give the same committed files.

- :func:`canonical_skops` rewrites a skops archive so that its bytes depend only on the
  model: skops names array files and memo ids after ``id(obj)`` (memory addresses) and
  stamps zip entries with the current time; both are replaced by canonical values.
(:func:`orokit.data.portable_path` records paths without the machine's prefix.)
"""
from __future__ import annotations

import io
import json
import zipfile
from typing import Any


__all__ = ["canonical_skops"]

#: the zip timestamp of every entry (the earliest a zip file can hold)
ZIP_EPOCH = (1980, 1, 1, 0, 0, 0)


def _collect_ids(node: Any, order: dict[int, int]) -> None:
    if isinstance(node, dict):
        ident = node.get("__id__")
        if isinstance(ident, int) and not isinstance(ident, bool) and ident not in order:
            order[ident] = len(order) + 1
        for value in node.values():
            _collect_ids(value, order)
    elif isinstance(node, list):
        for value in node:
            _collect_ids(value, order)


def _renumber(node: Any, order: dict[int, int]) -> Any:
    if isinstance(node, dict):
        out: dict[str, Any] = {}
        for key, value in node.items():
            if key == "__id__" and isinstance(value, int) and value in order:
                out[key] = order[value]
            elif key == "file" and isinstance(value, str):
                stem, dot, ext = value.partition(".")
                out[key] = f"{order[int(stem)]}{dot}{ext}" if stem.isdigit() and int(stem) in order else value
            else:
                out[key] = _renumber(value, order)
        return out
    if isinstance(node, list):
        return [_renumber(v, order) for v in node]
    return node


def canonical_skops(blob: bytes) -> bytes:
    """The skops archive ``blob`` with canonical ids, file names, entry order and timestamps.

    Ids are renumbered 1, 2, ... in the order they first appear in ``schema.json`` (a
    deterministic walk of the model), array files renamed to match, entries written
    schema first then by name, all dated :data:`ZIP_EPOCH`. ``skops.io.loads`` reads the
    result like the original.
    """
    src = zipfile.ZipFile(io.BytesIO(blob))
    schema = json.loads(src.read("schema.json"))
    order: dict[int, int] = {}
    _collect_ids(schema, order)
    renamed = {}
    for info in src.infolist():
        stem, dot, ext = info.filename.partition(".")
        new = f"{order[int(stem)]}{dot}{ext}" if stem.isdigit() and int(stem) in order else info.filename
        renamed[new] = info
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as dst:
        names = sorted(renamed, key=lambda n: (n != "schema.json", len(n), n))
        for name in names:
            info = renamed[name]
            data = (json.dumps(_renumber(schema, order), indent=2).encode() if name == "schema.json"
                    else src.read(info.filename))
            entry = zipfile.ZipInfo(name, date_time=ZIP_EPOCH)
            entry.compress_type = info.compress_type
            entry.external_attr = info.external_attr
            dst.writestr(entry, data)
    return out.getvalue()
