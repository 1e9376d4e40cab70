"""``warpsky render --help`` fits on a few screens, and ``--help-settings NAME`` prints the settings tables of one
technique or pass (``all``: every one), or exits 2 naming the valid names."""

from __future__ import annotations

import pytest

from warpsky.cli.main import main


def _help(argv: list[str], capsys, monkeypatch) -> tuple[int, str, str]:
    monkeypatch.setenv("COLUMNS", "80")  # argparse wraps to the terminal; 80 columns is the usual narrowest
    with pytest.raises(SystemExit) as stop:
        main(argv)
    captured = capsys.readouterr()
    return stop.value.code, captured.out, captured.err


def test_render_help_is_at_most_100_lines_of_80_columns(capsys, monkeypatch):
    code, out, _ = _help(["render", "--help"], capsys, monkeypatch)
    lines = out.splitlines()
    assert code == 0
    assert len(lines) <= 100, len(lines)
    assert max(len(line) for line in lines) <= 80
    assert "slice_count" not in out and "fog.nodes" not in out, "the settings tables are behind --help-settings"
    assert "--help-settings" in lines[-1], "the last line says how to see a technique's settings"


def test_help_settings_hybrid_lists_its_settings_only(capsys, monkeypatch):
    code, out, err = _help(["render", "--help-settings", "hybrid"], capsys, monkeypatch)
    assert code == 0 and not err
    assert "target_error" in out and "time_budget" in out and "hybrid (default):" in out
    assert "slice_count" not in out and "fog.nodes" not in out  # slicing's and the fog pass's


def test_help_settings_of_a_pass_carries_its_prefix(capsys, monkeypatch):
    code, out, _ = _help(["render", "--help-settings", "fog"], capsys, monkeypatch)
    assert code == 0
    assert "fog pass (prefix fog.;" in out and "fog.cut_depth" in out and "target_error" not in out


def test_help_settings_all_is_every_technique_and_pass(capsys, monkeypatch):
    from warpsky.render.registry import pass_classes, technique_names

    code, out, _ = _help(["render", "--help-settings", "all"], capsys, monkeypatch)
    assert code == 0
    for name in technique_names():
        assert f"\n  {name}" in out, name
    for cls in pass_classes():
        if cls.Settings is not None:
            assert f"\n  {cls.name} pass (prefix" in out, cls.name


def test_help_settings_of_an_unknown_name_exits_2_listing_the_valid_names(capsys, monkeypatch):
    code, out, err = _help(["render", "--help-settings", "hybird"], capsys, monkeypatch)
    assert code == 2 and not out
    assert len(err.strip().splitlines()) == 1, err
    assert "'hybird'" in err
    for name in ("hybrid", "path_tracer", "single_scatter", "slicing", "stratiform", "deck", "fog", "all"):
        assert name in err
