"""Refinement of ridge and river segments to pieces shorter than lambda, with planar jitter."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from orokit._typing import SeedLike

__all__ = ["Polylines", "refine_segments", "densify"]


@dataclass(frozen=True)
class Polylines:
    """Vertices ``xy`` (k, 2) with elevation ``z`` (k,) and value ``a`` (k,), and
    ``segments`` (s, 2) of vertex ids. The first vertices are the original nodes."""

    xy: np.ndarray
    z: np.ndarray
    a: np.ndarray
    segments: np.ndarray
    origin: np.ndarray | None = None  # (s,) index of the input segment each piece comes from


def refine_segments(
    node_xy: np.ndarray,
    node_z: np.ndarray,
    seg: np.ndarray,
    *,
    lam: float,
    jitter: float = 0.25,
    node_a: np.ndarray | None = None,
    profile: Callable[[np.ndarray], np.ndarray] | None = None,
    segment_profile: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    rng: SeedLike = None,
) -> Polylines:
    """Split each segment ``seg[i] = (u, v)`` into pieces shorter than ``lam``.

    Interior points are displaced in the plane by a random vector of length at most
    ``jitter * piece length`` perpendicular to the segment; their elevation (and value
    ``a``) is interpolated along the original segment: linearly, or with weight
    ``profile(t)`` of the end node (t = 0 at ``u``, 1 at ``v``) for the elevation, or
    ``segment_profile(t, i)`` (``i`` the segment of each point; instead of ``profile``). End
    points (the original nodes) do not move.
    """
    rng = np.random.default_rng(rng)
    node_a = np.zeros(node_xy.shape[0]) if node_a is None else np.asarray(node_a, float)
    seg = np.asarray(seg, np.int64).reshape(-1, 2)
    p0, p1 = node_xy[seg[:, 0]], node_xy[seg[:, 1]]
    d = p1 - p0
    length = np.hypot(d[:, 0], d[:, 1])
    k = np.maximum(np.ceil(length / lam).astype(np.int64), 1)  # pieces per segment
    n_int = k - 1
    tot = int(n_int.sum())
    sid = np.repeat(np.arange(seg.shape[0]), n_int)
    first = np.cumsum(n_int) - n_int
    step = np.arange(tot) - np.repeat(first, n_int) + 1
    t = step / np.repeat(k, n_int)
    base = p0[sid] + t[:, None] * d[sid]
    normal = np.column_stack([-d[sid, 1], d[sid, 0]]) / np.maximum(length[sid], 1e-12)[:, None]
    piece = (length / k)[sid]
    base = base + normal * (rng.uniform(-jitter, jitter, tot) * piece)[:, None]
    if segment_profile is not None:
        wz = np.asarray(segment_profile(t, sid), dtype=np.float64)
    else:
        wz = t if profile is None else np.asarray(profile(t), dtype=np.float64)
    z = node_z[seg[sid, 0]] + wz * (node_z[seg[sid, 1]] - node_z[seg[sid, 0]])
    a = node_a[seg[sid, 0]] + t * (node_a[seg[sid, 1]] - node_a[seg[sid, 0]])
    n0 = node_xy.shape[0]
    ids = n0 + np.arange(tot)
    # chain: start, interior..., end for every segment
    chain_start = np.repeat(seg[:, 0], 1)
    segs = []
    # first piece of each segment
    first_to = np.where(n_int > 0, n0 + first, seg[:, 1])
    segs.append(np.column_stack([chain_start, first_to]))
    # interior pieces
    if tot:
        last_of = np.zeros(tot, bool)
        last_of[(first + n_int - 1)[n_int > 0]] = True
        nxt = np.where(last_of, seg[sid, 1], ids + 1)
        segs.append(np.column_stack([ids, nxt]))
    return Polylines(
        xy=np.concatenate([node_xy, base]),
        z=np.concatenate([node_z, z]),
        a=np.concatenate([node_a, a]),
        segments=np.concatenate(segs).astype(np.int64),
        origin=np.concatenate([np.arange(seg.shape[0]), sid]).astype(np.int64),
    )


def densify(lines: Polylines, spacing: float, *, value: str = "a", origin: bool = False):
    """Points every ``<= spacing`` along all segments: ``(xy, z, v)``.

    ``v`` is the interpolated value ``a`` (``value="a"``) or the absolute slope
    ``|dz/ds|`` of the segment each point lies on (``value="slope"``). With
    ``origin=True`` a fourth array gives each point's input segment (-1 for the
    appended vertices).
    """
    s = lines.segments
    p0, p1 = lines.xy[s[:, 0]], lines.xy[s[:, 1]]
    length = np.hypot(*(p1 - p0).T)
    k = np.maximum(np.ceil(length / spacing).astype(np.int64), 1)
    sid = np.repeat(np.arange(s.shape[0]), k)
    first = np.cumsum(k) - k
    t = (np.arange(int(k.sum())) - np.repeat(first, k)) / np.repeat(k, k)
    xy = p0[sid] + t[:, None] * (p1 - p0)[sid]
    z = lines.z[s[sid, 0]] + t * (lines.z[s[sid, 1]] - lines.z[s[sid, 0]])
    if value == "slope":
        seg_slope = np.abs(lines.z[s[:, 1]] - lines.z[s[:, 0]]) / np.maximum(length, 1e-9)
        a = seg_slope[sid]
        node_v = np.zeros(lines.xy.shape[0])
        np.maximum.at(node_v, s[:, 0], seg_slope)
        np.maximum.at(node_v, s[:, 1], seg_slope)
    else:
        a = lines.a[s[sid, 0]] + t * (lines.a[s[sid, 1]] - lines.a[s[sid, 0]])
        node_v = lines.a
    # the end vertices of every segment
    xy = np.concatenate([xy, lines.xy])
    z = np.concatenate([z, lines.z])
    a = np.concatenate([a, node_v])
    if origin:
        src = lines.origin if lines.origin is not None else np.arange(s.shape[0])
        return xy, z, a, np.concatenate([src[sid], np.full(lines.xy.shape[0], -1, np.int64)])
    return xy, z, a
