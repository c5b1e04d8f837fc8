"""`camdirector keys create|list|revoke|rotate-secret`: a node's keys, and the secret that signs the
dashboard's logins, managed on the machine that holds its records database (or with `--job-store`
the cluster's PostgreSQL). Whoever runs this can read the data directory, so the command may make
keys of any tenant; over HTTP an admin manages only its own tenant's (`/v1/keys`)."""

from __future__ import annotations

import argparse
import json
import os
import sys

from camdirector.access.keys import LOGIN_SECRET, AccessUnavailable, KeyNotFound, open_access_store, read_key_file, split_key
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
    which = p3.add_mutually_exclusive_group(required=True)
    which.add_argument("key_id", nargs="?", help="the id `keys list` shows (a whole key works too, but shows in `ps`)")
    which.add_argument("--key-file", dest="key_file", metavar="PATH", help="revoke the key in this file (-: read it from stdin)")
    which.add_argument(
        "--key-from-env",
        dest="key_from_env",
        action="store_true",
        help="revoke the key in the CAMDIRECTOR_KEY environment variable",
    )
    p4 = verbs.add_parser(
        "rotate-secret", help="replace the secret that signs the dashboard's logins: every login ends, on every node"
    )
    for parser in (p, p2, p3, p4):
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
        elif args.keys_command == "rotate-secret":
            store.rotate_secret(LOGIN_SECRET)
            print("the dashboard's login secret is replaced: every login ends on every node at its next poll (0.25 s)")
        else:
            key_id = _revoked_id(args)
            record = store.revoke(key_id)
            store.audit(record.tenant, None, "key.revoke", None, {"key_id": key_id, "via": "cli"})
            print(json.dumps(record.as_public()))
    except KeyNotFound as exc:
        print(f"camdirector keys: no key {exc.args[0]!r} in {store.where}", file=sys.stderr)
        return 1
    except (ValueError, AccessUnavailable) as exc:
        print(f"camdirector keys: {exc}", file=sys.stderr)
        return 2
    finally:
        store.close()
    return 0


def _revoked_id(args: argparse.Namespace) -> str:
    """The id of the key `keys revoke` names: given, or read from a whole key (an argument, a
    file, standard input or CAMDIRECTOR_KEY). ValueError for an empty CAMDIRECTOR_KEY."""
    if args.key_file is not None:
        key = read_key_file(args.key_file)
    elif args.key_from_env:
        key = os.environ.get("CAMDIRECTOR_KEY", "").strip()
        if split_key(key) is None:
            raise ValueError("--key-from-env: CAMDIRECTOR_KEY does not hold a key (cdk_<id>_<secret>)")
    else:
        key = args.key_id
    return key.removeprefix("cdk_").split("_", 1)[0]
