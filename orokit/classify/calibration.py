"""Calibrated class probabilities and the open-set "unknown" answer of the region classifier.

A forest's class probabilities (the share of its trees' leaves) are not calibrated: on
ground it has not seen, a disk given 0.5 is not right half of the time. Temperature
scaling fixes that with one number ``T``: ``q = softmax(log(p) / T)`` (``p`` floored at
:data:`FLOOR` and renormalised). ``T`` is fitted by minimising the log-loss of held-out
predictions, here those of the spatial hold-out (disks more than 2 R from every
training disk), never of disks the forest saw. ``T`` is the same for every class, so
it never changes which class is the most probable one, on a disk or summed over disks.

The terrain-level posterior (the disks' summed log-probabilities) treats overlapping
disks as independent and is overconfident; it gets its own temperature, fitted the
same way on the held-out strips' terrain answers.

An input is answered "unknown" when its best class is not confident enough: a disk when
its calibrated top probability is below ``disk_threshold``, a whole input when the mean
calibrated probability of its best class over its disks is below ``terrain_threshold``.
Both thresholds keep a share (95 %) of the right answers on the held-out ground
(:func:`keep_threshold`); they are never tuned on regions the model does not know.

Everything here is pure array code: no files, no estimators.

Examples
--------
>>> import numpy as np
>>> p = np.array([[0.6, 0.4], [0.6, 0.4]])
>>> np.round(temper(p, 0.5), 3)  # T < 1 sharpens, T > 1 flattens
array([[0.692, 0.308],
       [0.692, 0.308]])
"""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FLOOR", "Calibration", "log_proba", "softmax", "temper", "fit_temperature", "calibration_scores", "reliability",
           "keep_threshold", "terrain_answers", "fit_calibration"]

#: probabilities are floored here before taking logs, so one disk cannot veto a class
FLOOR = 1e-3


def log_proba(proba: ArrayLike, *, floor: float = FLOOR) -> NDArray[np.float64]:
    """Log of the probabilities, floored at ``floor`` and renormalised (rows sum to 1)."""
    p = np.clip(np.asarray(proba, dtype=float), floor, 1.0)
    p /= p.sum(axis=-1, keepdims=True)
    return np.log(p)


def softmax(z: NDArray[np.float64]) -> NDArray[np.float64]:
    z = z - z.max(axis=-1, keepdims=True)
    e = np.exp(z)
    return np.asarray(e / e.sum(axis=-1, keepdims=True), dtype=float)


def temper(proba: ArrayLike, temperature: float, *, floor: float = FLOOR) -> NDArray[np.float64]:
    """Temperature-scaled probabilities ``softmax(log(p) / T)`` (``p`` floored, see :func:`log_proba`)."""
    if not temperature > 0:
        raise ValueError(f"temperature must be > 0, got {temperature!r}")
    return softmax(log_proba(proba, floor=floor) / float(temperature))


def _nll_of_logits(logits: NDArray[np.float64], true_index: NDArray[np.int64], temperature: float) -> float:
    z = logits / temperature
    z = z - z.max(axis=1, keepdims=True)
    lse = np.log(np.exp(z).sum(axis=1))
    return float(np.mean(lse - z[np.arange(len(z)), true_index]))


def fit_temperature(logits: ArrayLike, true_index: ArrayLike, *, bounds: tuple[float, float] = (0.02, 50.0)) -> float:
    """Temperature minimising the mean log-loss of ``softmax(logits / T)`` for the true classes.

    ``logits`` are log-probabilities (:func:`log_proba`) or summed log-probabilities of
    terrain answers; ``true_index`` the column of the true class of each row. The
    search is bounded to ``bounds`` (in ``T``). Without rows, returns 1 (no change).
    """
    from scipy.optimize import minimize_scalar

    z = np.asarray(logits, dtype=float)
    t = np.asarray(true_index, dtype=np.int64)
    if z.ndim != 2 or len(z) != len(t):
        raise ValueError(f"logits must be (n, classes) with one true index per row, got {z.shape} and {t.shape}")
    if len(z) == 0:
        return 1.0
    lo, hi = np.log(bounds[0]), np.log(bounds[1])
    res = minimize_scalar(lambda lt: _nll_of_logits(z, t, float(np.exp(lt))), bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-5})
    return float(np.exp(res.x))


def keep_threshold(confidences: ArrayLike, *, keep: float = 0.95) -> float:
    """The ``1 - keep`` quantile of ``confidences`` (those of right answers), so a share ``keep``
    of them stays at or above it; 0 without any."""
    c = np.asarray(confidences, dtype=float)
    c = c[np.isfinite(c)]
    return float(np.quantile(c, 1.0 - keep)) if len(c) else 0.0


def calibration_scores(proba: ArrayLike, true_index: ArrayLike, *, n_bins: int = 10) -> dict[str, float]:
    """Accuracy, mean log-loss, Brier score (multi-class: summed squared error per row) and the
    expected calibration error of the top class (``n_bins`` equal-width confidence bins)."""
    p = np.asarray(proba, dtype=float)
    t = np.asarray(true_index, dtype=np.int64)
    if len(p) == 0:
        return {"n": 0, "accuracy": float("nan"), "log_loss": float("nan"), "brier": float("nan"),
                "ece": float("nan")}
    onehot = np.zeros_like(p)
    onehot[np.arange(len(p)), t] = 1.0
    rel = reliability(p, t, n_bins=n_bins)
    n = rel["n"]
    filled = n > 0
    ece = float(np.sum(n[filled] * np.abs(rel["accuracy"][filled] - rel["confidence"][filled])) / len(p))
    return {"n": int(len(p)), "accuracy": float(np.mean(np.argmax(p, axis=1) == t)),
            "log_loss": float(-np.mean(np.log(np.clip(p[np.arange(len(p)), t], 1e-15, 1.0)))),
            "brier": float(np.mean(np.sum((p - onehot) ** 2, axis=1))), "ece": ece}


def reliability(proba: ArrayLike, true_index: ArrayLike, *, n_bins: int = 10) -> dict[str, NDArray[Any]]:
    """Reliability diagram of the top class: per equal-width confidence bin, the number of rows,
    their mean top probability and the share right (NaN for empty bins).

    Examples
    --------
    >>> r = reliability([[0.9, 0.1], [0.8, 0.2], [0.3, 0.7]], [0, 1, 1], n_bins=2)
    >>> r["n"].tolist(), r["accuracy"].tolist()
    ([0, 3], [nan, 0.6666666666666666])
    """
    p = np.asarray(proba, dtype=float)
    t = np.asarray(true_index, dtype=np.int64)
    conf = p.max(axis=1) if len(p) else np.zeros(0)
    right = (np.argmax(p, axis=1) == t) if len(p) else np.zeros(0, dtype=bool)
    edges = np.linspace(0.0, 1.0, n_bins + 1)
    b = np.clip(np.searchsorted(edges, conf, side="left") - 1, 0, n_bins - 1)
    n = np.bincount(b, minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_conf = np.bincount(b, weights=conf, minlength=n_bins) / n
        acc = np.bincount(b, weights=right.astype(float), minlength=n_bins) / n
    return {"lo": edges[:-1], "hi": edges[1:], "n": n, "confidence": mean_conf, "accuracy": acc}


@dataclasses.dataclass(frozen=True)
class Calibration:
    """Temperatures and "unknown" thresholds of a model (see the module doc).

    The identity (``Calibration()``) leaves probabilities as the forest gives them (floored
    and renormalised) and never answers unknown.
    """

    temperature: float = 1.0
    terrain_temperature: float = 1.0
    disk_threshold: float = 0.0
    terrain_threshold: float = 0.0
    keep: float = 0.95
    fitted_on: str = ""

    def disk_proba(self, proba: ArrayLike) -> NDArray[np.float64]:
        """Calibrated disk probabilities."""
        return temper(proba, self.temperature)

    def terrain_posterior(self, logp_sum: ArrayLike) -> NDArray[np.float64]:
        """Calibrated terrain posterior from the summed calibrated log-probabilities of its disks."""
        return softmax(np.asarray(logp_sum, dtype=float) / self.terrain_temperature)

    def to_dict(self) -> dict[str, Any]:
        return {"method": "temperature", **dataclasses.asdict(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> Calibration:
        if not d:
            return cls()
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


def fit_calibration(proba: ArrayLike, true_index: ArrayLike, terrain_id: ArrayLike, *, keep: float = 0.95,
                    fitted_on: str = "") -> Calibration:
    """Fit a :class:`Calibration` on held-out predictions.

    ``proba``: the forest's probabilities of held-out disks (rows), ``true_index`` their
    true class columns, ``terrain_id`` which held-out input (e.g. run and region) each disk
    belongs to: the disks of one input make one terrain answer.
    """
    p = np.asarray(proba, dtype=float)
    t = np.asarray(true_index, dtype=np.int64)
    tid = np.asarray(terrain_id)
    if len(p) == 0:
        return Calibration(keep=keep, fitted_on=fitted_on)
    temperature = fit_temperature(log_proba(p), t)
    q = temper(p, temperature)
    right = np.argmax(q, axis=1) == t
    disk_threshold = keep_threshold(q.max(axis=1)[right], keep=keep)
    sums, truth, best, conf = terrain_answers(np.log(q), t, tid, q)
    terrain_temperature = fit_temperature(sums, truth)
    terrain_threshold = keep_threshold(conf[best == truth], keep=keep)
    return Calibration(temperature, terrain_temperature, disk_threshold, terrain_threshold, keep, fitted_on)


def terrain_answers(logq: NDArray[np.float64], true_index: NDArray[np.int64], terrain_id: ArrayLike,
                    q: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64],
                                                     NDArray[np.float64]]:
    """Per terrain (rows sharing a ``terrain_id``, in order of first appearance): summed log-probabilities,
    true class (that of its first disk), best class and mean probability of the best class over its disks."""
    tid = np.asarray(terrain_id)
    _, first, inv = np.unique(tid, return_index=True, return_inverse=True)
    inv = np.asarray(inv).ravel()
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    g = rank[inv]
    n_t = len(order)
    sums = np.zeros((n_t, logq.shape[1]))
    np.add.at(sums, g, logq)
    best = np.argmax(sums, axis=1)
    counts = np.bincount(g, minlength=n_t)
    conf = np.bincount(g, weights=q[np.arange(len(q)), best[g]], minlength=n_t) / counts
    truth = np.asarray(true_index, dtype=np.int64)[np.sort(first)]
    return sums, truth, best.astype(np.int64), conf
