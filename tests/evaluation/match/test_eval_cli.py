"""`camdirector eval-match`'s command line (evaluation/match/eval_cli.py): its help names every
registered director (pipeline/match/director_registry.py), the plugins' too once imported."""

from __future__ import annotations

import pytest

from camdirector.__main__ import main
from camdirector.pipeline.match import director_registry
from camdirector.pipeline.match.director_registry import DirectorEntry, registered


def _help(capsys) -> str:
    with pytest.raises(SystemExit) as done:
        main(["eval-match", "--help"])
    assert done.value.code == 0
    return " ".join(capsys.readouterr().out.split())  # argparse wraps lines where it likes


def test_the_help_names_every_registered_director(capsys):
    text = _help(capsys)
    assert len(registered()) >= 3
    for entry in registered():
        assert f"{entry.name}: {entry.label}" in text, entry.name


def test_the_help_names_a_director_registered_later(capsys, monkeypatch):
    monkeypatch.setattr(director_registry, "_ENTRIES", dict(director_registry._ENTRIES))
    director_registry.register(DirectorEntry("studio-cam", "a studio's own director, registered by its plugin", object))
    assert "studio-cam: a studio's own director, registered by its plugin" in _help(capsys)
