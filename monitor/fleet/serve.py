"""`monitor fleet serve`: the fleet web page live on localhost (Python's http.server).

The pages are written once at start into a temporary folder (the machine pages judge logs
again for their signal plots, kept in memory) and served from there; the index, the alarm
list and the machine pages are made anew on every request, so an acknowledgement shows at
once.  POST /ack (a plain HTML form:
alarm, action, by, note) appends to RESULTS/alarm-acks.jsonl and redirects to the list.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from http import HTTPStatus
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from threading import Lock
from typing import Any
from urllib.parse import parse_qs

from monitor.errors import ConfigError
from monitor.fleet.acks import record


def _handler(site: Any, root: Path, lock: Lock) -> type[SimpleHTTPRequestHandler]:
    class Handler(SimpleHTTPRequestHandler):
        def __init__(self, *a: Any, **kw: Any) -> None:
            super().__init__(*a, directory=str(root), **kw)

        def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - the API's
            pass  # no line per request on the terminal

        def _page(self, html: str, status: HTTPStatus = HTTPStatus.OK) -> None:
            data = html.encode("utf-8")
            self.send_response(status)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(data)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(data)

        def do_GET(self) -> None:  # noqa: N802 - the API's name
            path = self.path.split("?", 1)[0]
            if path in ("/", "/index.html"):
                self._page(site.index_html())
            elif path == "/alarms.html":
                self._page(site.alarms_html(live=True))
            elif site.view(path.lstrip("/")) is not None:
                self._page(site.machine_html(site.view(path.lstrip("/"))))
            else:
                super().do_GET()

        def do_POST(self) -> None:  # noqa: N802 - the API's name
            if self.path.split("?", 1)[0] != "/ack":
                self.send_error(HTTPStatus.NOT_FOUND)
                return
            n = int(self.headers.get("Content-Length") or 0)
            form = parse_qs(self.rfile.read(min(n, 65536)).decode("utf-8", "replace"))

            def one(key: str) -> str:
                return (form.get(key) or [""])[0]

            try:
                with lock:
                    record(site.results, one("alarm"), one("action"), one("by"), one("note"))
            except ConfigError as exc:
                self.send_error(HTTPStatus.BAD_REQUEST, str(exc))
                return
            self.send_response(HTTPStatus.SEE_OTHER)
            self.send_header("Location", "alarms.html")
            self.end_headers()

    return Handler


def serve_site(site: Any, host: str, port: int, say: Callable[[str], None]) -> int:
    """Write the pages, then serve them until Ctrl-C (exit 0)."""
    with tempfile.TemporaryDirectory(prefix="fleet-page-") as tmp:
        say("fleet serve: writing the pages (machine pages judge their alarm logs again)")
        site.write(Path(tmp))
        try:
            server = ThreadingHTTPServer((host, port), _handler(site, Path(tmp), Lock()))
        except OSError as exc:
            raise ConfigError(f"{host}:{port}: cannot listen ({exc.strerror or exc})") from None
        with server:
            h, p = server.socket.getsockname()[:2]  # server_address, typed str | bytes
            say(f"fleet serve: http://{h}:{p}/ (Ctrl-C to stop)")
            try:
                server.serve_forever()
            except KeyboardInterrupt:
                say("fleet serve: stopped")
    return 0
