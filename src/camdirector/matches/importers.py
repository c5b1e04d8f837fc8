"""The match importers, as data: one entry each (its name, the endings of the file names it
reads, and where its load function lives), which `camdirector import-match` (import_cli.py) reads
to pick one by the file's name, and to say in its help what it reads.

A load function takes the demo's path and returns its match (evaluation/match/match_file.py):
`load(path: Path, *, level: str | None, rate_hz: float) -> MatchRecording`, raising a ValueError
(or an OSError) for a file it cannot read. It is named ("module:function"), not imported, so that
reading the registry loads no reader (numpy, demoparser2) before a file is read. Adding a game's
demo format is its module, with that function, and one entry in IMPORTERS.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from camdirector.evaluation.match.match_file import MatchRecording


@dataclass(frozen=True)
class MatchImporter:
    name: str  # the game, as help texts name it
    suffixes: tuple[str, ...]  # lower-case endings of the file names it reads
    load: str  # "module:function", the load function (module docstring)

    def reads(self, path: Path) -> bool:
        return path.name.lower().endswith(self.suffixes)

    def read(self, path: Path, *, level: str | None, rate_hz: float) -> MatchRecording:
        module, _, function = self.load.partition(":")
        match: MatchRecording = getattr(importlib.import_module(module), function)(path, level=level, rate_hz=rate_hz)
        return match


IMPORTERS = (
    MatchImporter("QuakeWorld", (".mvd", ".mvd.gz"), "camdirector.matches.quakeworld_mvd:load_mvd_file"),
    MatchImporter("CS2", (".dem",), "camdirector.matches.cs2_demo:load_cs2_demo_file"),
)


def readable_suffixes() -> str:
    """Every importer's endings, for messages: ".mvd, .mvd.gz or .dem"."""
    suffixes = [suffix for importer in IMPORTERS for suffix in importer.suffixes]
    return ", ".join(suffixes[:-1]) + " or " + suffixes[-1] if len(suffixes) > 1 else suffixes[0]


def importer_for(path: Path) -> MatchImporter:
    """The importer that reads `path`, by its name's ending; ValueError when none does."""
    for importer in IMPORTERS:
        if importer.reads(path):
            return importer
    raise ValueError(f"not a demo this command reads ({readable_suffixes()})")
