"""`camdirector keys create|list|revoke`: a node's keys, managed on the machine that holds its
records database (or with `--job-store` the cluster's PostgreSQL). Whoever runs this can read the
data directory, so the command may make keys of any tenant; over HTTP an admin manages only its
own tenant's (`/v1/keys`)."""

from __future__ import annotations

import argparse
import json
import sys

from camdirector.access.keys import AccessUnavailable, KeyNotFound, open_access_store
from camdirector.access.roles import ROLES
from camdirector.server_settings import ServerSettings


def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    keys = sub.add_parser("keys", help="create, list and revoke API keys (docs/security.md)")
    verbs = keys.add_subparsers(dest="keys_command", required=True)
    p = verbs.add_parser("create", help="make a key and print it alone on one line (shown this once)")
    p.add_argument("--role", required=True, choices=ROLES)
    p.add_argument("--tenant", default="default")
    p.add_argument("--name", default="", help="a label: who or what holds the key")
    p2 = verbs.add_parser("list", help="the keys (never the keys themselves), one JSON object a line")
    p2.add_argument("--tenant", help="only this tenant's")
    p3 = verbs.add_parser("revoke", help="refuse a key from now on, on every node")
    p3.add_argument("key_id", help="the id `keys list` shows (or the whole key)")
    for parser in (p, p2, p3):
        parser.add_argument("--data-dir", dest="data_dir", help="the server's data directory (its access.sqlite3)")
        parser.add_argument("--job-store", dest="job_store", help="the cluster's records database, postgresql://...")
        parser.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    try:
        settings = ServerSettings.from_env(data_dir=args.data_dir, job_store=args.job_store)
        store = open_access_store(settings.job_store, settings.data_dir)
    except (ValueError, AccessUnavailable) as exc:
        print(f"camdirector keys: {exc}", file=sys.stderr)
        return 2
    try:
        if args.keys_command == "create":
            record, text = store.create_key(args.role, args.tenant, args.name)
            store.audit(
                record.tenant,
                None,
                "key.create",
                None,
                {"key_id": record.key_id, "role": record.role, "name": record.name, "via": "cli"},
            )
            print(text)
        elif args.keys_command == "list":
            for key in store.list_keys(args.tenant):
                print(json.dumps(key.as_public()))
        else:
            key_id = args.key_id.removeprefix("cdk_").split("_", 1)[0]
            record = store.revoke(key_id)
            store.audit(record.tenant, None, "key.revoke", None, {"key_id": key_id, "via": "cli"})
            print(json.dumps(record.as_public()))
    except KeyNotFound:
        print(f"camdirector keys: no key {args.key_id!r} in {store.where}", file=sys.stderr)
        return 1
    except (ValueError, AccessUnavailable) as exc:
        print(f"camdirector keys: {exc}", file=sys.stderr)
        return 2
    finally:
        store.close()
    return 0
