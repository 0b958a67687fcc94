"""Fixtures of the classification tests."""
from __future__ import annotations

import pytest
from helpers.classify_synth import make_peaks


@pytest.fixture
def peaks_factory():
    return make_peaks
