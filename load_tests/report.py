"""What every benchmark here does with its result, and where they find the shared data by default."""
from __future__ import annotations

import json
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
