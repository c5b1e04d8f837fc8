"""The match importers' registry (matches/importers.py) and `camdirector import-match` over it:
an importer is picked by the file's name, and one registered in a test alone (a module with its
load function, and an entry) is read end to end by the command."""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from camdirector.__main__ import main
from camdirector.evaluation.match.match_file import load_match
from camdirector.matches import importers
from camdirector.matches.importers import IMPORTERS, MatchImporter, importer_for, readable_suffixes

TOY_IMPORTER = textwrap.dedent('''
    import numpy as np

    from camdirector.evaluation.match.match_file import MatchPlayer, MatchRecording


    def load_toy_file(path, *, level, rate_hz):
        """A .toy file: one line, the number of frames; one player standing at the origin."""
        frames = int(path.read_text())
        if frames < 2:
            raise ValueError("a toy match has at least 2 frames")
        return MatchRecording(level=level or "toyland", seed=0, rate_hz=rate_hz,
                              players=[MatchPlayer("p00", 0, 1.8, 0.4, "toy")],
                              time_s=np.arange(frames) / rate_hz, positions_world=np.zeros((frames, 1, 3)),
                              rotations_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (frames, 1, 1)),
                              alive=np.ones((frames, 1), bool), events=[])
''')


@pytest.mark.parametrize("name, game", [("duel.mvd", "QuakeWorld"), ("DUEL.MVD.GZ", "QuakeWorld"), ("final.dem", "CS2")])
def test_the_importer_is_picked_by_the_files_name(name, game):
    assert importer_for(Path("demos") / name).name == game


def test_a_file_no_importer_reads_is_refused_naming_what_is_read():
    assert readable_suffixes() == ".mvd, .mvd.gz or .dem"
    with pytest.raises(ValueError, match=r"^not a demo this command reads \(\.mvd, \.mvd\.gz or \.dem\)$"):
        importer_for(Path("match.mp4"))


def test_every_entry_names_a_load_function_that_exists():
    import importlib

    for importer in IMPORTERS:
        module, _, function = importer.load.partition(":")
        assert callable(getattr(importlib.import_module(module), function)), importer


def test_an_importer_registered_in_a_test_alone_is_read_end_to_end(tmp_path, monkeypatch, capsys):
    (tmp_path / "toy_importer.py").write_text(TOY_IMPORTER)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(importers, "IMPORTERS", (*IMPORTERS, MatchImporter("Toy", (".toy",), "toy_importer:load_toy_file")))
    demo, out = tmp_path / "m.toy", tmp_path / "m.npz"
    demo.write_text("12\n")
    assert main(["import-match", str(demo), "--level", "arena", "--rate-hz", "30", "--out", str(out)]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["level"] == "arena" and printed["frames"] == 12 and printed["players"] == [{"name": "toy", "team": 0}]
    match = load_match(out)
    assert match.rate_hz == 30.0 and match.level == "arena"
    np.testing.assert_allclose(match.time_s, np.arange(12) / 30.0)

    demo.write_text("1\n")  # its ValueError is the command's bad input: status 2, no traceback
    assert main(["import-match", str(demo), "--out", str(out)]) == 2
    assert "at least 2 frames" in capsys.readouterr().err
    sys.modules.pop("toy_importer", None)
