"""matches/mvd_wire.py's live decoder (MvdStream), as the QTV bridge feeds it: a real demo cut into
random chunks decodes to exactly what parse_mvd reads from the whole file; bytes that are no MVD,
or garbage after a good start, are an MvdError at the stream's offset."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from camdirector.matches.mvd_wire import MvdError, MvdStream, parse_mvd

DEMO = Path(__file__).parents[1] / "data" / "real_matches" / "2on2_sf_vs_red_frobodm2_220104-0915.mvd.gz"


@pytest.fixture(scope="module")
def demo_bytes() -> bytes:
    return gzip.decompress(DEMO.read_bytes())


def test_random_chunks_decode_as_the_whole_file(demo_bytes):
    whole = parse_mvd(demo_bytes)
    stream = MvdStream()
    rng = np.random.default_rng(7)
    samples: dict[int, list] = {}
    stats: dict[int, list] = {}
    deaths = []
    pos = 0
    while pos < len(demo_bytes):
        n = int(rng.integers(1, 3000))
        update = stream.feed(demo_bytes[pos : pos + n])
        pos += n
        for slot, track in update.tracks.items():
            samples.setdefault(slot, []).append(
                np.column_stack([track.time_s, track.origin_units, track.angles_deg, track.jump, track.dead])
            )
        for slot, s in update.stats.items():
            stats.setdefault(slot, []).append(np.column_stack([s.time_s, s.values]))
        deaths += update.deaths
    assert stream.pending_bytes == 0
    assert update.time_s == whole.duration_s
    assert update.players == whole.players
    for p in whole.players:
        t = whole.tracks[p.slot]
        expected = np.column_stack([t.time_s, t.origin_units, t.angles_deg, t.jump, t.dead])
        np.testing.assert_array_equal(np.concatenate(samples[p.slot]), expected)
        st = whole.stats[p.slot]
        np.testing.assert_array_equal(np.concatenate(stats[p.slot]), np.column_stack([st.time_s, st.values])[1:])
    assert [d for d in deaths if d.killer in whole.tracks or d.victim in whole.tracks] == whole.deaths
    assert len(whole.deaths) > 30  # the match's frags, not an empty comparison


def test_not_an_mvd_is_an_error_at_once():
    with pytest.raises(MvdError, match="not an MVD demo"):
        MvdStream().feed(b"HTTP/1.1 200 OK\r\nContent-Type: text/html\r\n\r\n")


def test_garbage_after_a_good_start_names_its_stream_offset(demo_bytes):
    probe = MvdStream()
    probe.feed(demo_bytes[:5000])
    boundary = 5000 - probe.pending_bytes  # where a block begins
    stream = MvdStream()
    stream.feed(demo_bytes[:boundary])
    with pytest.raises(MvdError, match="unknown block type 7") as caught:
        stream.feed(bytes([0, 7]) + b"\xff" * 64)
    assert caught.value.offset == boundary + 1
