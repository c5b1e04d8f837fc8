"""Tenant names: what a valid one is, and the tenant of everything made without keys.

A key has one tenant (access/roles.py), and sessions, levels and jobs belong to it; a tenant's
name is part of paths (its levels' folder, precompute/tracks/registry.py), so it is checked
wherever one comes in. Here, below every process and area, so that what names things by tenant
does not import who may do what.
"""

from __future__ import annotations

import re

DEFAULT_TENANT = "default"  # the one tenant without authentication, and the keys' default
_TENANT = re.compile(r"[a-z0-9][a-z0-9_-]{0,62}")


def check_tenant(tenant: str) -> None:
    """ValueError unless `tenant` is 1-63 of a-z, 0-9, '_' and '-' (it names levels' folders)."""
    if not _TENANT.fullmatch(tenant):
        raise ValueError(f"tenant {tenant!r}: expected 1-63 characters of a-z, 0-9, '_' and '-', starting with a letter or digit")
