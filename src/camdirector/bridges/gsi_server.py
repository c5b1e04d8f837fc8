"""The HTTP endpoint Counter-Strike posts its Game State Integration payloads to, and the
gamestate_integration cfg that points the game at it.

Every POST (any path) is answered: 200 once read (accepted, or dropped as a duplicate or out of
order: gsi_tracks.py; the game only waits for an answer), 401 when its auth.token is not ours
(compared in constant time; one warning line in the log with the sender's address), 413 when its
body is over max_body_bytes (not read), 411 without a Content-Length, 400 when it is not a GSI
payload. A handler never lets an error out: the server runs on, one thread per connection
(the stdlib's ThreadingHTTPServer; the game posts one payload at a time).

The cfg (Valve Developer Community, "Counter-Strike: Global Offensive Game State Integration",
https://developer.valvesoftware.com/wiki/Counter-Strike:_Global_Offensive_Game_State_Integration):
a KeyValues block with "uri", "timeout" (s the game waits for an answer), "buffer" (s it gathers
changes before sending), "throttle" (s at least between two payloads), "heartbeat" (s at most
between two: sent even when nothing changed), "auth" {"token"} and "data" with a "1" for each
block sent. The allplayers_* blocks reach only a spectator's or an observer's client (GOTV or a
spectator slot), which is where a caster sits.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import threading
import time
from collections.abc import Callable
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from camdirector.bridges.gsi import GsiPayloadError, parse_payload
from camdirector.bridges.gsi_settings import GsiEndpointSettings
from camdirector.bridges.gsi_tracks import GsiTracks

log = logging.getLogger("camdirector.bridges.gsi")

CONFIG_TIMING_S = {"timeout": 1.0, "buffer": 0.0, "throttle": 0.1, "heartbeat": 1.0}
CONFIG_DATA = (
    "provider",
    "map",
    "round",
    "player_id",
    "player_state",
    "allplayers_id",
    "allplayers_state",
    "allplayers_match_stats",
    "allplayers_position",
)


def gamestate_config(settings: GsiEndpointSettings, name: str = "camdirector") -> str:
    """The gamestate_integration_camdirector.cfg text for the endpoint (module docstring)."""
    timing = "".join(f'    "{k}" "{v:.1f}"\n' for k, v in CONFIG_TIMING_S.items())
    data = "".join(f'        "{k}" "1"\n' for k in CONFIG_DATA)
    return (
        f'"{name}"\n{{\n    "uri" "http://{settings.host}:{settings.port}/"\n{timing}'
        f'    "auth"\n    {{\n        "token" "{settings.token}"\n    }}\n'
        f'    "data"\n    {{\n{data}    }}\n}}\n'
    )


class GsiEndpoint:
    """The endpoint serving in a thread of its own: `with GsiEndpoint(settings, tracks) as e:`;
    e.port is the port it listens on. `clock` stamps arrivals (monotonic s)."""

    def __init__(self, settings: GsiEndpointSettings, tracks: GsiTracks, clock: Callable[[], float] = time.monotonic):
        self.settings = settings
        self.refused = 0  # payloads refused for their token
        token = settings.token.encode()
        endpoint = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 (the stdlib's name)
                try:
                    self._answer(*self._take())
                except OSError:  # the game hung up
                    pass

            def _take(self) -> tuple[int, str]:
                length = self.headers.get("Content-Length")
                if length is None or not length.isdigit():
                    return 411, "a Content-Length is required"
                if int(length) > settings.max_body_bytes:
                    self.close_connection = True  # its body is not read
                    return 413, f"over {settings.max_body_bytes} bytes"
                body = self.rfile.read(int(length))
                try:
                    payload = parse_payload(body)
                except GsiPayloadError as exc:
                    return 400, str(exc)
                if not hmac.compare_digest(payload.token.encode(), token):
                    endpoint.refused += 1
                    log.warning("GSI payload from %s refused: wrong token", self.client_address[0])
                    return 401, "wrong token"
                return 200, tracks.offer(payload, hashlib.sha256(body).digest(), clock())

            def _answer(self, status: int, text: str) -> None:
                body = (text + "\n").encode()
                self.send_response(status)
                self.send_header("Content-Type", "text/plain; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, format: str, *args: object) -> None:  # noqa: A002 (the stdlib's name)
                pass  # one line per payload would drown the progress lines

        self._server = ThreadingHTTPServer((settings.host, settings.port), Handler)
        self._server.daemon_threads = True
        self.port = self._server.server_address[1]
        self._thread = threading.Thread(target=self._server.serve_forever, name="gsi-endpoint", daemon=True)

    def __enter__(self) -> GsiEndpoint:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._server.shutdown()
        self._server.server_close()
