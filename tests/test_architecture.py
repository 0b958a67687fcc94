"""Shape of the package, checked on its source (AST; nothing is imported).

1. Imports go one way: the module import graph of ``orokit`` (imports inside
   functions included) has no cycle.
2. Only the shells open files: ``orokit/io``, ``orokit/cli`` and ``orokit/reports``
   (``orokit/data`` only re-exports the dataset manifest and fetching of ``orokit/io``). Modules of
   the algorithm packages that still do are listed in ``KNOWN_FILE_ACCESS`` with the
   issue that moves their IO; an entry that no longer opens files fails the test, so
   the list only shrinks.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "orokit"

#: packages allowed to touch files
SHELLS = ("io", "cli", "reports")

#: calls that open, read, write or remove files (attribute names; plus the builtin open)
FILE_CALLS = {
    "to_file", "to_parquet", "to_csv", "to_raster", "to_netcdf", "to_zarr", "savefig",
    "write_text", "read_text", "write_bytes", "read_bytes", "mkdir", "unlink", "rmdir",
    "savez", "savez_compressed", "read_parquet", "read_file", "read_csv", "open_rasterio", "open_dataset",
}
#: generic method names that open files only on these modules (``np.load``, ``rasterio.open``...)
GENERIC_CALLS = {"open", "load", "save", "dump"}
FILE_MODULES = {"np", "numpy", "json", "pickle", "joblib", "rasterio", "Image", "gzip", "zipfile", "tarfile",
                "shutil", "skops", "sio", "yaml", "os"}

#: algorithm modules that still open files, and who moves that IO to orokit/io
KNOWN_FILE_ACCESS = {
}


def _modules() -> dict[str, Path]:
    out = {}
    for p in PKG.rglob("*.py"):
        parts = list(p.relative_to(PKG.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    is_pkg = path.name == "__init__.py"
    targets: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_pkg else name.split(".")[:-1]
                base = base[: len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets.add(mod)
            targets.update(f"{mod}.{a.name}" for a in node.names)
    resolved = set()
    for t in targets:
        while t and t not in known:
            t = t.rpartition(".")[0]
        if t and t != name:
            resolved.add(t)
    return resolved


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of a directed graph (list of nodes), or None (iterative DFS)."""
    state: dict[str, int] = {}
    for start in sorted(graph):
        if state.get(start):
            continue
        stack = [(start, iter(sorted(graph[start])))]
        path = [start]
        state[start] = 1
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                state[node] = 2
                stack.pop()
                path.pop()
            elif state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            elif not state.get(nxt):
                state[nxt] = 1
                stack.append((nxt, iter(sorted(graph[nxt]))))
                path.append(nxt)
    return None


def test_cycle_finder_finds_a_cycle():
    assert _find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert _find_cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None


def test_no_import_cycle():
    mods = _modules()
    graph = {m: _imports(m, p, set(mods)) for m, p in mods.items()}
    assert sum(map(len, graph.values())) > 100  # the graph was really read
    assert graph["orokit.analysis"] >= {"orokit.topology.tables", "orokit.topology.engine"}
    cycle = _find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_no_package_cycle():
    """Also between sub-packages (orokit.io, orokit.synthesis, ...): io never imports an algorithm package."""
    mods = _modules()
    graph: dict[str, set[str]] = {}
    for m, p in mods.items():
        top = ".".join(m.split(".")[:2])
        targets = {".".join(t.split(".")[:2]) for t in _imports(m, p, set(mods))}
        graph.setdefault(top, set()).update(targets - {top, "orokit"})
    cycle = _find_cycle(graph)
    assert cycle is None, "package import cycle: " + " -> ".join(cycle or [])


def _file_calls(path: Path) -> list[str]:
    hits = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        if isinstance(f, ast.Name):
            hit = f.id == "open"
        elif isinstance(f, ast.Attribute):
            hit = f.attr in FILE_CALLS or (
                f.attr in GENERIC_CALLS and isinstance(f.value, ast.Name) and f.value.id in FILE_MODULES)
        else:
            hit = False
        if hit:
            hits.append(f"{path.name}:{node.lineno}: {ast.unparse(f)}")
    return hits


def test_file_call_detector(tmp_path):
    assert _file_calls(PKG / "io" / "analysis_io.py")  # the writers are seen
    src = tmp_path / "m.py"
    src.write_text("import numpy as np\nnp.load('a')\nopen('b')\nspec.load()\nframe.to_csv('c')\n")
    assert [h.split(": ")[1] for h in _file_calls(src)] == ["np.load", "open", "frame.to_csv"]


ALGORITHM_MODULES = sorted(p for p in PKG.rglob("*.py") if p.relative_to(PKG).parts[0] not in SHELLS)


@pytest.mark.parametrize("path", ALGORITHM_MODULES, ids=lambda p: str(p.relative_to(PKG)))
def test_only_shells_open_files(path: Path):
    hits = _file_calls(path)
    key = path.relative_to(PKG).as_posix()
    if key in KNOWN_FILE_ACCESS:
        assert hits, f"{key} no longer opens files: remove it from KNOWN_FILE_ACCESS"
    else:
        assert not hits, f"only {SHELLS} may open files; move this IO to orokit/io: {hits}"
