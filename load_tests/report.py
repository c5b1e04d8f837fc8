"""What every benchmark here does with its result, and where they find the shared data by default."""
from __future__ import annotations

import json
import sys
from pathlib import Path

# ../shared/data beside the repository (never copied into it)
SHARED_DATA_DIR = Path(__file__).resolve().parents[2] / "shared" / "data"


def emit(result: dict, path: Path | None) -> None:
    """Print the result as JSON, and write the same text to path when one is given."""
    text = json.dumps(result, indent=1)
    print(text)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def shared_subfolder(data_dir: Path, name: str, program: str) -> Path | None:
    """data_dir / name, or None after saying on stderr that it is missing (the caller exits 2)."""
    folder = data_dir / name
    if not folder.is_dir():
        print(f"{program}: no {name} folder at {folder} (pass --data-dir)", file=sys.stderr)
        return None
    return folder
