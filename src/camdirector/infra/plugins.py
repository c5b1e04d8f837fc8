"""Plugins: Python modules a server imports at start, in the front process and in every worker
process (spawned: each imports them again from the settings it receives), and `eval-match` in its
own process. A plugin extends the service by registering itself on import (a studio's own match
director: pipeline/match/director_registry.py `register`); nothing else calls it.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable


def import_plugins(modules: Iterable[str]) -> None:
    """Imports each module (once: Python keeps it in sys.modules). ValueError naming the module
    and why for one that cannot be imported or fails while registering."""
    for name in modules:
        try:
            importlib.import_module(name)
        except Exception as exc:  # noqa: BLE001 - whatever a plugin raises, start refuses it with its name
            raise ValueError(f"plugin {name!r} could not be imported: {type(exc).__name__}: {exc}") from exc
