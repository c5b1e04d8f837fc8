"""The one redaction of the records database's and Redis's connection strings (`--job-store`,
`--job-queue`, `--checkpoint-store`, a level index's `--records-url`) for every log line and
message that names one: the password of a URL's `user:password@`, and the values of `password`,
`sslpassword` and `sslkey` (a client key's path) whether they come as a URL's query parameters
(libpq's and redis-py's `?password=`) or as libpq's `key=value` words. What else the string holds
(user, host, port, database) stays, so an operator can tell which database a log line means; a
client is told none of it (the edges answer without the string at all)."""

from __future__ import annotations

import re
from urllib.parse import unquote

HIDDEN = "***"
_SECRET_KEYS = frozenset({"password", "sslpassword", "sslkey"})
# A URL query parameter (its key maybe percent-encoded, as libpq accepts), and a libpq key=value
# word (its value a single-quoted string with backslash escapes, or up to a space): `lead` is all
# but the value.
_QUERY_PARAM = re.compile(r"(?P<lead>[?&;](?P<key>[^&;=#]*)=)[^&;#]*")
_CONNINFO_WORD = re.compile(r"(?P<lead>(?:^|\s)(?P<key>\w+)\s*=\s*)(?:'(?:\\.|[^'\\])*'?|\S*)")


def redacted(url: str) -> str:
    """`url` (a postgresql://, redis:// or other URL, or a libpq key=value string) with its
    secrets replaced by `***` (module docstring)."""
    if "://" not in url:
        return _CONNINFO_WORD.sub(_hide_if_secret, url)
    scheme, sep, rest = url.partition("://")
    # libpq and urllib end the user info at the last '@' before the path's '/'; a password that
    # holds an unencoded '/' (which neither parses) ends it at the last '@' before the query.
    path_at = rest.find("/") if "/" in rest else len(rest)
    query_at = rest.find("?") if "?" in rest else len(rest)
    at = rest.rfind("@", 0, path_at)
    if at < 0:
        at = rest.rfind("@", 0, query_at)
    userinfo = rest[:at] if at >= 0 else ""
    if ":" in userinfo:
        rest = f"{userinfo.split(':', 1)[0]}:{HIDDEN}{rest[at:]}"
    return scheme + sep + _QUERY_PARAM.sub(_hide_if_secret, rest)


def _hide_if_secret(match: re.Match[str]) -> str:
    secret = unquote(match["key"]).strip().lower() in _SECRET_KEYS
    return match["lead"] + HIDDEN if secret else match[0]
