"""Compare computed peaks with a reference Divide Tree (e.g. the paper's TXT trees).

The paper's reference trees were made by a modified version of Kirmse's program and
not finalised (low edge peaks kept for merging; elevations off by 1-2 ft), so the
comparison is by location: the share of reference peaks that sit at or next to
(Chebyshev distance <= ``tolerance`` cells) a computed peak, and the converse for
computed peaks that are clearly prominent.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = ["near_share", "compare_with_reference"]


def near_share(points_rc: np.ndarray, targets_rc: np.ndarray, shape: tuple[int, int], tolerance: int = 1) -> float:
    """Share of cells ``points_rc`` within Chebyshev distance ``tolerance`` of a cell of ``targets_rc``."""
    points_rc = np.asarray(points_rc, dtype=np.int64).reshape(-1, 2)
    targets_rc = np.asarray(targets_rc, dtype=np.int64).reshape(-1, 2)
    if len(points_rc) == 0:
        return float("nan")
    occ = np.zeros(shape, dtype=bool)
    occ[targets_rc[:, 0], targets_rc[:, 1]] = True
    if tolerance > 0:
        occ = ndimage.binary_dilation(occ, structure=np.ones((3, 3), bool), iterations=tolerance)
    return float(occ[points_rc[:, 0], points_rc[:, 1]].mean())


def compare_with_reference(peaks_all, reference_tree, shape: tuple[int, int], *,
                           min_prominence_m: float = 100 * 0.3048, elevation_error: float = 2 * 0.3048) -> dict:
    """Shares between a peaks table computed at eps = 0 and a reference tree.

    Returns ``ref_in_ours`` (reference peaks at or next to one of ours),
    ``ours_in_ref`` (our exact peaks with prominence >= ``min_prominence_m`` +
    ``elevation_error`` at or next to a reference peak) and the counts.
    """
    ref_rc = reference_tree.peaks[["row", "col"]].to_numpy()
    ours = peaks_all[["row", "col"]].to_numpy()
    prom = peaks_all["prominence"].to_numpy(float)
    exact = peaks_all["prominence_exact"].to_numpy(bool)
    strong = ours[(prom >= min_prominence_m + elevation_error) & exact]
    return {
        "reference_peaks": int(len(ref_rc)),
        "our_peaks_eps0": int(len(ours)),
        "ref_in_ours": near_share(ref_rc, ours, shape),
        "our_strong_peaks": int(len(strong)),
        "ours_in_ref": near_share(strong, ref_rc, shape),
    }
