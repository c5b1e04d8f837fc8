"""Tenant names (infra/tenants.py): what may name a tenant, since a tenant names folders."""

from __future__ import annotations

import pytest

from camdirector.infra.tenants import DEFAULT_TENANT, check_tenant


@pytest.mark.parametrize("tenant", [DEFAULT_TENANT, "a", "acme-studio_2", "0" * 63])
def test_good_tenants_pass(tenant):
    check_tenant(tenant)


@pytest.mark.parametrize("tenant", ["", "Big Studio", "acme/arena", "-lead", "_lead", "a" * 64, "..", "acme\n"])
def test_bad_tenants_are_refused_with_what_a_tenant_may_be(tenant):
    with pytest.raises(ValueError, match="expected 1-63 characters of a-z, 0-9, '_' and '-'"):
        check_tenant(tenant)
