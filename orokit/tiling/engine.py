"""Out-of-core / distributed orometry with dask.

The raster is read chunk by chunk (each with a one-cell halo); every chunk becomes a
:class:`~orokit.tiling.summary.ChunkSummary`, and summaries are merged by a tree
reduction that halves the longer side of the chunk grid at each level, so a task
holds at most two summaries (side cells + kept peaks), never the raster. The same
graph runs on the threaded scheduler or a ``dask.distributed`` cluster.

Chunk summaries can be written to a checkpoint folder (one ``.npz`` per chunk,
written atomically); a rerun with the same folder reuses the finished chunks.
"""
from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from orokit.errors import TilingError
from orokit.io.checkpoint_io import chunk_path, discard_chunk, open_checkpoint, read_chunk, write_chunk
from orokit.io.spill_io import SpillFolder, read_spill, remove_stale_folders, take_spill, write_spill
from orokit.tiling.isolation import SettledIsolation, block_stats, chunk_isolation
from orokit.tiling.memory import release_free_heap
from orokit.tiling.summary import ChunkSummary, chunk_summary, finalize_summary, merge_summaries
from orokit.topology.engine import Orometry

logger = logging.getLogger(__name__)

__all__ = ["tiled_orometry", "get_compute", "TiledOrometry"]


@dataclass(frozen=True)
class TiledOrometry:
    """Output of :func:`tiled_orometry`.

    Attributes
    ----------
    orometry : the exact engine output, equal to the in-memory engine's.
    chunk_stats : (chunk rows, chunk cols, 2) array: maximum of each chunk (-inf if
        empty) and 1.0 if it holds a NaN; the isolation search skips chunks with it.
    chunk_isolation : isolation settled inside the chunks (arrays ``key``, ``best``,
        ``cand``, ``nan``): a dict when carried up the merges, a
        :class:`~orokit.tiling.isolation.SettledIsolation` of the chunks' spill files when spilled
        (the files stay until it is closed or let go), or None without an isolation metric.
    """

    orometry: Orometry
    chunk_stats: np.ndarray
    chunk_isolation: dict | SettledIsolation | None


def get_compute(scheduler: Any = None):
    """A function computing a list of dask objects on ``scheduler``.

    ``scheduler`` is None (dask's default: threads, or the active distributed client),
    a scheduler name ("threads", "processes", "synchronous"), a
    ``distributed.Client``, or the address of a distributed scheduler.
    """
    import dask

    if scheduler is None or scheduler in ("threads", "threading", "processes", "synchronous", "sync"):
        return lambda objs: dask.compute(*objs, scheduler=scheduler)
    if isinstance(scheduler, str):
        from distributed import Client

        client = Client(scheduler)
    else:
        client = scheduler
    return lambda objs: client.compute(list(objs), sync=True)


_ISO_FIELDS = ("key", "best", "cand", "nan")


class _Window:
    """One chunk and its one-cell halo, as a small dask array read inside its own task.

    It is opaque to the outer graph (dask does not look inside it), so no chunk task
    shares a source block with another: each reads its core and the eight thin halo
    strips (dask fuses the slices into the source's reads) and frees them when done,
    instead of every source block waiting in memory for its neighbours' halos.
    """

    def __init__(self, data, r0: int, r1: int, c0: int, c1: int):
        from orokit.io.dem import window_source

        H, W = data.shape
        self.pad = ((int(r0 == 0), int(r1 == H)), (int(c0 == 0), int(c1 == W)))
        self.box = (slice(max(r0 - 1, 0), min(r1 + 1, H)), slice(max(c0 - 1, 0), min(c1 + 1, W)))
        # a raster read_dem opened: the window straight from its file (a slice of the dask array costs
        # O(chunks) graph work per window: ~10 ms per chunk at 2500 chunks, session 17)
        self.source = window_source(data)
        self.array: Any = data[self.box] if self.source is None else None

    def read(self) -> np.ndarray:
        """The window with NaN outside the raster: float32 when stored so (the kernels order
        float32 values exactly as their float64 copies, at half the memory), else float64."""
        if self.source is not None:
            block = np.asarray(self.source[self.box])
        else:
            block = np.asarray(self.array.compute(scheduler="sync"))
        if block.dtype != np.float32:
            block = block.astype(np.float64)
        return np.pad(block, self.pad, constant_values=np.nan) if any(sum(self.pad, ())) else block


#: a task's output: (summary, settled isolation or None, {(i, j): (chunk maximum, has NaN)})
_Part = tuple


def _load_summary(path: str) -> tuple[ChunkSummary, dict | None]:
    data = read_chunk(path)
    iso = {f: data[f"iso_{f}"] for f in _ISO_FIELDS} if "iso_key" in data else None
    return ChunkSummary.from_npz(data), iso


def _load_task(path: str, window: _Window, ij: tuple[int, int], spill: str | None = None) -> _Part:
    data = read_chunk(path)
    iso = {f: data[f"iso_{f}"] for f in _ISO_FIELDS} if "iso_key" in data else None
    if "stats" in data:
        stats = (float(data["stats"][0]), float(data["stats"][1]))
    else:  # written before the statistics were stored: read the chunk once more
        stats = block_stats(window.read()[1:-1, 1:-1])
    return ChunkSummary.from_npz(data), _spill_iso(iso, spill), {ij: stats}


def _spill_iso(iso: dict | None, spill: str | None) -> dict | None:
    """``iso`` written to the spill file ``spill`` (then None: it does not travel with the summaries)."""
    if iso is None or spill is None:
        return iso
    write_spill(spill, iso)
    return None


def _spilled_isolation(spills: dict[tuple[int, int], str], rb: np.ndarray, owner: SpillFolder) -> SettledIsolation:
    """The settled isolation left in the chunks' spill files ``spills`` ((i, j): path), by rows of chunks
    (``rb``: row edges); the folder ``owner`` is removed when the source is closed or let go."""
    nby = len(rb) - 1
    rows_of: list[list[str]] = [[] for _ in range(nby)]
    for (i, _j), path in sorted(spills.items()):
        if Path(path).exists():  # a reused chunk of an old checkpoint may have none
            rows_of[i].append(path)

    def read(band: int, names: tuple[str, ...] | None) -> dict:
        parts = [read_spill(path, names) for path in rows_of[band]]
        if not parts:
            empty = {"key": np.empty(0, np.int64), "best": np.empty(0), "nan": np.empty(0),
                     "cand": np.empty((0, 0), np.int64)}
            return {f: empty[f] for f in (names or _ISO_FIELDS)}
        out = _merge_iso(parts)
        assert out is not None  # parts is not empty
        return out

    def close() -> None:
        rows_of.clear()
        owner.close()
    return SettledIsolation([(int(rb[i]), int(rb[i + 1])) for i in range(nby)], read, close)


def _corrupt_chunk(path: str) -> bool:
    """True (with a warning, and the file removed) when a checkpoint chunk cannot be used."""
    try:
        _load_summary(path)
        return False
    except (TilingError, KeyError, ValueError, TypeError, IndexError) as exc:
        discard_chunk(path, exc)
        return True


def _tile_task(window: _Window, ij: tuple[int, int], row0: int, col0: int, shape, min_prominence_m: float,
               path: str | None, metric, spill: str | None = None) -> _Part:
    block = window.read()
    summary = chunk_summary(block, row0, col0, shape, min_prominence_m)
    core = np.ascontiguousarray(block[1:-1, 1:-1])  # made after the summary: one raster copy alive at a time
    del block
    stats = block_stats(core)
    iso = None
    if metric is not None:
        iso = chunk_isolation(core, row0, col0, shape, summary.key[summary.ismax], metric)
    if path is not None:
        extra = {} if iso is None else {f"iso_{f}": v for f, v in iso.items()}
        write_chunk(path, {**summary.to_npz(), **extra, "stats": np.array(stats, np.float64)})
    del core
    iso = _spill_iso(iso, spill)
    release_free_heap()  # the chunk's arrays: the heap keeps them otherwise (glibc: up to 32 MB each)
    return summary, iso, {ij: stats}


def _merge_iso(parts: list, keep: np.ndarray | None = None) -> dict | None:
    """Settled isolation of several parts in one (the fields of the first), only for the peaks in ``keep``
    (global cells).
    The parts' dicts are emptied (their owner, a merge, passes them on)."""
    parts = [p for p in parts if p is not None]
    if not parts:
        return None
    width = max(p["cand"].shape[1] for p in parts) if "cand" in parts[0] else 0
    out = {}
    for f in [f for f in _ISO_FIELDS if f in parts[0]]:  # one field at a time, each part's field freed once joined
        if f == "cand":
            out[f] = np.concatenate([np.pad(p[f], ((0, 0), (0, width - p[f].shape[1])), constant_values=-1)
                                     for p in parts])
        else:
            out[f] = np.concatenate([p[f] for p in parts])
        for p in parts:
            del p[f]
    if keep is not None:
        sel = np.isin(out["key"], keep)
        out = {f: v[sel] for f, v in out.items()}
    return out


@dataclass(frozen=True)
class _SpilledSummary:
    """A merge's summary written to the spill file ``path`` (:func:`_merge_task`): its consumer reads it
    back and removes the file."""

    path: str


def _summary_of(part: _Part) -> ChunkSummary:
    """The summary of a task's output, read back (and its file removed) when it was spilled."""
    s = part[0]
    if not isinstance(s, _SpilledSummary):
        return s
    data = take_spill(s.path)
    out = ChunkSummary.from_npz(data)
    del data
    return out


def _merge_task(a: _Part, b: _Part, min_prominence_m: float, reduce: bool = True, spill: str | None = None) -> _Part:
    """Merged summary of two parts; settled isolation kept only for peaks still in it.

    The inputs are consumed (their arrays freed once merged): the scheduler holds them
    until this task ends, and each part has this merge as its only consumer. ``reduce=False``
    (the root merge): the merged graph is not contracted, the finalize does that. ``spill`` (a
    path; the settled isolation is spilled, so none travels): the merged summary is written there and
    its consumer reads it back (:func:`_summary_of`), so a top merge's output does not wait in memory
    while its sibling's half of the raster is summarised (at a 4 G-cell mosaic's root: half the root,
    ~200 MB, through half of the chunk pass, then a quarter through a quarter...).
    """
    s = merge_summaries(_summary_of(a), _summary_of(b), min_prominence_m, consume=True, reduce=reduce)
    iso = None if a[1] is None and b[1] is None else _merge_iso([a[1], b[1]], keep=s.key[s.ismax])
    out: ChunkSummary | _SpilledSummary = s
    if spill is not None and iso is None:
        write_spill(spill, s.to_npz())
        s.release()
        out = _SpilledSummary(spill)
    del s
    release_free_heap()
    return out, iso, {**a[2], **b[2]}


def _finalize_task(root: _Part, min_prominence_m: float, outside: str, nby: int, nbx: int,
                   store: Any = None) -> tuple:
    s, iso = _summary_of(root), root[1]
    logger.info("root summary: %d nodes (%d candidate peaks), %d edges, %.1f MB; settled isolation: %d peaks, %.1f MB",
                s.n_nodes, int(s.ismax.sum()), s.ea.size, s.nbytes() / 2**20,
                0 if iso is None else iso["key"].size, 0 if iso is None else sum(v.nbytes for v in iso.values()) / 2**20)
    stats = np.array([[root[2][i, j] for j in range(nbx)] for i in range(nby)], dtype=float)
    s.nexit = np.empty(0, s.nexit.dtype)  # not used by the finalize (a view [:0] would keep it alive)
    iso = root[1]
    del root  # the root summary is released by the finalize as it goes (dask holds its tuple till the end)
    return (finalize_summary(s, min_prominence_m=min_prominence_m, outside=outside, consume=True, store=store),
            iso, stats)


def _checkpoint_dir(checkpoint, data, min_prominence_m: float) -> Path | None:
    if checkpoint is None:
        return None
    fingerprint = {
        "shape": list(data.shape),
        "chunks": [list(c) for c in data.chunks],
        "min_prominence_m": float(min_prominence_m),
        "graph": data.name,  # dask name: a hash of the source and its processing
        "format": 2,  # 2: exit nodes (nexit) in the summaries
    }
    return open_checkpoint(checkpoint, fingerprint)


def spill_parent(checkpoint) -> str | None:
    """Where a run's spill folder goes: the checkpoint folder, dask's temporary-directory, or None (TMPDIR)."""
    if checkpoint is not None:
        return str(checkpoint)
    import dask

    return dask.config.get("temporary-directory", default=None) or None


def _same_disk(scheduler: Any) -> bool:
    """True when every task of ``scheduler`` runs on this machine (threads, processes, or dask's
    default without an active distributed client), so tasks can leave files for the caller."""
    if scheduler is None:
        import sys

        if "distributed" in sys.modules:
            from distributed import default_client

            try:
                default_client()
            except ValueError:
                return True
            return False
        return True
    return scheduler in ("threads", "threading", "processes", "synchronous", "sync")


def in_process(scheduler: Any) -> bool:
    """True when every task of ``scheduler`` runs in this process (threads, synchronous, or dask's
    default without an active distributed client), so a task can fill an object of the caller.

    ``None`` is dask's default, which a configured scheduler replaces (``dask.config.set(scheduler=...)``,
    ``DASK_SCHEDULER=processes``): only a configured thread or synchronous scheduler counts.
    """
    if scheduler is None:
        import dask

        configured = dask.config.get("scheduler", None)
        if configured is not None:
            return isinstance(configured, str) and configured in _IN_PROCESS
        return _same_disk(None)
    return scheduler in _IN_PROCESS


#: scheduler names whose tasks run in the caller's process
_IN_PROCESS = ("threads", "threading", "synchronous", "sync")


def tiled_orometry(data, *, min_prominence_m: float, outside: str = "unknown", scheduler: Any = None,
                   checkpoint=None, progress: bool = False, isolation_metric=None,
                   store: Any = None) -> TiledOrometry:
    """Exact orometry of a 2-D dask array (NaN = nodata), chunk by chunk.

    ``result.orometry`` is exactly the :class:`~orokit.topology.engine.Orometry` of the
    in-memory engine (same peaks, prominences, key saddles, parents, flags and ridge
    saddles). With ``isolation_metric`` (a :class:`~orokit.metrics.isolation.KernelMetric`),
    each chunk also settles the isolation of its candidate peaks whose higher ground lies
    inside it (``result.chunk_isolation``), so the cross-chunk search reads few chunks.
    On a scheduler whose tasks run on this machine, each chunk's settled isolation is
    spilled to a temporary file instead of travelling up the merges with the summaries
    (~50 bytes per candidate peak alive through the top merges and the finalize), and left
    there: ``result.chunk_isolation`` reads it by rows of chunks (the isolation search holds one
    row's at a time, ~40 bytes per settled peak otherwise), and removes the files when it is
    closed or let go. The spill folder goes in the
    ``checkpoint`` folder when one is given, else in dask's ``temporary-directory`` if set, else in
    ``TMPDIR`` (on a RAM-backed ``TMPDIR`` the spills take memory that the RSS does not show).
    The spill and column folders that a killed run left in the ``checkpoint`` folder are removed
    first (:func:`~orokit.io.spill_io.remove_stale_folders`); its finished chunks are reused.
    ``store`` (a column store; only with a scheduler whose tasks run in this process,
    :func:`in_process`): the finalize puts the result's columns that the isolation search does not
    read there as it makes them (:data:`~orokit.topology.engine.SPILLED_OROMETRY`; ``orometry`` keeps
    empty arrays of their types).
    """
    if store is not None and not in_process(scheduler):
        raise TilingError("a column store needs a scheduler running in this process (threads or synchronous)")
    if checkpoint is not None:  # a killed run's temporary folders (its finished chunks are reused)
        remove_stale_folders(checkpoint)
    spill = None
    if isolation_metric is not None and _same_disk(scheduler):
        spill = SpillFolder(parent=spill_parent(checkpoint))
    try:
        return _tiled_orometry(data, min_prominence_m=min_prominence_m, outside=outside, scheduler=scheduler,
                               checkpoint=checkpoint, progress=progress, isolation_metric=isolation_metric,
                               spill=spill, store=store)
    except BaseException:
        if spill is not None:
            spill.close()
        raise


def _tiled_orometry(data, *, min_prominence_m: float, outside: str, scheduler: Any, checkpoint, progress: bool,
                    isolation_metric, spill: SpillFolder | None, store: Any = None) -> TiledOrometry:
    import dask

    if data.ndim != 2:
        raise TilingError(f"expected a 2-D array, got shape {data.shape}")
    if not np.issubdtype(data.dtype, np.floating):
        data = data.astype(np.float64)
    H, W = data.shape
    rb = np.concatenate([[0], np.cumsum(data.chunks[0])]).astype(int)
    cb = np.concatenate([[0], np.cumsum(data.chunks[1])]).astype(int)
    nby, nbx = len(rb) - 1, len(cb) - 1
    ckpt = _checkpoint_dir(checkpoint, data, min_prominence_m)
    tiles = {}
    reused = 0
    spills = {} if spill is None else {(i, j): str(spill.path / f"iso_{i:05d}_{j:05d}.npz")
                                       for i in range(nby) for j in range(nbx)}
    for i in range(nby):
        for j in range(nbx):
            path = None if ckpt is None else str(chunk_path(ckpt, i, j))
            window = _Window(data, int(rb[i]), int(rb[i + 1]), int(cb[j]), int(cb[j + 1]))
            sp = spills.get((i, j))
            if path is not None and Path(path).exists() and not _corrupt_chunk(path):
                tiles[i, j] = dask.delayed(_load_task)(path, window, (i, j), sp,
                                                       dask_key_name=f"orokit-load-{i}-{j}-{_h(path)}-{sp is None}")
                reused += 1
            else:
                tiles[i, j] = dask.delayed(_tile_task)(
                    window, (i, j), int(rb[i]), int(cb[j]), (H, W), float(min_prominence_m), path, isolation_metric,
                    sp,
                    dask_key_name=(f"orokit-tile-{i}-{j}-{data.name}-{min_prominence_m}-{isolation_metric is not None}"
                                   f"-{sp is None}"),
                )
    if reused:
        logger.info("reusing %d chunk summaries from %s", reused, ckpt)

    # the folder's path, not the folder: ``reduce`` below is recursive, a cycle that would keep the folder (removed
    # when let go) alive until the garbage collector runs
    spill_dir = None if spill is None else spill.path

    # one tree: every chunk's output is consumed by exactly one merge, so the scheduler
    # frees each pair as soon as it is merged (a depth-first order holds about log2(chunks)
    # summaries); settled isolation and chunk statistics travel up with the summaries
    def reduce(i0, i1, j0, j1):
        root = (i0, i1, j0, j1) == (0, nby, 0, nbx)
        if i1 - i0 == 1 and j1 - j0 == 1:
            return tiles[i0, j0]
        if i1 - i0 >= j1 - j0:
            m = (i0 + i1) // 2
            a, b = reduce(i0, m, j0, j1), reduce(m, i1, j0, j1)
        else:
            m = (j0 + j1) // 2
            a, b = reduce(i0, i1, j0, m), reduce(i0, i1, m, j1)
        # the root merge is not reduced: the finalize sorts, sweeps and prunes its graph once; the merges of
        # an eighth of the raster or more spill their output (it may wait for its sibling's half of the raster)
        big = not root and 8 * (rb[i1] - rb[i0]) * (cb[j1] - cb[j0]) >= H * W
        return dask.delayed(_merge_task)(
            a, b, float(min_prominence_m), reduce=not root,
            spill=str(spill_dir / f"summary_{i0}_{i1}_{j0}_{j1}.npz") if big and spill_dir is not None else None,
            dask_key_name=f"orokit-merge-{i0}-{i1}-{j0}-{j1}-{data.name}"
        )

    root = reduce(0, nby, 0, nbx)
    final = dask.delayed(_finalize_task)(root, float(min_prominence_m), outside, nby, nbx, store,
                                         dask_key_name=f"orokit-final-{data.name}-{min_prominence_m}-{outside}"
                                                       f"-{store is None}")
    compute = get_compute(scheduler)
    logger.info("tiled analysis of %dx%d cells in %d chunks", H, W, nby * nbx)
    if progress and (scheduler is None or isinstance(scheduler, str) and "://" not in scheduler):
        from dask.diagnostics import ProgressBar

        with ProgressBar():
            ((result, iso, st),) = compute([final])
    else:
        ((result, iso, st),) = compute([final])
    if spill is not None:  # the merges carried no settled isolation: the search reads the files by rows of chunks
        iso = _spilled_isolation(spills, rb, spill)
        logger.info("settled isolation left in %d spill files, %.1f MB", len(spills),
                    sum(Path(p).stat().st_size for p in spills.values() if Path(p).exists()) / 2**20)
    release_free_heap()  # the chunks' and merges' arrays, freed inside the heap
    return TiledOrometry(orometry=result, chunk_stats=st, chunk_isolation=iso)


def _h(text: str) -> str:
    return hashlib.sha1(text.encode()).hexdigest()[:10]
