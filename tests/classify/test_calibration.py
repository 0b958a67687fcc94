"""Calibrated probabilities and the "unknown" answer, on inputs whose answer is known analytically."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.classify.calibration import (
    Calibration,
    calibration_scores,
    fit_calibration,
    fit_temperature,
    keep_threshold,
    log_proba,
    reliability,
    softmax,
    temper,
    terrain_answers,
)


def _draw(n: int, n_classes: int, true_temperature: float, seed: int = 0):
    """Logits and labels drawn from softmax(logits / true_temperature): T = true_temperature calibrates them."""
    rng = np.random.default_rng(seed)
    z = rng.normal(0.0, 2.0, size=(n, n_classes))
    p = softmax(z / true_temperature)
    u = rng.random(n)[:, None]
    y = (u > np.cumsum(p, axis=1)).sum(axis=1)
    return z, np.minimum(y, n_classes - 1)


@pytest.mark.parametrize("true_temperature", [0.5, 1.0, 3.0])
def test_fit_temperature_recovers_the_generating_temperature(true_temperature):
    z, y = _draw(20_000, 5, true_temperature)
    assert fit_temperature(z, y) == pytest.approx(true_temperature, rel=0.06)


def test_temper_keeps_the_best_class_and_sums_to_one():
    rng = np.random.default_rng(1)
    p = rng.dirichlet(np.ones(6), size=200)
    for t in (0.3, 1.0, 4.0):
        q = temper(p, t)
        np.testing.assert_allclose(q.sum(axis=1), 1.0)
        assert (np.argmax(q, axis=1) == np.argmax(p, axis=1)).all()
    # T = 1 only floors at 1e-3 and renormalises
    np.testing.assert_allclose(temper(p, 1.0), np.exp(log_proba(p)))
    # summed over disks, the best class does not depend on T either (the per-disk normaliser is a constant)
    assert len({int(np.argmax(np.log(temper(p[:7], t)).sum(0))) for t in (0.3, 1.0, 4.0)}) == 1
    with pytest.raises(ValueError, match="temperature"):
        temper(p, 0.0)


def test_reliability_and_scores_of_an_overconfident_classifier():
    # ten disks at 0.9, six right: top-class confidence 0.9, accuracy 0.6, ECE 0.3 exactly
    p = np.tile([0.9, 0.1], (10, 1))
    y = np.array([0] * 6 + [1] * 4)
    rel = reliability(p, y, n_bins=10)
    assert rel["n"].tolist() == [0] * 8 + [10, 0]
    assert rel["accuracy"][8] == pytest.approx(0.6) and rel["confidence"][8] == pytest.approx(0.9)
    s = calibration_scores(p, y)
    assert s["ece"] == pytest.approx(0.3)
    assert s["accuracy"] == pytest.approx(0.6)
    assert s["brier"] == pytest.approx((6 * 2 * 0.1**2 + 4 * 2 * 0.9**2) / 10)
    assert s["log_loss"] == pytest.approx(-(6 * np.log(0.9) + 4 * np.log(0.1)) / 10)


def test_calibration_lowers_the_error_of_underconfident_probabilities():
    # probabilities flattened by T = 3 (like a forest's vote shares): fitting brings T back near 1/3
    z, y = _draw(6000, 4, 1.0, seed=2)
    flat = softmax(z / 3.0)
    tid = np.arange(len(y)) // 5  # terrain answers of 5 disks each (classes mixed: only the disk level matters here)
    cal = fit_calibration(flat, y, tid)
    assert cal.temperature == pytest.approx(1 / 3, rel=0.1)
    before, after = calibration_scores(flat, y), calibration_scores(cal.disk_proba(flat), y)
    assert after["ece"] < 0.5 * before["ece"] and after["log_loss"] < before["log_loss"]
    assert after["accuracy"] == before["accuracy"]


def test_thresholds_keep_the_requested_share_of_right_answers():
    c = np.linspace(0.0, 1.0, 101)
    assert keep_threshold(c, keep=0.9) == pytest.approx(0.1)
    assert keep_threshold([], keep=0.9) == 0.0
    z, y = _draw(4000, 3, 1.0, seed=3)
    p = softmax(z)
    cal = fit_calibration(p, y, np.arange(len(y)) // 4, keep=0.9)
    q = cal.disk_proba(p)
    right = np.argmax(q, axis=1) == y
    assert np.mean(q.max(axis=1)[right] >= cal.disk_threshold) == pytest.approx(0.9, abs=0.002)


def test_terrain_answers_group_disks_in_order_of_first_appearance():
    q = np.array([[0.7, 0.3], [0.2, 0.8], [0.6, 0.4], [0.1, 0.9]])
    sums, truth, best, conf = terrain_answers(np.log(q), np.array([1, 0, 1, 0]), np.array([5, 2, 5, 2]), q)
    np.testing.assert_allclose(sums, np.log([[0.7 * 0.6, 0.3 * 0.4], [0.2 * 0.1, 0.8 * 0.9]]))
    assert truth.tolist() == [1, 0] and best.tolist() == [0, 1]
    np.testing.assert_allclose(conf, [0.65, 0.85])


def test_terrain_temperature_softens_many_dependent_disks():
    # every terrain answer is one disk repeated 8 times (fully dependent disks): the summed
    # log-probabilities count its evidence 8 times, and the fitted terrain temperature is ~8
    z, y = _draw(3000, 4, 1.0, seed=4)
    p = softmax(z)
    rep = np.repeat(p, 8, axis=0)
    cal = fit_calibration(rep, np.repeat(y, 8), np.repeat(np.arange(len(y)), 8))
    assert cal.temperature == pytest.approx(1.0, rel=0.05)
    assert cal.terrain_temperature == pytest.approx(8.0, rel=0.1)


def test_calibration_round_trips_through_a_dict():
    cal = Calibration(0.5, 4.0, 0.3, 0.4, 0.95, "test")
    assert Calibration.from_dict(cal.to_dict()) == cal
    assert Calibration.from_dict(None) == Calibration()
