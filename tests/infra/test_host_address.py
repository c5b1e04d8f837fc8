"""infra/host_address.py: lookups run off the caller's thread, one at a time; what they found is
kept through a lookup that stalls or fails; a failed connection moves to the next address."""

from __future__ import annotations

import threading
import time

import pytest

from camdirector.infra.host_address import HostAddress, lookup_stream_addresses


class ScriptedLookup:
    """A host name lookup that answers what the test gives (addresses, or an OSError to raise), in
    turn; a call with nothing given stalls until something is, as a container network's DNS does
    (infra/host_address.py). Used by the stores' tests too."""

    def __init__(self, *answers: list[str] | OSError) -> None:
        self.answers = list(answers)
        self.calls = 0
        self.given = threading.Condition()

    def __call__(self, host: str, port: int) -> list[str]:
        with self.given:
            self.calls += 1
            self.given.wait_for(lambda: self.answers)
            answer = self.answers.pop(0)
        if isinstance(answer, OSError):
            raise answer
        return answer

    def give(self, answer: list[str] | OSError) -> None:
        with self.given:
            self.answers.append(answer)
            self.given.notify_all()


def _until(condition, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "the condition never held"
        time.sleep(0.005)


def test_a_lookup_runs_off_the_callers_thread_and_one_at_a_time():
    resolver = ScriptedLookup()
    address = HostAddress("redis", 6379, resolver)
    for _ in range(5):
        address.refresh()  # returns at once while the lookup stalls
    assert address.current is None
    assert address.wait(0.05) is None  # waited, not found
    assert resolver.calls == 1
    resolver.give(["10.0.0.2"])
    _until(lambda: address.current == "10.0.0.2")
    assert resolver.calls == 1


def test_what_was_found_is_kept_while_a_lookup_stalls_or_fails():
    resolver = ScriptedLookup()
    address = HostAddress("redis", 6379, resolver)
    resolver.give(["10.0.0.2"])
    assert address.wait(5.0) == "10.0.0.2"
    address.refresh()  # this one stalls
    _until(lambda: resolver.calls == 2)
    assert address.current == "10.0.0.2" and address.wait(0.0) == "10.0.0.2"
    resolver.give(OSError("Temporary failure in name resolution"))
    _until(lambda: address.last_error is not None)
    assert address.current == "10.0.0.2"


def test_a_failed_connection_tries_the_next_address_and_looks_the_name_up_again():
    resolver = ScriptedLookup()
    address = HostAddress("redis", 6379, resolver)
    resolver.give(["10.0.0.2", "10.0.0.3"])
    assert address.wait(5.0) == "10.0.0.2"
    address.failed()
    assert address.current == "10.0.0.3"
    resolver.give(["10.0.0.3", "10.0.0.2"])  # the same addresses: the one that answers stays first
    _until(lambda: resolver.calls == 2 and not resolver.answers)
    time.sleep(0.05)
    assert address.current == "10.0.0.3"
    address.failed()  # the service moved: the new lookup's address is used
    resolver.give(["10.0.0.9"])
    _until(lambda: address.current == "10.0.0.9")


def test_looking_up_now_raises_what_the_lookup_raised():
    address = HostAddress("no-such-host.invalid", 6379)
    with pytest.raises(OSError):
        address.look_up_now()
    assert address.current is None and address.last_error is not None


def test_the_default_lookup_answers_each_address_once():
    addresses = lookup_stream_addresses("localhost", 6379)
    assert "127.0.0.1" in addresses and len(addresses) == len(set(addresses))


def test_a_failing_slow_or_moved_lookup_is_logged_once_for_the_operator(caplog):
    resolver = ScriptedLookup(["10.0.0.2"])
    ticks = iter([0.0, 0.001, 10.0, 10.002, 20.0, 20.001, 30.0, 35.0, 40.0, 40.001])  # each lookup's start and end, s
    address = HostAddress("redis", 6379, resolver, clock=lambda: next(ticks))
    caplog.set_level("WARNING", logger="camdirector.lookups")
    address.look_up_now()
    assert caplog.messages == []
    for _ in range(2):
        resolver.give(OSError("Temporary failure in name resolution"))
        with pytest.raises(OSError):
            address.look_up_now()
    assert caplog.messages == [
        "looking up redis failed (Temporary failure in name resolution): new connections still go to 10.0.0.2"
    ]  # once, however many fail
    resolver.give(["10.0.0.7"])
    address.look_up_now()  # 5 s, and elsewhere now
    assert caplog.messages[1:] == [
        "looking up redis took 5.0 s (no connection waited for it)",
        "looking up redis works again: 10.0.0.7",
        "redis moved: 10.0.0.2 -> 10.0.0.7",
    ]
    resolver.give(["10.0.0.7"])
    address.look_up_now()
    assert len(caplog.messages) == 4 and address.current == "10.0.0.7"
