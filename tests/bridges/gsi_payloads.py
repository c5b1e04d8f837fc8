"""The recorded GSI payloads of tests/data/gsi (SOURCES.md) and the states they describe."""

from __future__ import annotations

import copy
import json
from pathlib import Path

DATA = Path(__file__).resolve().parents[1] / "data" / "gsi"
MIRAGE = DATA / "csgo_gsi_radar_de_mirage_round9.json"


def merged(current: dict, previously: dict) -> dict:
    """The payload before `current`: its `previously` block (the old values of what changed)
    laid over it, without the diff blocks."""
    out = copy.deepcopy(current)
    for key, old in previously.items():
        if isinstance(old, dict) and isinstance(out.get(key), dict):
            out[key] = merged(out[key], old)
        else:
            out[key] = old
    return out


def mirage_sequence(token: str) -> list[dict]:
    """The two states of the recorded payload, in the game's order, with our token: the one before
    (rebuilt from `previously`) and the payload itself."""
    payload = json.loads(MIRAGE.read_text())
    before = merged({k: v for k, v in payload.items() if k not in ("previously", "added")}, payload["previously"])
    now = {k: v for k, v in payload.items() if k not in ("previously", "added")}
    return [{**p, "auth": {"token": token}} for p in (before, now)]
