"""Training and evaluation protocol of the orometric region classifier.

Paper protocol (Argudo et al. 2019, section 4.2): Random Forest with 100 trees; per
region at most 80 training and 20 validation disks drawn at random (80:20) afresh on
every run; accuracy averaged over the runs (mean and median), per-class accuracy,
confusion matrix and the accuracy of each feature group alone (Table 2).

Neighbouring disks overlap (centres can be 0.5 R apart) and share peaks, so a random
split puts near-copies of validation disks in the training set. The *spatial* split
reported beside it holds out a strip of each region: a random direction per run and
per input, the last ``val_fraction`` of the disks along it are validation disks, and
only disks whose centres are farther than ``buffer_m`` (default 2 R: no shared peak)
from every validation centre are used for training.

orokit's default classifier is extremely randomized trees (``classifier="et"``), chosen
on the spatial hold-out; ``"rf"`` is the paper's forest. Every run also records the
terrain-level answer of each held-out strip (summed log-probability of its disks), from
which the "unknown" threshold of a model is taken (:meth:`Evaluation.unknown_threshold`).
"""
from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from orokit._typing import SeedLike
from orokit.errors import InputError, OrokitWarning
from orokit.classify.calibration import (
    Calibration,
    calibration_scores,
    fit_calibration,
    log_proba,
    reliability,
    softmax,
    terrain_answers,
)
from orokit.classify.features import check_feature_table, feature_set_of

logger = logging.getLogger(__name__)

SplitKind = Literal["random", "spatial", "blocks"]
SPLIT_KINDS = ("random", "spatial", "blocks")


ClassifierKind = Literal["rf", "et", "hgb"]
CLASSIFIER_KINDS = ("rf", "et", "hgb")


def make_classifier(kind: ClassifierKind = "rf", *, n_estimators: int = 100, n_jobs: int = 1,
                    random_state: int | None = None) -> Any:
    """A scikit-learn Pipeline with the region classifier.

    ``"rf"``: the paper's Random Forest (``n_estimators`` trees). ``"et"``: extremely
    randomized trees (``2 * n_estimators`` trees; random split thresholds average out the
    noise of few-peak disks). ``"hgb"``: scikit-learn's HistGradientBoostingClassifier
    (``n_estimators`` boosting iterations, no early stopping).
    """
    from sklearn.pipeline import Pipeline

    if kind == "rf":
        from sklearn.ensemble import RandomForestClassifier

        est = RandomForestClassifier(n_estimators=n_estimators, n_jobs=n_jobs, random_state=random_state)
        return Pipeline([("rf", est)])
    if kind == "et":
        from sklearn.ensemble import ExtraTreesClassifier

        est = ExtraTreesClassifier(n_estimators=2 * n_estimators, n_jobs=n_jobs, random_state=random_state)
        return Pipeline([("et", est)])
    if kind == "hgb":
        from sklearn.ensemble import HistGradientBoostingClassifier

        est = HistGradientBoostingClassifier(max_iter=n_estimators, early_stopping=False, random_state=random_state)
        return Pipeline([("hgb", est)])
    raise InputError(f"classifier must be one of {', '.join(CLASSIFIER_KINDS)}, got {kind!r}")


def check_classes(labels: Sequence[Any], *, min_disks: int = 2, small_classes: Literal["error", "drop"] = "error"
                  ) -> NDArray[np.bool_]:
    """Check every class has ``min_disks`` disks; returns a keep-mask.

    ``small_classes="error"`` raises :class:`~orokit.errors.InputError` listing the
    regions and their counts; ``"drop"`` drops them with a warning (documented fallback).
    """
    lab = pd.Series(np.asarray(labels, dtype=object))
    counts = lab.value_counts()
    small = counts[counts < min_disks]
    keep = ~lab.isin(small.index).to_numpy()
    if len(small):
        listing = ", ".join(f"{k}: {v}" for k, v in small.items())
        if small_classes == "error":
            raise InputError(f"regions with fewer than {min_disks} usable disks cannot be split into training and "
                             f"validation sets ({listing}); use more data, a smaller radius or --min-peaks, or drop "
                             f"them (small_classes='drop', CLI --drop-small-classes)")
        import warnings

        warnings.warn(f"dropping regions with fewer than {min_disks} disks: {listing}", OrokitWarning, stacklevel=2)
    if keep.sum() and len(counts[counts >= min_disks]) < 2:
        raise InputError(f"need at least 2 regions with >= {min_disks} disks to train a classifier; got "
                         f"{dict(counts)}")
    return keep


def random_split(labels: Sequence[Any], *, max_train: int = 80, max_val: int = 20, val_fraction: float = 0.2,
                 rng: SeedLike = None) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Per-class random split: ``round(n * val_fraction)`` (>= 1, <= max_val) validation disks,
    up to ``max_train`` of the others for training. Returns disjoint positional indices."""
    rng = np.random.default_rng(rng)
    lab = np.asarray(labels, dtype=object)
    tr, va = [], []
    for c in pd.unique(lab):
        idx = rng.permutation(np.flatnonzero(lab == c))
        n = len(idx)
        if n < 2:
            tr.append(idx)
            continue
        n_val = int(min(max_val, max(1, round(n * val_fraction))))
        va.append(idx[:n_val])
        tr.append(idx[n_val:][:max_train])
    return _cat(tr), _cat(va)


def _cat(parts: list[NDArray]) -> NDArray[np.int64]:
    return np.sort(np.concatenate(parts).astype(np.int64)) if parts else np.zeros(0, dtype=np.int64)


def metric_coordinates(x: NDArray, y: NDArray, groups: Sequence[Any] | NDArray, *, crs: Any = None,
                       lon: NDArray | None = None, lat: NDArray | None = None
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Disk centres in metres, group by group, for distance tests between disks.

    - ``crs`` geographic: ``x, y`` are lon/lat degrees;
    - else, where ``lon``/``lat`` are finite for every disk of a group, they are used;

    and each such group is projected to an azimuthal equidistant CRS centred on it
    (:func:`orokit.sampling.disks.local_metric_crs`; distances good to a fraction of a
    percent over hundreds of km). Other groups keep ``x, y`` (metres of a projected or
    local grid). Only distances within a group are meaningful.
    """
    from pyproj import CRS, Transformer

    from orokit.sampling.disks import local_metric_crs

    grp = np.asarray(groups, dtype=object)
    mx = np.asarray(x, dtype=float).copy()
    my = np.asarray(y, dtype=float).copy()
    geographic = crs is not None and CRS.from_user_input(crs).is_geographic
    if geographic:
        glon, glat = mx.copy(), my.copy()
    elif lon is not None and lat is not None:
        glon, glat = np.asarray(lon, dtype=float), np.asarray(lat, dtype=float)
    else:
        return mx, my
    for g in pd.unique(grp):
        idx = np.flatnonzero(grp == g)
        lo, la = glon[idx], glat[idx]
        if not (np.isfinite(lo).all() and np.isfinite(la).all()):
            if geographic:
                raise InputError(f"group {g!r} has disks without finite lon/lat; cannot measure distances")
            continue
        lon0 = 0.5 * (lo.min() + lo.max()) if np.ptp(lo) <= 180 else float(lo[0])
        to_local = Transformer.from_crs("EPSG:4326", local_metric_crs(lon0, 0.5 * (la.min() + la.max())),
                                        always_xy=True)
        px, py = to_local.transform(lo, la)
        mx[idx], my[idx] = px, py
    return mx, my


def spatial_split(labels: Sequence[Any], x: NDArray, y: NDArray, *, groups: Sequence[Any] | None = None,
                  buffer_m: float = 0.0, max_train: int = 80, max_val: int = 20, val_fraction: float = 0.2,
                  crs: Any = None, rng: SeedLike = None) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Per-class spatially held-out split.

    For each group (input file / region; default: the label) a random direction is
    drawn; the last ``val_fraction`` of its disks along that direction (>= 1) are
    validation disks; training disks are those whose centre is farther than
    ``buffer_m`` metres from every validation centre of the same group. Caps of
    ``max_val``/``max_train`` per class are applied by random subsets. ``x, y`` are
    metres, or lon/lat degrees when ``crs`` is geographic (each group is then
    projected to a local azimuthal equidistant CRS, see :func:`metric_coordinates`).
    """
    rng = np.random.default_rng(rng)
    lab = np.asarray(labels, dtype=object)
    grp = np.asarray(groups if groups is not None else labels, dtype=object)
    x, y = metric_coordinates(x, y, grp, crs=crs)
    tr, va = [], []
    for c in pd.unique(lab):
        ctr, cva = [], []
        for g in pd.unique(grp[lab == c]):
            idx = np.flatnonzero((lab == c) & (grp == g))
            if len(idx) < 2:
                ctr.append(idx)
                continue
            theta = rng.uniform(0, 2 * np.pi)
            proj = x[idx] * np.cos(theta) + y[idx] * np.sin(theta) + rng.random(len(idx)) * 1e-9
            order = idx[np.argsort(proj)]
            n_val = max(1, int(round(len(idx) * val_fraction)))
            val, rest = order[-n_val:], order[:-n_val]
            if buffer_m > 0 and len(rest):
                d = np.hypot(x[rest, None] - x[None, val], y[rest, None] - y[None, val]).min(axis=1)
                rest = rest[d > buffer_m]
            cva.append(val)
            ctr.append(rest)
        cva_i, ctr_i = _cat(cva), _cat(ctr)
        if len(cva_i) > max_val:
            cva_i = np.sort(rng.choice(cva_i, max_val, replace=False))
        if len(ctr_i) > max_train:
            ctr_i = np.sort(rng.choice(ctr_i, max_train, replace=False))
        tr.append(ctr_i)
        va.append(cva_i)
    return _cat(tr), _cat(va)


def block_folds(labels: Sequence[Any], x: NDArray, y: NDArray, *, groups: Sequence[Any] | None = None,
                block_m: float, buffer_m: float = 0.0, max_train: int | None = 80, rng: SeedLike = None
                ) -> list[tuple[NDArray[np.int64], NDArray[np.int64]]]:
    """Spatial k-fold split: every disk is a validation disk exactly once.

    Each group's disk centres (metres; distances only within a group) are cut into square
    blocks of side ``block_m`` on a grid with a random rotation and offset. The blocks of
    each group are shuffled; fold ``j`` holds out the ``j``-th block of every group. Its
    training disks are all other disks whose centre is farther than ``buffer_m`` from every
    held-out centre of the same group (disks of other groups always train), at most
    ``max_train`` per class (random subset). Returns one ``(train, validation)`` pair of
    positional indices per fold.

    Examples
    --------
    >>> folds = block_folds(["a"] * 4, np.array([0.0, 1.0, 50.0, 51.0]), np.zeros(4), block_m=10.0,
    ...                     buffer_m=20.0, rng=0)
    >>> sorted(int(i) for _, va in folds for i in va)
    [0, 1, 2, 3]
    """
    if not block_m > 0:
        raise InputError(f"block size must be > 0 metres, got {block_m!r}")
    rng = np.random.default_rng(rng)
    lab = np.asarray(labels, dtype=object)
    grp = np.asarray(groups if groups is not None else labels, dtype=object)
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    blocks: list[list[NDArray[np.int64]]] = []  # per group: its blocks in fold order
    for g in pd.unique(grp):
        idx = np.flatnonzero(grp == g)
        theta = rng.uniform(0, 2 * np.pi)
        u = (x[idx] * np.cos(theta) + y[idx] * np.sin(theta)) / block_m + rng.random()
        v = (-x[idx] * np.sin(theta) + y[idx] * np.cos(theta)) / block_m + rng.random()
        _, block_of = np.unique(np.column_stack([np.floor(u), np.floor(v)]), axis=0, return_inverse=True)
        block_of = np.asarray(block_of).ravel()
        order = rng.permutation(int(block_of.max()) + 1) if len(idx) else np.zeros(0, dtype=int)
        blocks.append([idx[block_of == b] for b in order])
    folds = []
    for j in range(max((len(b) for b in blocks), default=0)):
        val = [b[j] for b in blocks if j < len(b)]
        va = _cat(val)
        train_mask = np.ones(len(lab), dtype=bool)
        train_mask[va] = False
        if buffer_m > 0:
            for v in val:
                same = np.flatnonzero(train_mask & (grp == grp[v[0]]))
                if len(same):
                    d = np.hypot(x[same, None] - x[None, v], y[same, None] - y[None, v]).min(axis=1)
                    train_mask[same[d <= buffer_m]] = False
        tr = np.flatnonzero(train_mask)
        if max_train is not None:
            parts = []
            for c in pd.unique(lab[tr]):
                t = tr[lab[tr] == c]
                parts.append(np.sort(rng.choice(t, max_train, replace=False)) if len(t) > max_train else t)
            tr = _cat(parts)
        folds.append((tr.astype(np.int64), va))
    return folds


@dataclasses.dataclass
class Evaluation:
    """Result of repeated train/validation runs (one split kind)."""

    split: str
    classes: list[str]
    accuracies: NDArray[np.float64]
    confusion: NDArray[np.int64]  # summed over runs; rows = true class, columns = predicted
    per_class: dict[str, float]
    per_feature: dict[str, float]
    per_feature_runs: int
    mean_train: dict[str, float]
    mean_val: dict[str, float]
    params: dict[str, Any]
    #: per run and held-out region: (true region, terrain-level answer, mean disk probability of that answer)
    terrain: list[tuple[str, str, float]] = dataclasses.field(default_factory=list)
    #: held-out predictions of every fit (uncalibrated): the forest's probabilities (columns: ``classes``)
    heldout_proba: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    #: the true class column of each held-out row
    heldout_true: NDArray[np.int64] = dataclasses.field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: which terrain answer each held-out row belongs to (one per fit and held-out region)
    heldout_terrain: NDArray[np.int64] = dataclasses.field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def terrain_accuracy(self) -> float:
        """Share of held-out regions (per run) whose disks together get the right terrain label."""
        return float(np.mean([t == p for t, p, _ in self.terrain])) if self.terrain else float("nan")

    def calibration(self, keep: float = 0.95) -> Calibration:
        """Temperatures and 'unknown' thresholds fitted on all held-out predictions
        (:func:`orokit.classify.calibration.fit_calibration`; ``keep`` of the right held-out
        answers stay answered)."""
        return fit_calibration(self.heldout_proba, self.heldout_true, self.heldout_terrain, keep=keep,
                               fitted_on=f"{self.split} hold-out, {len(self.accuracies)} runs, "
                                         f"{len(self.heldout_true)} held-out disks")

    def calibration_check(self, keep: float = 0.95, n_bins: int = 10) -> dict[str, Any]:
        """Calibration before and after, measured honestly: the held-out disks of each region are
        calibrated with a :class:`Calibration` fitted on the held-out disks of the *other* regions.

        Returns scores (:func:`~orokit.classify.calibration.calibration_scores`) and reliability
        bins of the disks, raw and calibrated, the same for the terrain answers (raw terrain
        posterior: the softmax of the summed floored log-probabilities), and the share of right
        and wrong answers called unknown.
        """
        p, t, tid = self.heldout_proba, self.heldout_true, self.heldout_terrain
        q = np.zeros_like(p)
        disk_unknown = np.zeros(len(t), dtype=bool)
        raw_t, cal_t, truth_t, unknown_t = [], [], [], []
        for k in np.unique(t):
            rows = t == k
            cal = fit_calibration(p[~rows], t[~rows], tid[~rows], keep=keep)
            q[rows] = cal.disk_proba(p[rows])
            disk_unknown[rows] = q[rows].max(axis=1) < cal.disk_threshold
            sums_raw, truth, _, _ = terrain_answers(log_proba(p[rows]), t[rows], tid[rows], p[rows])
            sums, _, best, conf = terrain_answers(np.log(q[rows]), t[rows], tid[rows], q[rows])
            raw_t.append(softmax(sums_raw))
            cal_t.append(cal.terrain_posterior(sums))
            truth_t.append(truth)
            unknown_t.append(conf < cal.terrain_threshold)
        right = np.argmax(p, axis=1) == t
        tp_raw, tp_cal, tt = np.concatenate(raw_t), np.concatenate(cal_t), np.concatenate(truth_t)
        t_unknown, t_right = np.concatenate(unknown_t), np.argmax(tp_cal, axis=1) == tt
        return {
            "disks": {"raw": calibration_scores(p, t, n_bins=n_bins), "calibrated": calibration_scores(q, t, n_bins=n_bins),
                      "reliability_raw": reliability(p, t, n_bins=n_bins),
                      "reliability_calibrated": reliability(q, t, n_bins=n_bins),
                      "unknown_right": float(disk_unknown[right].mean()) if right.any() else float("nan"),
                      "unknown_wrong": float(disk_unknown[~right].mean()) if (~right).any() else float("nan")},
            "terrain": {"raw": calibration_scores(tp_raw, tt, n_bins=n_bins),
                        "calibrated": calibration_scores(tp_cal, tt, n_bins=n_bins),
                        "reliability_raw": reliability(tp_raw, tt, n_bins=n_bins),
                        "reliability_calibrated": reliability(tp_cal, tt, n_bins=n_bins),
                        "unknown_right": float(t_unknown[t_right].mean()) if t_right.any() else float("nan"),
                        "unknown_wrong": float(t_unknown[~t_right].mean()) if (~t_right).any() else float("nan")},
        }

    @property
    def mean_accuracy(self) -> float:
        a = self.accuracies[np.isfinite(self.accuracies)]
        return float(np.mean(a)) if len(a) else float("nan")

    @property
    def median_accuracy(self) -> float:
        a = self.accuracies[np.isfinite(self.accuracies)]
        return float(np.median(a)) if len(a) else float("nan")

    def confusion_normalized(self) -> NDArray[np.float64]:
        c = self.confusion.astype(float)
        s = c.sum(axis=1, keepdims=True)
        return np.divide(c, s, out=np.zeros_like(c), where=s > 0)

    def to_dict(self) -> dict[str, Any]:
        return {
            "split": self.split, "runs": int(len(self.accuracies)),
            "mean_accuracy": self.mean_accuracy, "median_accuracy": self.median_accuracy,
            "std_accuracy": float(np.nanstd(self.accuracies)) if np.isfinite(self.accuracies).any() else float("nan"),
            "runs_without_training_set": int(np.sum(~np.isfinite(self.accuracies))),
            "per_class": self.per_class, "per_feature": self.per_feature,
            "per_feature_runs": self.per_feature_runs, "classes": self.classes,
            "confusion": self.confusion.tolist(), "mean_train_disks": self.mean_train,
            "mean_validation_disks": self.mean_val, "params": self.params,
            "terrain_accuracy": self.terrain_accuracy,
            "calibration": self.calibration().to_dict() if len(self.heldout_true) else None,
        }


def _predict_in_order(clf: Any) -> None:
    """One thread for predicting: a threaded forest sums its trees' probabilities in any order."""
    est = clf[-1]
    if "n_jobs" in est.get_params():
        est.set_params(n_jobs=1)


def _fit_score(X: NDArray, y: NDArray, tr: NDArray, va: NDArray, cols: NDArray | None, seed: int,
               n_estimators: int, classes: list[str], kind: ClassifierKind = "rf", strict: bool = True,
               n_jobs: int = 1) -> tuple[float, NDArray[np.int64], list[tuple[str, str, float]], NDArray[np.int64],
                          NDArray[np.float64]]:
    """One fit: accuracy, confusion, terrain answers, the validation rows it tested and their
    probabilities (columns: ``classes``; 0 for a class without training disks)."""
    from sklearn.metrics import confusion_matrix

    empty = np.zeros((len(classes), len(classes)), dtype=np.int64)
    none = (np.zeros(0, dtype=np.int64), np.zeros((0, len(classes))))
    if not strict and len(va):
        # a fold of the block split can leave a region without a training disk far enough from its
        # held-out block: those disks cannot be tested in this fold (they are counted as untested)
        va = va[np.isin(y[va], y[tr])]
    # a spatial split can leave a region with no training disk far enough from its held-out strip:
    # that run cannot test the region (its disks could only be misclassified), so it is not counted
    if len(va) == 0 or len(np.unique(y[tr])) < 2 or not np.isin(np.unique(y[va]), y[tr]).all():
        return float("nan"), empty, [], *none
    Xs = X if cols is None else X[:, cols]
    clf = make_classifier(kind, n_estimators=n_estimators, n_jobs=n_jobs, random_state=seed)
    clf.fit(Xs[tr], y[tr])  # the same trees for any n_jobs (their seeds are drawn before the fit)
    _predict_in_order(clf)
    proba = clf.predict_proba(Xs[va])
    known = [str(c) for c in clf.classes_]
    pred = np.asarray(known)[np.argmax(proba, axis=1)]
    acc = float(np.mean(pred == y[va]))
    # terrain level: the validation disks of each region together, summed log-probabilities
    terrain = []
    for c in pd.unique(y[va]):
        p = proba[y[va] == c]
        k = int(np.argmax(np.log(np.clip(p, 1e-3, 1.0)).sum(axis=0)))
        terrain.append((str(c), known[k], float(p[:, k].mean())))
    full = np.zeros((len(va), len(classes)))
    full[:, [classes.index(c) for c in known]] = proba
    return acc, confusion_matrix(y[va], pred, labels=classes), terrain, va.astype(np.int64), full


def evaluate(features: pd.DataFrame, *, runs: int = 100, split: SplitKind = "random",
             feature_groups: bool = True, feature_runs: int | None = None, n_estimators: int = 100,
             max_train: int = 80, max_val: int = 20, val_fraction: float = 0.2, buffer_m: float | None = None,
             block_m: float | None = None, min_disks: int = 2, small_classes: Literal["error", "drop"] = "error", n_jobs: int = 2,
             classifier: ClassifierKind = "et", progress: bool = False, rng: SeedLike = None) -> Evaluation:
    """Repeated-split evaluation of the classifier on a feature table.

    Parameters
    ----------
    features : DataFrame
        Feature table (:func:`orokit.classify.features.feature_table`).
    runs : int
        Number of runs with fresh splits (paper: 100).
    split : {"random", "spatial", "blocks"}
        Random 80:20 per region (paper), spatially held-out strips (see module doc), or
        spatial k-fold blocks (:func:`block_folds`: every disk is tested once per run, and
        training keeps all ground farther than the buffer from the held-out block).
    feature_groups : bool
        Also score each feature group alone (Table 2 rows).
    feature_runs : int, optional
        Runs for each feature group (default: ``runs``).
    buffer_m : float, optional
        Spatial and block splits: minimum distance of training centres from validation
        centres (default 2 R, so training and validation disks share no peak).
    block_m : float, optional
        Block split: side of the square blocks (default R).
    min_disks, small_classes
        See :func:`check_classes`: a region with fewer disks is an error, or dropped.
    n_jobs : int
        Threads of each forest's fit (the fits run one after the other; the results do not
        depend on it).
    classifier : {"rf", "hgb"}
        See :func:`make_classifier`.
    rng : Generator, int or None
        Seed of the splits and forests.

    Returns
    -------
    Evaluation
    """

    if runs < 1:
        raise InputError(f"runs must be >= 1, got {runs}")
    if split not in SPLIT_KINDS:
        raise InputError(f"split must be one of {', '.join(SPLIT_KINDS)}, got {split!r}")
    fs = feature_set_of(features)
    cols = check_feature_table(features)
    keep = check_classes(features["label"].astype(str).to_numpy(), min_disks=min_disks, small_classes=small_classes)
    f = features.loc[keep].reset_index(drop=True)
    X = f[cols].to_numpy(dtype=float)
    y = f["label"].astype(str).to_numpy()
    classes = sorted(pd.unique(y).tolist())
    radius = float(np.nanmax(f["radius_m"])) if len(f) else float("nan")
    if buffer_m is None:
        buffer_m = 2.0 * radius
    if block_m is None:
        block_m = radius
    groups = (f["label"].astype(str) + "|" + f["source"].astype(str)).to_numpy()
    if split != "random":  # metres: lon/lat tables (peak lists, geographic DEMs) are projected per group
        mx, my = metric_coordinates(f["x"].to_numpy(float), f["y"].to_numpy(float), groups,
                                    lon=f["lon"].to_numpy(float) if "lon" in f else None,
                                    lat=f["lat"].to_numpy(float) if "lat" in f else None)
    rng = np.random.default_rng(rng)
    seeds = rng.integers(0, 2**31 - 1, size=runs)
    # every run is a list of (train, validation) folds: one for the random and strip splits
    splits: list[list[tuple[NDArray[np.int64], NDArray[np.int64]]]] = []
    for s in seeds:
        if split == "random":
            splits.append([random_split(y, max_train=max_train, max_val=max_val, val_fraction=val_fraction, rng=s)])
        elif split == "spatial":
            splits.append([spatial_split(y, mx, my, groups=groups, buffer_m=buffer_m, max_train=max_train,
                                         max_val=max_val, val_fraction=val_fraction, rng=s)])
        else:
            splits.append(block_folds(y, mx, my, groups=groups, block_m=block_m, buffer_m=buffer_m,
                                      max_train=max_train, rng=s))
    strict = split != "blocks"
    tasks: list[tuple[str | None, NDArray | None, int, int]] = [(None, None, i, k) for i in range(runs)
                                                                 for k in range(len(splits[i]))]
    groups_cols: dict[str, NDArray] = {}
    if feature_groups:
        fr = runs if feature_runs is None else min(feature_runs, runs)
        for name, gcols in fs.groups().items():
            groups_cols[name] = np.array([cols.index(c) for c in gcols])
            tasks += [(name, groups_cols[name], i, k) for i in range(fr) for k in range(len(splits[i]))]
    else:
        fr = 0
    # The fits run one after the other, each forest on n_jobs threads. Fits in concurrent threads
    # raced on the process-wide warning filters (sklearn's workers reset them while another
    # thread's Parallel captured them) and raised spurious sklearn UserWarnings.
    todo = tasks
    if progress:
        from tqdm.auto import tqdm

        todo = tqdm(tasks, desc=f"training ({split} split)", unit="fit")
    results = [_fit_score(X, y, splits[i][k][0], splits[i][k][1], gc, int(seeds[i]) + k, n_estimators, classes,
                          classifier, strict, n_jobs) for _, gc, i, k in todo]
    nc = len(classes)

    def pooled(name: str | None, n_runs: int) -> tuple[NDArray[np.float64], list[NDArray[np.int64]]]:
        """Per run: accuracy over all its folds (NaN when a strict run could not test a region), confusion."""
        accs, confs = [], []
        for i in range(n_runs):
            rs = [r for (n, _, j, _), r in zip(tasks, results) if n == name and j == i]
            cm = sum((r[1] for r in rs), np.zeros((nc, nc), dtype=np.int64))
            bad = strict and any(not np.isfinite(r[0]) for r in rs)
            accs.append(float("nan") if bad or cm.sum() == 0 else float(np.trace(cm) / cm.sum()))
            confs.append(cm)
        return np.array(accs), confs

    accs, run_confs = pooled(None, runs)
    terrain = [t for (name, _, _, _), r in zip(tasks, results) if name is None for t in r[2]]
    main = [(j, r) for j, ((name, _, _, _), r) in enumerate(zip(tasks, results)) if name is None and len(r[3])]
    if main:
        h_proba = np.concatenate([r[4] for _, r in main])
        h_true = np.concatenate([np.searchsorted(classes, y[r[3]]) for _, r in main]).astype(np.int64)
        h_terrain = np.concatenate([j * nc + np.searchsorted(classes, y[r[3]]) for j, r in main]).astype(np.int64)
    else:
        h_proba, h_true, h_terrain = np.zeros((0, nc)), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    conf = sum(run_confs, np.zeros((nc, nc), dtype=np.int64))
    per_feature = {}
    for name in groups_cols:
        a, _ = pooled(name, fr)
        per_feature[name] = float(np.mean(a[np.isfinite(a)])) if np.isfinite(a).any() else float("nan")
    recalls: dict[str, list[float]] = {c: [] for c in classes}
    for cm in run_confs:
        for k, c in enumerate(classes):
            if cm[k].sum():
                recalls[c].append(cm[k, k] / cm[k].sum())
    per_class = {c: float(np.mean(v)) if v else float("nan") for c, v in recalls.items()}
    all_folds = [f for run in splits for f in run]
    mean_train = {c: float(np.mean([np.sum(y[t] == c) for t, _ in all_folds])) for c in classes}
    # validation disks per run (a block run tests every disk once, minus untestable ones)
    if split == "blocks":
        mean_val = {c: float(np.mean([cm[k].sum() for cm in run_confs])) for k, c in enumerate(classes)}
    else:
        mean_val = {c: float(np.mean([np.sum(y[v] == c) for _, v in all_folds])) for c in classes}
    params = {"runs": runs, "split": split, "classifier": classifier, "feature_set": fs.name,
              "n_estimators": n_estimators, "max_train": max_train,
              "max_val": max_val, "val_fraction": val_fraction, "radius_m": radius,
              "buffer_m": float(buffer_m) if split != "random" else None,
              "block_m": float(block_m) if split == "blocks" else None, "n_disks": int(len(f)),
              "untested_disks_per_run": float(len(f) - conf.sum() / runs) if split == "blocks" else None,
              "dropped_classes": sorted(set(features["label"].astype(str)[~keep]))}
    ev = Evaluation(split, classes, accs, conf, per_class, per_feature, fr, mean_train, mean_val, params, terrain,
                    h_proba, h_true, h_terrain)
    logger.info("%s split, %d runs: mean accuracy %.3f, median %.3f", split, runs, ev.mean_accuracy,
                ev.median_accuracy)
    return ev


@dataclasses.dataclass
class OpenSetEvaluation:
    """Leave-one-region-out test of the "unknown" answer (:func:`evaluate_open_set`).

    One row per left-out region: the share of its disks (and of its terrain answers, all its
    disks together, one per run) answered unknown by models that never saw it, against the
    share of the known regions' held-out disks (and strips) answered unknown by the same
    models; ``auroc`` is the area under the ROC curve of the calibrated top probability for
    telling the known regions' held-out disks from the left-out region's disks (0.5: no
    better than chance). ``answered_as`` is the class most of its disks get.
    """

    rows: list[dict[str, Any]]
    params: dict[str, Any]

    def summary(self) -> dict[str, float]:
        """Means over the left-out regions."""
        keys = ("unknown_disks", "unknown_terrain", "known_unknown_disks", "known_unknown_terrain", "auroc")
        return {k: float(np.nanmean([r[k] for r in self.rows])) if self.rows else float("nan") for k in keys}

    def to_dict(self) -> dict[str, Any]:
        return {"rows": self.rows, "summary": self.summary(), "params": self.params}


def _fit_predict(X: NDArray, y: NDArray, tr: NDArray, tests: list[NDArray], seed: int, n_estimators: int,
                 kind: ClassifierKind, n_jobs: int = 1) -> tuple[list[str], list[NDArray[np.float64]]]:
    clf = make_classifier(kind, n_estimators=n_estimators, n_jobs=n_jobs, random_state=seed)
    clf.fit(X[tr], y[tr])
    _predict_in_order(clf)
    return [str(c) for c in clf.classes_], [clf.predict_proba(X[t]) if len(t) else np.zeros((0, len(clf.classes_)))
                                           for t in tests]


def evaluate_open_set(features: pd.DataFrame, *, runs: int = 3, n_estimators: int = 100, max_train: int = 80,
                      max_val: int = 20, val_fraction: float = 0.2, buffer_m: float | None = None, keep: float = 0.95,
                      min_disks: int = 2, small_classes: Literal["error", "drop"] = "error", n_jobs: int = 2,
                      classifier: ClassifierKind = "et", progress: bool = False, rng: SeedLike = None
                      ) -> OpenSetEvaluation:
    """Leave-one-region-out test of the calibrated "unknown" answer.

    For every region ``r`` and run: a spatial hold-out split (:func:`spatial_split`, training
    disks farther than ``buffer_m``, default 2 R) of the *other* regions; a model fitted on
    their training disks predicts their held-out disks and all disks of ``r``. The
    calibration (temperatures, thresholds keeping ``keep`` of the right answers) is fitted
    on the known regions' held-out disks only, exactly as for a model
    (:meth:`Evaluation.calibration`), and applied to ``r``'s disks; the known regions' own
    unknown rates use a calibration fitted without the region measured. Nothing is tuned
    on the left-out region.
    """
    from sklearn.metrics import roc_auc_score

    if runs < 1:
        raise InputError(f"runs must be >= 1, got {runs}")
    cols = check_feature_table(features)
    keep_rows = check_classes(features["label"].astype(str).to_numpy(), min_disks=min_disks,
                              small_classes=small_classes)
    f = features.loc[keep_rows].reset_index(drop=True)
    X = f[cols].to_numpy(dtype=float)
    y = f["label"].astype(str).to_numpy()
    classes = sorted(pd.unique(y).tolist())
    if len(classes) < 3:
        raise InputError(f"the open-set test leaves one region out and needs >= 3 regions, got {classes}")
    radius = float(np.nanmax(f["radius_m"]))
    if buffer_m is None:
        buffer_m = 2.0 * radius
    groups = (f["label"].astype(str) + "|" + f["source"].astype(str)).to_numpy()
    mx, my = metric_coordinates(f["x"].to_numpy(float), f["y"].to_numpy(float), groups,
                                lon=f["lon"].to_numpy(float) if "lon" in f else None,
                                lat=f["lat"].to_numpy(float) if "lat" in f else None)
    rng = np.random.default_rng(rng)
    tasks = []
    for r in classes:
        known = np.flatnonzero(y != r)
        unknown = np.flatnonzero(y == r)
        for s in rng.integers(0, 2**31 - 1, size=runs):
            tr, va = spatial_split(y[known], mx[known], my[known], groups=groups[known], buffer_m=buffer_m,
                                   max_train=max_train, max_val=max_val, val_fraction=val_fraction, rng=s)
            tasks.append((r, known[tr], known[va], unknown, int(s)))
    todo = tasks
    if progress:
        from tqdm.auto import tqdm

        todo = tqdm(tasks, desc="open-set test (one region left out)", unit="fit")
    # one fit after the other, each forest on n_jobs threads (see evaluate)
    results = [_fit_predict(X, y, tr, [va, u], s, n_estimators, classifier, n_jobs) for _, tr, va, u, s in todo]
    rows = []
    for r in classes:
        kc = [c for c in classes if c != r]
        kp, kt, kid, up, uid = [], [], [], [], []
        for j, ((rr, tr, va, u, _), (fit_classes, (p_va, p_u))) in enumerate(zip(tasks, results)):
            if rr != r or fit_classes != kc:  # a region without training disks: this run cannot test
                continue
            kp.append(p_va)
            kt.append(np.searchsorted(kc, y[va]))
            kid.append(j * len(classes) + np.searchsorted(kc, y[va]))
            up.append(p_u)
            uid.append(np.full(len(u), j))
        if not kp:
            continue
        p, t, tid = np.concatenate(kp), np.concatenate(kt).astype(np.int64), np.concatenate(kid)
        cal = fit_calibration(p, t, tid, keep=keep)
        pu, uid_a = np.concatenate(up), np.concatenate(uid)
        qu = cal.disk_proba(pu)
        u_disk = qu.max(axis=1) < cal.disk_threshold
        _, _, ubest, uconf = terrain_answers(np.log(qu), np.zeros(len(qu), dtype=np.int64), uid_a, qu)
        # the known regions' held-out disks, each calibrated without its own region
        qk = np.zeros_like(p)
        k_disk = np.zeros(len(t), dtype=bool)
        k_terrain = []
        for k in np.unique(t):
            m = t == k
            ck = fit_calibration(p[~m], t[~m], tid[~m], keep=keep)
            qk[m] = ck.disk_proba(p[m])
            k_disk[m] = qk[m].max(axis=1) < ck.disk_threshold
            _, _, _, kconf = terrain_answers(np.log(qk[m]), t[m], tid[m], qk[m])
            k_terrain.append(kconf < ck.terrain_threshold)
        score = np.concatenate([cal.disk_proba(p).max(axis=1), qu.max(axis=1)])  # one calibration: threshold-free
        is_known = np.r_[np.ones(len(qk)), np.zeros(len(qu))]
        answered = pd.Series(np.asarray(kc)[np.argmax(qu, axis=1)]).value_counts()
        rows.append({"region": r, "runs": len(kp), "disks": int(np.sum(y == r)),
                     "unknown_disks": float(u_disk.mean()), "unknown_terrain": float(np.mean(uconf < cal.terrain_threshold)),
                     "terrain_confidence": float(np.mean(uconf)), "answered_as": str(answered.index[0]),
                     "answered_as_share": float(answered.iloc[0] / len(qu)),
                     "known_unknown_disks": float(k_disk.mean()),
                     "known_unknown_terrain": float(np.mean(np.concatenate(k_terrain))),
                     "known_accuracy": float(np.mean(np.argmax(qk, axis=1) == t)),
                     "auroc": float(roc_auc_score(is_known, score)),
                     "disk_threshold": cal.disk_threshold, "terrain_threshold": cal.terrain_threshold})
    params = {"runs": runs, "classifier": classifier, "n_estimators": n_estimators, "max_train": max_train,
              "buffer_m": float(buffer_m), "keep": keep, "radius_m": radius, "n_disks": int(len(f)),
              "dropped_classes": sorted(set(features["label"].astype(str)[~keep_rows]))}
    return OpenSetEvaluation(rows, params)


def train_classifier(features: pd.DataFrame, *, n_estimators: int = 100, min_disks: int = 2,
                     small_classes: Literal["error", "drop"] = "error", max_per_class: int | None = None,
                     classifier: ClassifierKind = "et", n_jobs: int = 2, rng: SeedLike = None) -> Any:
    """Fit the final classifier Pipeline on all disks of a feature table.

    ``max_per_class`` caps the disks per region (random subset) to balance classes.
    """
    cols = check_feature_table(features)
    keep = check_classes(features["label"].astype(str).to_numpy(), min_disks=min_disks, small_classes=small_classes)
    f = features.loc[keep].reset_index(drop=True)
    rng = np.random.default_rng(rng)
    if max_per_class:
        idx = np.concatenate([rng.permutation(np.flatnonzero(f["label"].astype(str) == c))[:max_per_class]
                              for c in sorted(f["label"].astype(str).unique())])
        f = f.iloc[np.sort(idx)]
    model = make_classifier(classifier, n_estimators=n_estimators, n_jobs=n_jobs,
                            random_state=int(rng.integers(0, 2**31 - 1)))
    model.fit(f[cols].to_numpy(dtype=float), f["label"].astype(str).to_numpy())
    return model
