"""The CLI as a user meets it: shared options behave the same in every command, help order,
manifest dataset names wherever a DEM is read, one-line warnings."""
from __future__ import annotations

import importlib
import logging
import subprocess
import sys
import warnings

import click
import numpy as np
import pytest
from click.testing import CliRunner

from orokit.cli import options
from orokit.cli.main import COMMANDS, REPORT_COMMANDS, SHORT_HELP, USER_COMMANDS, cli, setup_logging


def _command(name: str) -> click.Command:
    module, attr = COMMANDS[name].split(":")
    return getattr(importlib.import_module(module), attr)


def _all_commands() -> list[tuple[str, click.Command]]:
    out = []
    for name in COMMANDS:
        cmd = _command(name)
        if isinstance(cmd, click.Group):
            out += [(f"{name} {sub}", c) for sub, c in cmd.commands.items()]
        else:
            out.append((name, cmd))
    return out


def _option(cmd: click.Command, flag: str) -> click.Option | None:
    for p in cmd.params:
        if isinstance(p, click.Option) and flag in p.opts + p.secondary_opts:
            return p
    return None


def test_every_command_has_a_short_help_and_one_section():
    assert set(SHORT_HELP) == set(COMMANDS)
    assert not set(USER_COMMANDS) & set(REPORT_COMMANDS)


def test_help_lists_user_commands_first():
    res = CliRunner().invoke(cli, ["--help"])
    assert res.exit_code == 0, res.output
    text = res.output
    report_section = text.index("Report-building commands")
    for name in USER_COMMANDS:
        assert 0 < text.index(f"  {name} ") < report_section, name
    for name in REPORT_COMMANDS:
        assert text.index(f"  {name} ") > report_section, name


@pytest.mark.parametrize("name,cmd", _all_commands(), ids=[n for n, _ in _all_commands()])
def test_shared_options_are_the_shared_definitions(name, cmd):
    seed = _option(cmd, "--seed")
    if seed is not None:
        assert isinstance(seed.type, click.IntRange) and seed.type.min == 0, name
        assert "the same seed gives the same result [default: " in seed.help, name
        if seed.default is None:
            assert "fresh entropy, recorded in" in seed.help, name
    overwrite = _option(cmd, "--overwrite")
    if overwrite is not None:
        assert overwrite.is_flag and overwrite.help.startswith("Replace "), name
        assert "existing outputs are kept" in overwrite.help, name
    progress = _option(cmd, "--progress")
    if progress is not None:
        assert "--no-progress" in progress.secondary_opts and progress.default is True, name
    assert _option(cmd, "--no-progress") is None or progress is not None, name  # never a lone --no-progress flag
    for flag in ("--min-prominence", "--cell-size", "--resolution", "--radius", "--size", "--lambda",
                 "--txt-cell-size", "--real-cell-size"):
        opt = _option(cmd, flag)
        if opt is not None:
            assert isinstance(opt.type, options.Length), (name, flag)


@pytest.mark.parametrize("name", [n for n, c in _all_commands() if _option(c, "--min-prominence") is not None])
def test_min_prominence_is_a_length_everywhere(name):
    opt = _option(dict(_all_commands())[name], "--min-prominence")
    assert opt.type.convert("100ft", opt, None) == pytest.approx(30.48)
    assert opt.type.convert("0", opt, None) == 0.0
    assert opt.type.convert("1km", opt, None) == 1000.0
    with pytest.raises(click.BadParameter):
        opt.type.convert("-5m", opt, None)


def test_length_parser_knows_feet_and_refuses_other_units():
    assert options.parse_length("100 ft") == pytest.approx(30.48)
    assert options.parse_length("3x2ft", pair=True) == (pytest.approx(0.9144), pytest.approx(0.6096))
    for bad in ("100 miles", "5 yd", "0m", "ft"):
        with pytest.raises(click.BadParameter):
            options.parse_length(bad)


def test_refuse_existing_names_the_file(tmp_path):
    f = tmp_path / "x.json"
    options.refuse_existing(f, None, overwrite=False)  # nothing exists: fine
    f.write_text("{}")
    with pytest.raises(click.UsageError, match="x.json already exists; pass --overwrite"):
        options.refuse_existing(f, overwrite=False)
    options.refuse_existing(f, overwrite=True)


def test_unknown_input_name_lists_the_datasets(tmp_path):
    for args in (["analyze", "no-such-dem", "-o", str(tmp_path / "a")],
                 ["features", "no-such-dem", "-o", str(tmp_path / "f.parquet")],
                 ["type", "no-such-dem", "-o", str(tmp_path / "t.json")]):
        res = CliRunner().invoke(cli, args)
        assert res.exit_code == 2, res.output
        assert "neither an existing file or folder nor a DEM of the datasets manifest" in res.output
        assert "gobi" in res.output and "Traceback" not in res.output


@pytest.mark.realdata
def test_dataset_names_resolve_with_manifest_units(real_data):
    real_data("gobi")
    src = options.resolve_input("gobi")
    assert src.dataset == "gobi" and src.z_units == "ft" and src.cell_size_m == pytest.approx(92.6, rel=0.01)
    assert src.path.is_file() and str(src) == "gobi" and src.label == "gobi"
    assert src.dem_options(None, None) == ("ft", src.cell_size_m)
    with pytest.raises(click.UsageError, match="drop --z-units m"):
        src.dem_options("m", None)
    with pytest.raises(click.UsageError, match="drop --cell-size"):
        src.dem_options(None, 30.0)
    dem = src.read_dem()
    assert dem.attrs["dataset"] == "gobi" and dem.shape == (648, 648)
    assert options.resolve_input(src.path).dataset is None  # an existing path wins over a name


@pytest.mark.realdata
def test_features_accepts_a_dataset_name(real_data, tmp_path):
    real_data("gobi")
    out = tmp_path / "f.parquet"
    res = CliRunner().invoke(cli, ["features", "gobi", "-o", str(out), "--max-disks", "3", "--min-peaks", "1",
                                   "--no-progress"])
    assert res.exit_code == 0, res.output
    import pandas as pd

    table = pd.read_parquet(out)
    assert len(table) >= 1 and set(table["label"]) == {"gobi"}


def test_warnings_print_one_line(capsys):
    from orokit.errors import OrokitWarning

    before = warnings.formatwarning
    try:
        setup_logging(0, False)
        fmt = warnings.formatwarning
        assert fmt("4 disks skipped:\n fewer than 20 peaks", OrokitWarning, "x.py", 3) == \
            "Warning: 4 disks skipped: fewer than 20 peaks\n"
        assert fmt("old API", DeprecationWarning, "x.py", 3) == "Warning: old API (DeprecationWarning)\n"
        logging.getLogger("orokit.test").warning("a logged warning")
        assert capsys.readouterr().err == "Warning: a logged warning\n"
        with pytest.warns(OrokitWarning, match="recorded"):  # recorders still see every warning
            warnings.warn("recorded", OrokitWarning, stacklevel=1)
        setup_logging(0, True)  # -q: errors only
        assert warnings.formatwarning("hidden", OrokitWarning, "x.py", 3) == ""
        logging.getLogger("orokit.test").warning("hidden too")
        assert capsys.readouterr().err == ""
    finally:
        warnings.formatwarning = before
        logging.getLogger().handlers = [h for h in logging.getLogger().handlers
                                        if not getattr(h, "_orokit_cli", False)]


@pytest.mark.realdata
def test_a_warning_is_one_line_in_a_real_run(real_data, tmp_path):
    real_data("gobi")
    proc = subprocess.run([sys.executable, "-m", "orokit.cli.main", "features", "gobi", "--max-disks", "2",
                           "--min-peaks", "400", "--no-progress", "-o", str(tmp_path / "f.parquet")],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.splitlines() == [
        "Warning: 2 of 2 disks of 'gobi' have fewer than 400 peaks with prominence >= 30 m and were skipped "
        "(min_peaks / --min-peaks)"], proc.stderr


@pytest.mark.realdata
def test_png_with_cell_size_has_no_rasterio_warning(real_data, tmp_path):
    png = real_data("dems/gobi.png")
    out = tmp_path / "a"
    proc = subprocess.run([sys.executable, "-m", "orokit.cli.main", "analyze", str(png), "--z-units", "ft",
                           "--cell-size", "92.6m", "--min-prominence", "300ft", "--no-isolation", "--no-progress",
                           "-o", str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "NotGeoreferenced" not in proc.stderr and "geotransform" not in proc.stderr, proc.stderr
    assert "warnings.warn" not in proc.stderr and "Traceback" not in proc.stderr
    assert (out / "analysis.json").is_file()


#: commands whose work takes long enough to want a progress bar (the DEM readers and renderers)
LONG_COMMANDS = ["analyze", "features", "classify", "train", "type", "synthesize", "synthesize-tree", "render",
                 "validate", "compare", "data fetch"]


@pytest.mark.parametrize("name", LONG_COMMANDS)
def test_long_commands_offer_progress(name):
    assert _option(dict(_all_commands())[name], "--progress") is not None, name


def test_tiny_chunks_are_refused_with_what_the_option_means(make_dem, tmp_path):
    """``--chunks 1`` made one chunk per cell (a 300 x 300 raster: 90,000 chunks, stopped after 3.5 min at
    0.98 GB; in memory 5 s): refused, saying N is a side in cells and what to give instead."""
    tif = tmp_path / "dem.tif"
    make_dem(np.random.default_rng(0).normal(size=(30, 30)).astype("float32")).rio.to_raster(tif)
    for n in ("1", "15", "0", "-3"):
        res = CliRunner().invoke(cli, ["analyze", str(tif), "--chunks", n, "-o", str(tmp_path / "a")])
        assert res.exit_code == 2, res.output
        assert f"must be at least 16, got {n}" in res.output and "not a number of chunks" in res.output
        assert "--chunks 1024" in res.output and "Traceback" not in res.output
        assert not (tmp_path / "a" / "analysis.json").exists()
    res = CliRunner().invoke(cli, ["analyze", str(tif), "--chunks", "16", "--no-progress", "-o", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    # a side beyond any raster is one chunk (before: 1e20 ended in numpy's "ufunc 'isnan' not supported")
    res = CliRunner().invoke(cli, ["analyze", str(tif), "--chunks", "1" + "0" * 20, "--no-progress", "-o",
                                   str(tmp_path / "b")])
    assert res.exit_code == 0, res.output
