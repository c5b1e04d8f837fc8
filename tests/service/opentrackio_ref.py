"""SMPTE's OpenTrackIO reference material (../shared/third_party/opentrackio): the 1.0.1 schema and
the reference receiver, as the judges of what the pose outputs emit. Imported from where it lies,
never copied; skipped with a reason where that folder is absent, a failure under
CAMDIRECTOR_REQUIRE_SHARED_DATA=1 (as tests/conftest.py's `shared_data`)."""

from __future__ import annotations

import contextlib
import importlib
import io
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import jsonschema
import pytest

OPENTRACKIO_DIR = Path(__file__).resolve().parents[3] / "shared" / "third_party" / "opentrackio"


@dataclass
class Reference:
    lib: ModuleType  # opentrackio_lib: fletcher16, OpenTrackIOProtocol, constants
    receiver: ModuleType  # opentrackio_receiver: OpenTrackIOPacketReceiver._parse_packet
    schema_text: str
    validator: jsonschema.Draft202012Validator

    def new_receiver(self):
        """A receiver of one stream (its duplicate check compares each packet's sequence number
        with the previous one's); `feed` gives it packets."""
        return self.receiver.OpenTrackIOPacketReceiver(
            {"verbose": False, "multicast_group": "", "port": 0, "schema_text": self.schema_text}
        )

    def feed(self, receiver, packets: list[bytes]) -> dict | None:
        """The sample SMPTE's receiver reassembles and decodes from one payload's packets (None if
        it rejected them); what it prints (its time source notice, its rejections) is swallowed."""
        receiver.protocol.pd = None
        with contextlib.redirect_stdout(io.StringIO()):
            accepted = [receiver._parse_packet(packet) for packet in packets]
        return receiver.protocol.pd if all(accepted) else None

    def errors(self, sample: dict) -> list[str]:
        """Where the sample breaks SMPTE's schema (empty: valid)."""
        return [f"{'/'.join(map(str, e.absolute_path))}: {e.message}" for e in self.validator.iter_errors(sample)]


def load_reference() -> Reference:
    if not (OPENTRACKIO_DIR / "schema.json").is_file():
        if os.environ.get("CAMDIRECTOR_REQUIRE_SHARED_DATA") == "1":
            pytest.fail(f"{OPENTRACKIO_DIR} is required (CAMDIRECTOR_REQUIRE_SHARED_DATA=1)")
        pytest.skip(f"{OPENTRACKIO_DIR} is absent: SMPTE's OpenTrackIO schema and reference receiver are not in this clone")
    if str(OPENTRACKIO_DIR) not in sys.path:
        sys.path.append(str(OPENTRACKIO_DIR))  # the receiver does `from opentrackio_lib import *`
    schema_text = (OPENTRACKIO_DIR / "schema.json").read_text()
    schema = json.loads(schema_text)
    jsonschema.Draft202012Validator.check_schema(schema)
    return Reference(
        importlib.import_module("opentrackio_lib"),
        importlib.import_module("opentrackio_receiver"),
        schema_text,
        jsonschema.Draft202012Validator(schema),
    )
