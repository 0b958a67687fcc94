"""Classification inputs in lon/lat, analysis folders and CLI defaults (review B2, B3, B5, B7, B10)."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest
import shapely
from click.testing import CliRunner
from pyproj import Geod, Transformer

from orokit.analysis import write_analysis
from orokit.classify.features import concat_features, feature_table
from orokit.io.model_io import write_feature_table as write_features
from orokit.classify.peaklist import peak_geometry
from orokit.classify.train import evaluate, metric_coordinates, spatial_split
from orokit.cli.main import cli
from orokit.errors import InputError
from orokit.sampling.disks import local_metric_crs, sample_disks_in_polygon

STYLES = {"rolling": dict(prom_scale=60.0, saddle_scale_m=700.0), "alpine": dict(prom_scale=350.0,
          saddle_scale_m=2500.0), "mid": dict(prom_scale=150.0, saddle_scale_m=1400.0)}
LON0, LAT0 = 10.0, 46.0
_CACHE: dict[str, pd.DataFrame] = {}


def _metric_feats() -> pd.DataFrame:
    if "feats" not in _CACHE:
        from helpers.classify_synth import make_peaks

        tables = []
        for k, (name, kw) in enumerate(STYLES.items()):
            p = peak_geometry(make_peaks(1500, rng=10 + k, **kw))
            d = sample_disks_in_polygon(shapely.box(0, -60_000, 60_000, 0), radius_m=10_000, rng=k)
            tables.append(feature_table(p, d, label=name, source=name))
        _CACHE["feats"] = concat_features(tables)
    return _CACHE["feats"]


def _to_lonlat(x, y):
    to_ll = Transformer.from_crs(local_metric_crs(LON0, LAT0), "EPSG:4326", always_xy=True)
    return (np.asarray(v, float) for v in to_ll.transform(x, y))


def _lonlat_feats() -> pd.DataFrame:
    """The same disks, placed on the ground around (10 E, 46 N) and stored in lon/lat."""
    f = _metric_feats().copy()
    lon, lat = _to_lonlat(f["x"], f["y"])
    f["x"], f["y"], f["lon"], f["lat"] = lon, lat, lon, lat
    return f


def test_spatial_split_with_lonlat_disks_keeps_a_buffered_training_set():
    rng = np.random.default_rng(0)
    n = 40
    xm, ym = rng.uniform(0, 120_000, n), rng.uniform(0, 120_000, n)  # disks over 120 km, metres
    lon, lat = _to_lonlat(xm, ym)
    labels = np.array(["a"] * n)
    tr, va = spatial_split(labels, lon, lat, crs="EPSG:4326", buffer_m=20_000.0, rng=3)
    assert len(va) == 8 and len(tr) > 0
    g = Geod(ellps="WGS84")
    for i in tr:  # every training centre is > 20 km (on the ground) from every validation centre
        _, _, d = g.inv(np.full(len(va), lon[i]), np.full(len(va), lat[i]), lon[va], lat[va])
        assert d.min() > 20_000.0
    # the same disks in metres give the same training set size (up to the projection's distortion)
    tr_m, va_m = spatial_split(labels, xm, ym, buffer_m=20_000.0, rng=3)
    assert abs(len(tr_m) - len(tr)) <= 2


def test_metric_coordinates_keep_ground_distances():
    x = np.array([0.0, 30_000.0, 0.0])
    y = np.array([0.0, 0.0, 40_000.0])
    lon, lat = _to_lonlat(x, y)
    mx, my = metric_coordinates(lon, lat, ["g"] * 3, crs="EPSG:4326")
    d = np.hypot(mx[:, None] - mx[None], my[:, None] - my[None])
    assert d[0, 1] == pytest.approx(30_000.0, rel=1e-3) and d[1, 2] == pytest.approx(50_000.0, rel=1e-3)
    # a table without lon/lat (local grid) keeps its metres
    mx, my = metric_coordinates(x, y, ["g"] * 3, lon=np.full(3, np.nan), lat=np.full(3, np.nan))
    assert (mx == x).all() and (my == y).all()
    with pytest.raises(InputError, match="lon/lat"):
        metric_coordinates(np.array([1.0, np.nan]), np.array([1.0, 2.0]), ["g", "g"], crs="EPSG:4326")


def test_evaluate_spatial_on_lonlat_table_matches_metric_table():
    """The spatial hold-out is measurable on lon/lat tables (review B2, T2)."""
    metric = evaluate(_metric_feats(), runs=3, split="spatial", feature_groups=False, rng=0)
    geo = evaluate(_lonlat_feats(), runs=3, split="spatial", feature_groups=False, rng=0)
    assert np.isfinite(geo.accuracies).all() and geo.mean_accuracy > 0.6  # 3 classes: chance 1/3
    for c in STYLES:
        assert geo.mean_train[c] > 5
        assert geo.mean_train[c] == pytest.approx(metric.mean_train[c], rel=0.25)


def test_train_report_is_checked_before_training(tmp_path):
    """train --report refuses existing report files without --overwrite, before any run (review B7)."""
    feats = tmp_path / "f.parquet"
    write_features(_metric_feats(), feats)
    rep = tmp_path / "rep"
    (rep / "tables").mkdir(parents=True)
    (rep / "tables" / "table2.md").write_text("old report\n")
    model = tmp_path / "m.skops"
    args = ["train", str(feats), "-o", str(model), "--runs", "2", "--feature-runs", "0", "--split", "random",
            "--no-progress", "--report", str(rep)]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 2 and "--overwrite" in res.output and "table2.md" in res.output
    assert not model.exists()  # refused before training
    assert (rep / "tables" / "table2.md").read_text() == "old report\n"
    res = CliRunner().invoke(cli, args + ["--overwrite"])
    assert res.exit_code == 0, res.output
    assert model.exists() and (rep / "tables" / "table2.md").read_text() != "old report\n"


def test_classify_keeps_explicit_zero_thresholds_of_the_model(monkeypatch):
    """A model trained at eps = 0 classifies with eps = 0, not the 30 m default (review B3)."""
    import orokit.classify.inputs as inputs
    from orokit.classify.predict import classify_input

    seen = {}

    def fake(source, **kw):
        seen.update(kw)
        return pd.DataFrame()

    monkeypatch.setattr(inputs, "features_for_input", fake)

    @dataclasses.dataclass
    class Model:
        metadata: dict
        radius_m: float = 10_000.0
        feature_set: object = None

    with pytest.raises(InputError):
        classify_input(Model({"min_prominence_m": 0.0, "min_peaks": 0}), "x")
    assert seen["min_prominence_m"] == 0.0 and seen["min_peaks"] == 0
    with pytest.raises(InputError):
        classify_input(Model({}), "x")
    assert seen["min_prominence_m"] == 30.0 and seen["min_peaks"] == 20


def _geographic_analysis(make_dem, tmp_path, *, dataset: str = ""):
    """A lon/lat DEM with a void, written as GeoTIFF, analysed, analysis folder written."""
    import orokit
    from orokit.io.dem import read_dem

    rng = np.random.default_rng(5)
    n = 160
    yy, xx = np.mgrid[0:n, 0:n]
    z = np.full((n, n), 300.0)
    for _ in range(260):
        cy, cx, h, w = rng.uniform(0, n), rng.uniform(0, n), rng.uniform(40, 300), rng.uniform(1.5, 4)
        z += h * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * w**2))
    z[:, 100:] = -9999.0  # void over the eastern part
    tif = tmp_path / "geo.tif"
    da = make_dem(z.astype("float32"), res=(0.0012, 0.0008), crs="EPSG:4326")
    da.rio.write_nodata(-9999.0, inplace=True)
    da.rio.to_raster(tif)
    dem = read_dem(tif, z_units="m")
    if dataset:
        dem.attrs["dataset"] = dataset
    out = tmp_path / "ana"
    write_analysis(orokit.analyze(dem, min_prominence_m=30.0), out)
    return dem, out


def test_analysis_folder_of_a_lonlat_dem_keeps_its_voids(make_dem, tmp_path):
    """Disks from an analysis folder avoid the DEM's nodata, also for lon/lat DEMs (review B5)."""
    from orokit.classify.inputs import _analysis_domain
    from orokit.classify.peaklist import read_peaks

    dem, out = _geographic_analysis(make_dem, tmp_path)
    meta = json.loads((out / "analysis.json").read_text())
    raw = pd.read_parquet(out / "peaks.parquet", columns=["row", "col", "x", "y"])
    valid, transform, found = _analysis_domain(raw, meta)
    assert tuple(transform)[:6] == pytest.approx(tuple(dem.rio.transform())[:6])
    assert (valid == np.isfinite(dem.values)).all() and (~valid).sum() == 160 * 60
    assert found is not None and found.shape == dem.shape  # the DEM itself, for terrain features

    from orokit.classify.inputs import features_for_input

    assert read_peaks(out).crs.is_geographic
    f = features_for_input(out, radius_m=3_000.0, min_peaks=1, max_disks=40, rng=0)
    assert len(f) > 0
    east_edge = transform.c + 100 * transform.a  # first void column
    g = Geod(ellps="WGS84")
    _, _, d = g.inv(f["x"].to_numpy(), f["y"].to_numpy(), np.full(len(f), east_edge), f["y"].to_numpy())
    assert (f["x"] < east_edge).all() and (d >= 3_000.0).all()


def test_features_label_an_analysis_folder_with_its_dataset(make_dem, tmp_path):
    """`orokit features ANALYSIS_DIR` labels with analysis.json["dataset"] (review B10)."""
    _, out = _geographic_analysis(make_dem, tmp_path, dataset="my-range")
    assert json.loads((out / "analysis.json").read_text())["dataset"] == "my-range"
    ft = tmp_path / "f.parquet"
    res = CliRunner().invoke(cli, ["features", str(out), "-o", str(ft), "--radius", "3km", "--min-peaks", "1",
                                   "--no-progress"])
    assert res.exit_code == 0, res.output
    labels = set(pd.read_parquet(ft)["label"])
    assert labels == {"my-range"}
