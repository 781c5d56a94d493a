"""The live view (``qpavoid run ... --view``) answers only the operator's browser: the
served ``Host`` (no DNS rebinding), the URL's token, and no slow or crowding client
holding the others. Every wait here is bounded; the checks are on order, not speed."""

from __future__ import annotations

import contextlib
import http.client
import re
import select
import socket
import threading
import time
from collections.abc import Iterator
from urllib.parse import urlsplit
from urllib.request import urlopen

import pytest

from qpavoid.output import live_view
from qpavoid.output.live_view import LiveView
from qpavoid.output.view_server import MAX_CONNECTIONS

pytest.importorskip("meshcat", reason="the live view's page needs the extra 'view' (meshcat)")

#: Longest wait for anything the server should do at once or at a deadline, s (a loaded
#: CI machine: generous; a pass never waits for it).
BOUND_S = 10.0


@pytest.fixture
def view(robot) -> Iterator[LiveView]:
    with LiveView(("127.0.0.1", 0), robot, "capsules", "security") as v:
        yield v


def port_of(view: LiveView) -> int:
    return int(urlsplit(view.url).port)


def ask(port: int, request: bytes) -> tuple[int, bytes, bytes]:
    """Send ``request`` as it is and read the answer to its end: (status, head, body)."""
    with socket.create_connection(("127.0.0.1", port), timeout=BOUND_S) as s:
        s.sendall(request)
        answer = b""
        while chunk := s.recv(65536):
            answer += chunk
    head, _, body = answer.partition(b"\r\n\r\n")
    return int(head.split(b" ", 2)[1]), head, body


def get(port: int, path: str, host: str | None) -> tuple[int, bytes, bytes]:
    """``GET path`` with one ``Host`` header (none if ``host`` is None)."""
    lines = [f"GET {path} HTTP/1.1"] + ([f"Host: {host}"] if host is not None else [])
    return ask(port, ("\r\n".join([*lines, "Connection: close", "", ""])).encode("latin-1"))


def test_the_right_host_and_token_get_the_page_and_the_state(view):
    port = port_of(view)
    assert re.fullmatch(r"http://127\.0\.0\.1:\d+/[A-Za-z0-9_-]{20,}/", view.url)
    page = urlopen(view.url, timeout=BOUND_S).read().decode()
    assert "const LIVE = true" in page and view.token not in page
    assert 'fetch("state"' in page  # relative: under the token
    assert urlopen(view.url + "state", timeout=BOUND_S).read() == b"null"
    token = view.token
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"LocalHost:{port}", f"[::1]:{port}"):
        status, _, body = get(port, f"/{token}/state", host)
        assert (status, body) == (200, b"null"), host
    status, _, body = get(port, f"/{token}/", f"localhost:{port}")
    assert status == 200 and b"const LIVE = true" in body
    status, head, _ = get(port, f"/{token}", f"127.0.0.1:{port}")  # no "/": to the page
    assert status == 301 and f"Location: /{token}/".encode() in head


def test_a_foreign_host_gets_403_and_no_page(view):
    port = port_of(view)
    path = f"/{view.token}/"
    hosts = [
        f"rebind.attacker.example:{port}",  # DNS rebinding: the attacker's name, our address
        "rebind.attacker.example",
        f"127.0.0.1:{port + 1}",
        "127.0.0.1",
        "localhost",
        f"localhost.:{port}",
        f"127.0.0.1:{port}.attacker.example",
        "",
    ]
    for host in [*hosts, None]:
        status, _, body = get(port, path, host)
        assert status == 403, host
        assert len(body) < 200 and b"<" not in body and view.token.encode() not in body, host
    twice = f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nHost: evil.example\r\n\r\n"
    assert ask(port, twice.encode())[0] == 403


def test_a_missing_or_wrong_token_gets_404(view, robot):
    port = port_of(view)
    token = view.token
    wrong = [
        "/",
        "/state",
        "/index.html",
        "/favicon.ico",
        f"/{token[:-1]}/state",
        f"/{token}x/state",
        f"/x{token}/",
        f"/{token.swapcase()}/state",
        f"/{token}/other",
        f"/{token}/state/",
        "/\xff\xfe/state",
    ]
    for path in wrong:
        status, _, body = get(port, path, f"127.0.0.1:{port}")
        assert status == 404, path
        assert len(body) < 200 and b"null" not in body, path
    with LiveView(("127.0.0.1", 0), robot, "capsules", "other") as other:
        assert other.token != token


@pytest.fixture
def quick(robot) -> Iterator[LiveView]:
    """A view whose request deadline is short (a test of the deadline need not wait 2 s)."""
    with LiveView(("127.0.0.1", 0), robot, "capsules", "quick", request_deadline_s=1.2) as v:
        yield v


def test_a_slow_client_holds_no_one_and_is_cut_off_at_its_deadline(quick):
    """A client sending a byte every 0.5 s (each byte well within any per-read timeout)
    while an honest one asks for the state: the honest one is answered while the slow one
    is still connected, and the slow one is cut off once its deadline has passed."""
    port = port_of(quick)
    events: list[str] = []
    head = f"GET /{quick.token}/state HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nX-Slow: ".encode()
    slow = socket.create_connection(("127.0.0.1", port), timeout=BOUND_S)
    start = time.monotonic()
    slow.sendall(head[:1])  # connected and talking before the honest client

    def dribble() -> None:
        sent = 1
        while time.monotonic() < start + BOUND_S:
            readable, _, _ = select.select([slow], [], [], 0.5)
            if readable:
                try:
                    data = slow.recv(1)
                except OSError:
                    data = b""
                events.append("slow cut" if not data else "slow answered")
                return
            try:
                slow.sendall(head[sent : sent + 1] or b"a")  # never the blank line
            except OSError:
                events.append("slow cut")
                return
            sent += 1
        events.append("slow still connected")

    thread = threading.Thread(target=dribble, daemon=True)
    thread.start()
    try:
        honest = http.client.HTTPConnection("127.0.0.1", port, timeout=BOUND_S)
        honest.request("GET", f"/{quick.token}/state")
        answer = honest.getresponse()
        assert (answer.status, answer.read()) == (200, b"null")
        honest.close()
        events.append("honest answered")
        thread.join(BOUND_S + 1)
        cut_after = time.monotonic() - start
    finally:
        slow.close()
    assert events == ["honest answered", "slow cut"]
    assert cut_after >= 1.2 * 0.9  # not before its deadline


def test_a_crowd_beyond_the_cap_is_closed_at_once_and_an_honest_request_follows(quick):
    """``MAX_CONNECTIONS`` idle connections hold every slot until their deadline; the ones
    beyond are closed at once, before any of the crowd; then an honest request is served."""
    port = port_of(quick)

    def connect() -> socket.socket:
        return socket.create_connection(("127.0.0.1", port), timeout=BOUND_S)

    crowd = [connect() for _ in range(MAX_CONNECTIONS)]
    extra = [connect() for _ in range(4)]
    names = {s: "crowd" for s in crowd} | {s: "extra" for s in extra}
    order: list[str] = []
    end = time.monotonic() + BOUND_S
    try:
        while names and time.monotonic() < end:
            readable, _, _ = select.select(list(names), [], [], 0.5)
            for s in readable:
                try:
                    data = s.recv(1)
                except OSError:
                    data = b""
                assert data == b"", "an idle connection was answered"
                order.append(names.pop(s))
    finally:
        for s in crowd + extra:
            s.close()
    assert order == ["extra"] * 4 + ["crowd"] * MAX_CONNECTIONS
    assert urlopen(quick.url + "state", timeout=BOUND_S).read() == b"null"


def test_the_state_is_made_once_per_tick_by_one_thread_at_a_time(view, monkeypatch):
    """Many requests at once for a new tick: the robot model makes its geometry once, never
    in two threads at the same time, and every request gets the same answer."""
    inside = 0
    most_inside = 0
    calls = 0
    count_lock = threading.Lock()
    real = live_view.replay_data

    def counted(*args, **kwargs):
        nonlocal inside, most_inside, calls
        with count_lock:
            inside += 1
            calls += 1
            most_inside = max(most_inside, inside)
        time.sleep(0.05)  # widen any race (the pass does not depend on it)
        try:
            return real(*args, **kwargs)
        finally:
            with count_lock:
                inside -= 1

    monkeypatch.setattr(live_view, "replay_data", counted)
    start = live_view._one_tick(view.robot, view.human.skeleton)
    tick = {key: value[0] for key, value in start.items()}
    for round_ in (1, 2):
        view.update(tick)
        barrier = threading.Barrier(8)
        answers: list[bytes] = []

        def ask_state(barrier: threading.Barrier = barrier, answers: list = answers) -> None:
            barrier.wait(BOUND_S)
            answers.append(urlopen(view.url + "state", timeout=BOUND_S).read())

        threads = [threading.Thread(target=ask_state) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(BOUND_S)
        assert len(answers) == 8 and len(set(answers)) == 1 and answers[0] != b"null"
        assert calls == round_ and most_inside == 1


def test_close_cuts_open_connections_and_stops_serving(robot):
    # a deadline far beyond the wait: the idle connection's end is close()'s doing
    view = LiveView(("127.0.0.1", 0), robot, "capsules", "closing", request_deadline_s=60.0)
    port = port_of(view)
    idle = socket.create_connection(("127.0.0.1", port), timeout=BOUND_S)
    try:
        idle.sendall(b"GET /")
        assert urlopen(view.url + "state", timeout=BOUND_S).read() == b"null"  # served
        view.close()
        with contextlib.suppress(ConnectionResetError):  # cut, or reset: either ends it
            assert idle.recv(1) == b""  # within BOUND_S, long before its deadline
    finally:
        idle.close()
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", port), timeout=BOUND_S).close()


def test_only_the_operators_page_can_ask_to_clear_the_flagged_people(view):
    port, token = port_of(view), view.token
    host = f"127.0.0.1:{port}"

    def post(path: str, host: str, origin: str | None = None) -> int:
        lines = [f"POST {path} HTTP/1.1", f"Host: {host}", "Content-Length: 0"]
        lines += [f"Origin: {origin}"] if origin else []
        return ask(port, ("\r\n".join([*lines, "Connection: close", "", ""])).encode())[0]

    assert post("/clear", host) == 404 and post("/wrong/clear", host) == 404
    assert post(f"/{token}/clear", "rebind.attacker.example") == 403
    assert post(f"/{token}/clear", host, "http://evil.example") == 403  # another site's form
    assert not view.clear_requested.is_set()
    assert post(f"/{token}/state", host) == 404  # only clear is posted
    assert post(f"/{token}/clear", host, f"http://{host}") == 200  # the page's own fetch
    assert view.clear_requested.is_set()
