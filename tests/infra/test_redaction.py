"""infra/redaction.py: every form libpq and Redis take a secret in is hidden, and what tells an
operator which database a line means (user, host, port, database) stays."""

from __future__ import annotations

import pytest

from camdirector.infra.redaction import redacted

SECRET = "hunter2"


@pytest.mark.parametrize(
    ("url", "shown"),
    [
        # a URL's user:password@ (libpq, redis-py), an empty user (Redis's AUTH password alone)
        (f"postgresql://cam:{SECRET}@db.local:5432/jobs", "postgresql://cam:***@db.local:5432/jobs"),
        (f"postgres://cam:{SECRET}@db.local/jobs", "postgres://cam:***@db.local/jobs"),
        (f"redis://:{SECRET}@127.0.0.1:6379/0", "redis://:***@127.0.0.1:6379/0"),
        (f"redis://default:{SECRET}@127.0.0.1:6379/0", "redis://default:***@127.0.0.1:6379/0"),
        # a password with an unencoded '@', '?' or '/' (the last is parsed by neither: still hidden)
        (f"postgresql://cam:{SECRET}@x@db.local/jobs", "postgresql://cam:***@db.local/jobs"),
        (f"postgresql://cam:{SECRET}?x@db.local/jobs", "postgresql://cam:***@db.local/jobs"),
        (f"postgresql://cam:{SECRET}/x@db.local/jobs", "postgresql://cam:***@db.local/jobs"),
        # query parameters: password, sslpassword, sslkey (a client key's path), any case, percent-encoded
        (f"postgresql://cam@db.local/jobs?password={SECRET}", "postgresql://cam@db.local/jobs?password=***"),
        (
            f"postgresql://cam@db.local/jobs?sslmode=require&sslpassword={SECRET}&sslkey=/etc/{SECRET}.key&application_name=cd",
            "postgresql://cam@db.local/jobs?sslmode=require&sslpassword=***&sslkey=***&application_name=cd",
        ),
        (f"postgresql://cam@db.local/jobs?PASSWORD={SECRET}", "postgresql://cam@db.local/jobs?PASSWORD=***"),
        (f"postgresql://cam@db.local/jobs?pass%77ord={SECRET}", "postgresql://cam@db.local/jobs?pass%77ord=***"),
        (f"redis://127.0.0.1:6379/0?password={SECRET}", "redis://127.0.0.1:6379/0?password=***"),
        (f"redis://127.0.0.1:6379?password={SECRET}#frag", "redis://127.0.0.1:6379?password=***#frag"),
        (f"unix:///run/redis.sock?db=0&password={SECRET}", "unix:///run/redis.sock?db=0&password=***"),
        # both at once
        (
            f"postgresql://cam:{SECRET}@h1:5432,h2:5433/jobs?password={SECRET}",
            "postgresql://cam:***@h1:5432,h2:5433/jobs?password=***",
        ),
        # libpq's key=value words: bare, quoted (with an escaped quote and spaces), spaces around '='
        (f"host=db.local user=cam password={SECRET} dbname=jobs", "host=db.local user=cam password=*** dbname=jobs"),
        (f"password='{SECRET} it\\'s' host=db.local", "password=*** host=db.local"),
        (f"host=db.local sslpassword = {SECRET} sslkey=/k/{SECRET}", "host=db.local sslpassword = *** sslkey=***"),
    ],
)
def test_every_form_of_a_secret_is_hidden(url, shown):
    assert redacted(url) == shown
    assert SECRET not in redacted(url)


@pytest.mark.parametrize(
    "url",
    [
        "",
        "postgresql://camdirector@127.0.0.1:5432/camdirector",
        "redis://127.0.0.1:6379/0",
        "postgresql://db.local/jobs?sslmode=require&connect_timeout=5",
        "host=db.local user=cam dbname=jobs",
    ],
)
def test_a_string_without_secrets_is_unchanged(url):
    assert redacted(url) == url
