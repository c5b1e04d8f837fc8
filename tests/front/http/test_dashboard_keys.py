"""The dashboard with keys (issue 26), in a real browser (Chromium, driven by Playwright) against a
real server with authentication on. A director of one tenant logs in through the form once, sees
that tenant's sessions and never another's, watches a monitor through the login cookie, stays
logged in across a reload and logs out; a key revoked meanwhile brings the form back with the
server's reason. A viewer finds the take, release and style buttons off, saying why, and a take or
a style change forced anyway is refused with the server's message in the page. The login cookie is
HttpOnly and SameSite=Strict, holds no secret, and a change that carries it without the CSRF token
(or from another origin) is refused. Against a `--no-auth` server no form is shown at all.

The sessions are made over gRPC with engine keys of each tenant (docs/security.md); the other keys
with `camdirector keys create` on the server's data directory. Where Chromium is absent the tests
skip as test_dashboard.py's do (its `browser` fixture).
"""

from __future__ import annotations

import subprocess
import sys
from types import SimpleNamespace

import pytest

from camdirector.access.roles import Verb
from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb
from tests.front.http import test_dashboard
from tests.service.test_match_sessions import frames as match_frames
from tests.service.test_match_sessions import match_request
from tests.service.wire_client import GrpcRaw, two_target_request, walk

playwright = pytest.importorskip("playwright.sync_api")
expect = playwright.expect

browser = test_dashboard.browser  # the same Chromium, skipped or required the same way
TENANT_A, TENANT_B = "studio-a", "studio-b"
COOKIE = "camdirector_login"  # front/http/auth.py


class KeyedGrpc(GrpcRaw):
    """The wire client, every call carrying a key as gRPC metadata (docs/security.md)."""

    def __init__(self, address: str, key: str):
        super().__init__(address)
        self.metadata = (("authorization", f"Bearer {key}"),)

    def call(self, rpc: str, request):
        return getattr(self.stub, rpc)(request, timeout=30, metadata=self.metadata)

    def stream(self, frames):
        return list(self.stub.StreamFrames(iter(frames), timeout=60, metadata=self.metadata))


def camdirector(data_dir, *args: str) -> str:
    """`camdirector ARGS --data-dir DATA_DIR`'s output, stripped."""
    done = subprocess.run(
        [sys.executable, "-m", "camdirector", *args, "--data-dir", str(data_dir)], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def key_id(key: str) -> str:
    return key.removeprefix("cdk_").split("_", 1)[0]


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("keyed-server-data")


@pytest.fixture(scope="module")
def keyed_server(data_dir):
    srv = ServerProcess("--workers", "1", "--data-dir", str(data_dir), auth=True)
    yield srv
    assert srv.stop() == 0, "server did not exit cleanly"


@pytest.fixture(scope="module")
def keys(keyed_server, data_dir) -> dict[str, str]:
    """A key per (role, tenant) the tests use, made the way an operator does."""
    made = {
        (role, tenant): camdirector(data_dir, "keys", "create", "--role", role, "--tenant", tenant)
        for role, tenant in [("engine", TENANT_A), ("director", TENANT_A), ("viewer", TENANT_A), ("engine", TENANT_B)]
    }
    return {f"{role} {tenant}": key for (role, tenant), key in made.items()}


@pytest.fixture(scope="module")
def sessions(keyed_server, keys):
    """One streaming session in each tenant, made by its engine: their ids as .a and .b."""
    clients, ids = [], {}
    for name, tenant in (("a", TENANT_A), ("b", TENANT_B)):
        client = KeyedGrpc(keyed_server.grpc, keys[f"engine {tenant}"])
        ids[name] = client.call(
            "CreateSession", two_target_request(seed=5, style=pb.Style(visibility=pb.FRAMING_ONLY))
        ).session_id
        client.stream(list(walk(ids[name], 30)))
        clients.append((client, ids[name]))
    yield SimpleNamespace(**ids)
    for client, session_id in clients:
        client.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        client.close()


def open_dashboard(browser, server: ServerProcess):
    context = browser.new_context()
    page = context.new_page()
    page.set_default_timeout(test_dashboard.TIMEOUT_MS)
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(f"http://{server.http}/")
    return context, page, errors


@pytest.fixture
def page(browser, keyed_server):
    context, page, errors = open_dashboard(browser, keyed_server)
    yield page
    context.close()
    assert not errors, f"the page raised: {errors}"


def log_in(page, key: str) -> None:
    """Through the form, as a person does."""
    expect(page.locator("#login-panel")).to_be_visible()
    page.fill('#login-form input[name="key"]', key)
    page.click("#login-form button[type=submit]")
    expect(page.locator("#login-panel")).to_be_hidden()


def page_fetch(page, path: str, method: str = "GET", headers: dict | None = None, body=None) -> dict:
    """A request made by the page's own script, its cookie going with it: {status, body}."""
    return page.evaluate(
        """async ([path, method, headers, body]) => {
        const reply = await fetch(path, { method, headers, body: body === null ? undefined : JSON.stringify(body) });
        return { status: reply.status, body: await reply.json() }; }""",
        [path, method, headers or {}, body],
    )


def test_a_director_logs_in_once_and_sees_only_its_tenants_sessions(keyed_server, keys, sessions, page):
    key = keys[f"director {TENANT_A}"]
    expect(page.locator("#dashboard")).to_be_hidden()
    expect(page.locator("#login-result")).to_contain_text("no key")  # the server's reason, from /v1/whoami
    assert page.get_attribute('#login-form input[name="key"]', "type") == "password"
    # Every session id the list ever shows, from the first poll on.
    page.evaluate("""() => {
        window.listed = new Set();
        window.listings = 0;
        const body = document.querySelector('#sessions tbody');
        new MutationObserver(() => {
            window.listings += 1;
            body.querySelectorAll('tr').forEach((row) => window.listed.add(row.dataset.session));
        }).observe(body, { childList: true }); }""")

    log_in(page, key)
    expect(page.locator("#who")).to_have_text(f"director of tenant {TENANT_A} (key {key_id(key)})")
    expect(page.locator("#logout")).to_be_visible()
    expect(page.locator("#role-note")).to_be_hidden()  # a director may use every control here
    expect(page.locator(f'#sessions tbody tr[data-session="{sessions.a}"]')).to_be_visible()
    page.wait_for_function("window.listings >= 4")  # a few polls on
    assert page.evaluate("[...window.listed]") == [sessions.a]
    assert page_fetch(page, f"/v1/sessions/{sessions.b}")["status"] == 404  # as if B's did not exist
    # The key is kept nowhere the page can reach: not in storage, the address, the form or a cookie.
    assert page.evaluate("localStorage.length + sessionStorage.length") == 0
    assert key not in page.url and page.input_value('#login-form input[name="key"]') == ""
    secret = key.split("_", 2)[2]
    assert not any(secret in c["value"] for c in page.context.cookies())

    page.reload()  # the cookie, not the key, logs in
    expect(page.locator("#who")).to_contain_text(f"director of tenant {TENANT_A}")
    expect(page.locator("#login-panel")).to_be_hidden()
    expect(page.locator(f'#sessions tbody tr[data-session="{sessions.a}"]')).to_be_visible()

    page.click("#logout")
    expect(page.locator("#login-result")).to_have_text("Logged out.")
    expect(page.locator("#dashboard")).to_be_hidden()
    assert COOKIE not in {c["name"] for c in page.context.cookies()}
    page.reload()
    expect(page.locator("#login-panel")).to_be_visible()


def test_the_monitors_show_through_the_login_cookie(keys, sessions, page):
    """The program monitor is an <img> streaming view.mjpeg: the cookie goes with its request."""
    log_in(page, keys[f"director {TENANT_A}"])
    page.click(f'#sessions tbody tr[data-session="{sessions.a}"]')
    expect(page.locator("#shot-summary")).to_contain_text("frames 1–30")
    page.wait_for_function("document.querySelector('#program-view').naturalWidth === 320")
    expect(page.locator("#program-view-status")).to_have_text("")


def test_a_revoked_key_brings_the_login_form_back_with_the_reason(keyed_server, data_dir, sessions, page):
    key = camdirector(data_dir, "keys", "create", "--role", "director", "--tenant", TENANT_A)
    log_in(page, key)
    expect(page.locator(f'#sessions tbody tr[data-session="{sessions.a}"]')).to_be_visible()
    camdirector(data_dir, "keys", "revoke", key_id(key))
    expect(page.locator("#login-panel")).to_be_visible()  # at the next poll's 401
    expect(page.locator("#login-result")).to_have_text("the key of this login was revoked: log in with another key")
    expect(page.locator("#dashboard")).to_be_hidden()
    expect(page.locator("#sessions tbody tr")).to_have_count(0)  # nothing of the tenant's is left shown

    page.fill('#login-form input[name="key"]', key)  # the key itself is refused too
    page.click("#login-form button[type=submit]")
    expect(page.locator("#login-result")).to_have_text(f"key {key_id(key)} was revoked")
    expect(page.locator("#dashboard")).to_be_hidden()


def test_a_viewers_take_is_refused_in_the_browser_with_the_servers_message(keyed_server, keys, page):
    engine = KeyedGrpc(keyed_server.grpc, keys[f"engine {TENANT_A}"])
    session_id = engine.call("CreateSession", match_request(delay_s=1.0)).session_id
    engine.stream(list(match_frames(session_id, 90)))
    try:
        controls = page.evaluate("async () => Object.keys((await import('/dashboard/roles.js')).CONTROLS)")
        assert set(controls) <= {verb.value for verb in Verb}

        log_in(page, keys[f"viewer {TENANT_A}"])
        expect(page.locator("#who")).to_contain_text(f"viewer of tenant {TENANT_A}")
        expect(page.locator("#role-note")).to_have_text(
            "A key of role 'viewer' may not take and release shots, change a session's style, submit overview jobs: "
            "those buttons are off (docs/security.md)."
        )
        page.click(f'#sessions tbody tr[data-session="{session_id}"]')
        expect(page.locator("#match-view")).to_be_visible()
        take = page.locator("#candidates tbody tr").first.locator("button")
        refused = "a key of role 'viewer' may not session.take (docs/security.md)"
        expect(take).to_be_disabled()
        expect(take).to_have_attribute("title", refused)
        expect(page.locator("#release")).to_be_disabled()
        style_button = page.locator("#style-form button[type=submit]")
        expect(style_button).to_be_disabled()
        expect(style_button).to_have_attribute("title", "a key of role 'viewer' may not session.style (docs/security.md)")

        take.evaluate("button => { button.disabled = false; }")  # forced: the server decides
        take.click()
        result = page.locator("#take-result")
        expect(result).to_be_visible()
        expect(result).to_have_text(f"403: {refused}")
        expect(result).to_have_class("error")
        after = engine.stream(list(match_frames(session_id, 30, start=90)))
        assert not any(u.shot.held for u in after)  # nothing was taken

        style_button.evaluate("button => { button.disabled = false; }")
        style_button.click()
        expect(page.locator("#style-result")).to_have_text("403: a key of role 'viewer' may not session.style (docs/security.md)")
        expect(page.locator("#style-result")).to_have_class("error")
    finally:
        engine.call("CloseSession", pb.CloseSessionRequest(session_id=session_id))
        engine.close()


def test_the_login_cookie_is_httponly_samesite_strict_and_a_change_needs_the_csrf_token(keyed_server, keys, sessions, page):
    log_in(page, keys[f"director {TENANT_A}"])
    cookie = next(c for c in page.context.cookies() if c["name"] == COOKIE)
    assert cookie["httpOnly"] and cookie["sameSite"] == "Strict"
    assert COOKIE not in page.evaluate("document.cookie")  # no script reads it

    path = f"/v1/sessions/{sessions.a}/style"
    style = page_fetch(page, f"/v1/sessions/{sessions.a}")["body"]["style"]
    json_type = {"Content-Type": "application/json"}
    refused = page_fetch(page, path, "PUT", json_type, style)  # the cookie goes, the token does not
    assert refused["status"] == 403 and "X-CSRF-Token" in refused["body"]["detail"], refused
    token = page_fetch(page, "/v1/whoami")["body"]["csrf_token"]
    assert page_fetch(page, path, "PUT", {**json_type, "X-CSRF-Token": token}, style)["status"] == 200

    # Another site's request: with the cookie and even the token, its Origin is not this service's.
    foreign = page.context.request.put(
        f"http://{keyed_server.http}{path}",
        data=style,
        headers={**json_type, "X-CSRF-Token": token, "Origin": "https://elsewhere.example"},
    )
    assert foreign.status == 403, foreign.text()
    same = page.context.request.put(f"http://{keyed_server.http}{path}", data=style, headers={**json_type, "X-CSRF-Token": token})
    assert same.status == 200, same.text()  # the cookie went with these requests


def test_without_authentication_no_login_is_asked(server, browser):
    context, page, errors = open_dashboard(browser, server)
    try:
        expect(page.locator("#who")).to_have_text("authentication off: every caller is an admin of tenant default")
        expect(page.locator("#dashboard")).to_be_visible()
        expect(page.locator("#login-panel")).to_be_hidden()
        expect(page.locator("#logout")).to_be_hidden()
        expect(page.locator("#role-note")).to_be_hidden()
    finally:
        context.close()
    assert not errors, f"the page raised: {errors}"
