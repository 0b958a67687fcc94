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
from orokit.classify.features import check_feature_table, feature_set_of

logger = logging.getLogger(__name__)

SplitKind = Literal["random", "spatial"]


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


def metric_coordinates(x: NDArray, y: NDArray, groups: Sequence[Any], *, crs: Any = None,
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

    @property
    def terrain_accuracy(self) -> float:
        """Share of held-out regions (per run) whose disks together get the right terrain label."""
        return float(np.mean([t == p for t, p, _ in self.terrain])) if self.terrain else float("nan")

    def unknown_threshold(self, keep: float = 0.95) -> float:
        """Confidence below which the terrain answer is 'unknown': the ``1 - keep`` quantile of the
        confidences of right terrain answers, so ``keep`` of them stay answered."""
        right = [c for t, p, c in self.terrain if t == p]
        return float(np.quantile(right, 1.0 - keep)) if right else 0.0

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
            "unknown_threshold": self.unknown_threshold() if self.terrain else None,
        }


def _fit_score(X: NDArray, y: NDArray, tr: NDArray, va: NDArray, cols: NDArray | None, seed: int,
               n_estimators: int, classes: list[str], kind: ClassifierKind = "rf"
               ) -> tuple[float, NDArray[np.int64], list[tuple[str, str, float]]]:
    from sklearn.metrics import confusion_matrix

    # a spatial split can leave a region with no training disk far enough from its held-out strip:
    # that run cannot test the region (its disks could only be misclassified), so it is not counted
    if len(va) == 0 or len(np.unique(y[tr])) < 2 or not np.isin(np.unique(y[va]), y[tr]).all():
        return float("nan"), np.zeros((len(classes), len(classes)), dtype=np.int64), []
    Xs = X if cols is None else X[:, cols]
    clf = make_classifier(kind, n_estimators=n_estimators, n_jobs=1, random_state=seed)
    clf.fit(Xs[tr], y[tr])
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
    return acc, confusion_matrix(y[va], pred, labels=classes), terrain


def evaluate(features: pd.DataFrame, *, runs: int = 100, split: SplitKind = "random",
             feature_groups: bool = True, feature_runs: int | None = None, n_estimators: int = 100,
             max_train: int = 80, max_val: int = 20, val_fraction: float = 0.2, buffer_m: float | None = None,
             min_disks: int = 2, small_classes: Literal["error", "drop"] = "error", n_jobs: int = 2,
             classifier: ClassifierKind = "et", progress: bool = False, rng: SeedLike = None) -> Evaluation:
    """Repeated-split evaluation of the classifier on a feature table.

    Parameters
    ----------
    features : DataFrame
        Feature table (:func:`orokit.classify.features.feature_table`).
    runs : int
        Number of runs with fresh splits (paper: 100).
    split : {"random", "spatial"}
        Random 80:20 per region (paper) or spatially held-out strips (see module doc).
    feature_groups : bool
        Also score each feature group alone (Table 2 rows).
    feature_runs : int, optional
        Runs for each feature group (default: ``runs``).
    buffer_m : float, optional
        Spatial split only: minimum distance of training centres from validation
        centres (default 2 R, so training and validation disks share no peak).
    min_disks, small_classes
        See :func:`check_classes`: a region with fewer disks is an error, or dropped.
    n_jobs : int
        Parallel fits (threads).
    classifier : {"rf", "hgb"}
        See :func:`make_classifier`.
    rng : Generator, int or None
        Seed of the splits and forests.

    Returns
    -------
    Evaluation
    """
    from joblib import Parallel, delayed

    if runs < 1:
        raise InputError(f"runs must be >= 1, got {runs}")
    if split not in ("random", "spatial"):
        raise InputError(f"split must be 'random' or 'spatial', got {split!r}")
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
    groups = (f["label"].astype(str) + "|" + f["source"].astype(str)).to_numpy()
    if split == "spatial":  # metres: lon/lat tables (peak lists, geographic DEMs) are projected per group
        mx, my = metric_coordinates(f["x"].to_numpy(float), f["y"].to_numpy(float), groups,
                                    lon=f["lon"].to_numpy(float) if "lon" in f else None,
                                    lat=f["lat"].to_numpy(float) if "lat" in f else None)
    rng = np.random.default_rng(rng)
    seeds = rng.integers(0, 2**31 - 1, size=runs)
    splits = []
    for s in seeds:
        if split == "random":
            splits.append(random_split(y, max_train=max_train, max_val=max_val, val_fraction=val_fraction, rng=s))
        else:
            splits.append(spatial_split(y, mx, my, groups=groups,
                                        buffer_m=buffer_m, max_train=max_train, max_val=max_val,
                                        val_fraction=val_fraction, rng=s))
    tasks = [(None, None, i) for i in range(runs)]
    groups_cols: dict[str, NDArray] = {}
    if feature_groups:
        fr = runs if feature_runs is None else min(feature_runs, runs)
        for name, gcols in fs.groups().items():
            groups_cols[name] = np.array([cols.index(c) for c in gcols])
            tasks += [(name, groups_cols[name], i) for i in range(fr)]
    else:
        fr = 0
    it = (delayed(_fit_score)(X, y, splits[i][0], splits[i][1], gc, int(seeds[i]), n_estimators, classes, classifier)
          for _, gc, i in tasks)
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(it, total=len(tasks), desc=f"training ({split} split)", unit="fit")
    results = Parallel(n_jobs=n_jobs, prefer="threads")(it)
    accs = np.array([r[0] for (name, _, _), r in zip(tasks, results) if name is None])
    terrain = [t for (name, _, _), r in zip(tasks, results) if name is None for t in r[2]]
    conf = sum((r[1] for (name, _, _), r in zip(tasks, results) if name is None),
               np.zeros((len(classes), len(classes)), dtype=np.int64))
    per_feature = {}
    for name in groups_cols:
        a = np.array([r[0] for (n, _, _), r in zip(tasks, results) if n == name])
        per_feature[name] = float(np.mean(a[np.isfinite(a)])) if np.isfinite(a).any() else float("nan")
    recalls = {c: [] for c in classes}
    for (name, _, _), r in zip(tasks, results):
        if name is None:
            cm = r[1]
            for k, c in enumerate(classes):
                if cm[k].sum():
                    recalls[c].append(cm[k, k] / cm[k].sum())
    per_class = {c: float(np.mean(v)) if v else float("nan") for c, v in recalls.items()}
    mean_train = {c: float(np.mean([np.sum(y[s[0]] == c) for s in splits])) for c in classes}
    mean_val = {c: float(np.mean([np.sum(y[s[1]] == c) for s in splits])) for c in classes}
    params = {"runs": runs, "split": split, "classifier": classifier, "feature_set": fs.name,
              "n_estimators": n_estimators, "max_train": max_train,
              "max_val": max_val, "val_fraction": val_fraction, "radius_m": radius,
              "buffer_m": float(buffer_m) if split == "spatial" else None, "n_disks": int(len(f)),
              "dropped_classes": sorted(set(features["label"].astype(str)[~keep]))}
    ev = Evaluation(split, classes, accs, conf, per_class, per_feature, fr, mean_train, mean_val, params, terrain)
    logger.info("%s split, %d runs: mean accuracy %.3f, median %.3f", split, runs, ev.mean_accuracy,
                ev.median_accuracy)
    return ev


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
