"""Units declared in a terrain-type JSON are honoured (issue 15)."""
from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from orokit.cli.main import cli
from orokit.errors import SchemaError
from orokit.synthesis.terrain_type import load_terrain_type, loads_terrain_type


def _with_units(small_type, **units):
    d = small_type.to_dict()
    d["units"] = {**d["units"], **units}
    return d


def test_feet_and_kilometres_are_converted(small_type):
    d = _with_units(small_type, elevation="ft", prominence="ft", isolation_distance="km")
    t = loads_terrain_type(json.dumps(d))
    for feature, factor in (("elevation", 0.3048), ("prominence", 0.3048), ("isolation_distance", 1000.0)):
        assert np.allclose(t.histograms[feature].edges, np.asarray(small_type.histograms[feature].edges) * factor)
        assert t.histograms[feature].counts == small_type.histograms[feature].counts
    assert t.histograms["saddle_distance"].edges == small_type.histograms["saddle_distance"].edges
    same = loads_terrain_type(json.dumps(small_type.to_dict()))
    assert same.histograms["elevation"].edges == small_type.histograms["elevation"].edges


@pytest.mark.parametrize("units, match", [
    ({"elevation": "furlongs"}, "unknown unit 'furlongs' for elevation"),
    ({"isolation_direction": "rad"}, "directions are in 'deg'"),
    ({"dominance": "%"}, "dominance is a ratio"),
    ({"height": "m"}, "unknown feature 'height'"),
    ("m", "'units' must map features to units"),
])
def test_unknown_units_are_refused(small_type, units, match):
    d = small_type.to_dict()
    d["units"] = units
    with pytest.raises(SchemaError, match=match):
        loads_terrain_type(json.dumps(d))


def test_cli_synthesis_follows_a_type_in_feet(tmp_path, small_type):
    (tmp_path / "m.json").write_text(json.dumps(small_type.to_dict()))
    (tmp_path / "ft.json").write_text(json.dumps(_with_units(small_type, elevation="ft", prominence="ft")))
    tops = {}
    for name in ("m", "ft"):
        out = tmp_path / f"out_{name}"
        res = CliRunner().invoke(cli, ["synthesize-tree", "--type", str(tmp_path / f"{name}.json"), "--size", "15km",
                                       "--seed", "5", "--no-progress", "-o", str(out)])
        assert res.exit_code == 0, res.output
        import pandas as pd

        tops[name] = pd.read_csv(out / "peaks.csv")["elevation"].max()
    top_m = max(small_type.histograms["elevation"].edges)
    assert tops["m"] <= top_m + 1e-6 and tops["m"] > 0.5 * top_m
    assert tops["ft"] <= top_m * 0.3048 + 1e-6  # the feet type's peaks stay below its highest edge in metres
    assert load_terrain_type(tmp_path / "ft.json").histograms["elevation"].edges[-1] == pytest.approx(top_m * 0.3048)
