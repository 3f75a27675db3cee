"""``hollowtree view STORE``: a labelled run store in the browser, element by element.

A local, read-only web server (``http.server.ThreadingHTTPServer``, 127.0.0.1 by default)
serves one page (``view_static/``: plain JavaScript and WebGL, nothing from the internet)
and a few data routes; every other path is refused (404), so nothing outside the page and
the store's data is ever served.

Data routes (JSON unless said):

- ``/api/meta``: the store, its tiles' nodes, the first-view plan, class names, colours and
  the store's label counts (from the labels stage's records: no array is read).
- ``/api/node?tile=T&chunk=C&level=K``: binary (``view_lod.pack``): level K of node
  (T, C), the rows it adds to the levels below (``view_lod``): positions (float32, metres
  from ``origin``), class, instance, coarse segment, tree leaf, score, RGB/intensity.
  One chunk read per tile array; the labels come from the tile's ``labels/parts``
  (sorted by original index), read once per tile and kept in a small cache.
- ``/api/element?instance=I&segment=S&leaf=L``: the element (instance) of a point, its
  point count and box, and the path from its tree's root to its leaf.
- ``/api/tree``, ``/api/children?tree=S&node=N``, ``/api/subtree?tree=S&node=N``: the
  hierarchical tree as an outline, and what to highlight for a node.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlsplit

from hollowtree.errors import ConfigError, PipelineError

__all__ = ["add_parser", "make_server", "cmd_view"]

#: The page's files: the only paths served besides the data routes.
STATIC = {"/": ("index.html", "text/html; charset=utf-8"),
          "/index.html": ("index.html", "text/html; charset=utf-8"),
          "/viewer.js": ("viewer.js", "text/javascript; charset=utf-8"),
          "/viewer.css": ("viewer.css", "text/css; charset=utf-8")}


# ---------------------------------------------------------------------- the server
def _static(name: str) -> bytes:
    return resources.files("hollowtree.pipeline").joinpath("view_static", name).read_bytes()


class _Handler(BaseHTTPRequestHandler):
    server_version = "hollowtree-view"
    protocol_version = "HTTP/1.1"
    view: Any  # view_store.ViewStore
    pages: dict[str, bytes]
    quiet = True
    loopback = True

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (the base class's name)
        if not self.quiet:
            super().log_message(format, *args)

    def _send(self, status: int, body: bytes, ctype: str, *, head: bool = False) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        if not head:
            self.wfile.write(body)

    def _json(self, obj: Any, status: int = 200, *, head: bool = False) -> None:
        self._send(status, json.dumps(obj, separators=(",", ":")).encode(), "application/json", head=head)

    def _refuse(self, status: int, text: str, *, head: bool = False) -> None:
        self._send(status, (text + "\n").encode(), "text/plain; charset=utf-8", head=head)

    def do_HEAD(self) -> None:  # noqa: N802 (http.server's name)
        self._route(head=True)

    def do_GET(self) -> None:  # noqa: N802
        self._route(head=False)

    def _not_allowed(self) -> None:
        self._refuse(HTTPStatus.METHOD_NOT_ALLOWED, "read only: GET and HEAD only")

    do_POST = do_PUT = do_DELETE = do_PATCH = _not_allowed  # noqa: N815

    def _route(self, *, head: bool) -> None:
        parts = urlsplit(self.path)
        path = parts.path
        if self.loopback and (self.headers.get("Host") or "").rsplit(":", 1)[0].strip("[]") not in _LOCAL_NAMES:
            # a page of another site that resolves its name to 127.0.0.1 (DNS rebinding)
            return self._refuse(HTTPStatus.FORBIDDEN, "this server answers localhost only", head=head)
        # only the page's own files and the data routes: no path is ever joined to a folder
        if path in STATIC and not parts.query:
            name, ctype = STATIC[path]
            return self._send(200, self.pages[name], ctype, head=head)
        q = {k: v[-1] for k, v in parse_qs(parts.query, keep_blank_values=True).items()}
        v = self.view
        try:
            if path == "/api/meta":
                return self._json(v.meta(), head=head)
            if path == "/api/node":
                level = _int(q, "level")
                body = v.node(_int(q, "tile"), _int(q, "chunk"), level, _int(q, "first", level))
                return self._send(200, body, "application/octet-stream", head=head)
            if path == "/api/element":
                return self._json(v.element(_int(q, "instance"), _int(q, "segment"), _int(q, "leaf")), head=head)
            if path == "/api/stats":  # what the server has read so far (benchmarks/bench_view.py)
                return self._json({"chunk_reads": v.chunk_reads, "bytes_read": v.bytes_read,
                                   "cached_tiles": len(v._parts)}, head=head)
            if path == "/api/tree":
                roots, total = v.tree().roots(_int(q, "limit", 300))
                return self._json({"roots": roots, "total": total}, head=head)
            if path == "/api/children":
                return self._json({"children": v.tree().kids(_int(q, "tree"), _int(q, "node"))}, head=head)
            if path == "/api/subtree":
                return self._json(v.tree().subtree(_int(q, "tree"), _int(q, "node")), head=head)
        except ConfigError as exc:
            return self._refuse(HTTPStatus.BAD_REQUEST, str(exc), head=head)
        except (BrokenPipeError, ConnectionResetError):
            return None
        except Exception as exc:  # a damaged store, a lost connection to S3: one line, and serve on
            print(f"hollowtree view: {path}: {type(exc).__name__}: {exc}", file=sys.stderr)
            return self._refuse(HTTPStatus.INTERNAL_SERVER_ERROR, f"{type(exc).__name__}: {exc}", head=head)
        return self._refuse(HTTPStatus.NOT_FOUND, "not found", head=head)


_LOCAL_NAMES = {"127.0.0.1", "localhost", "::1"}


def _int(q: dict[str, str], name: str, default: int | None = None) -> int:
    if name not in q:
        if default is None:
            raise ConfigError(f"missing parameter {name}")
        return default
    try:
        return int(q[name])
    except ValueError:
        raise ConfigError(f"parameter {name} must be an integer, not {q[name]!r}") from None


def make_server(store: str, *, host: str = "127.0.0.1", port: int = 0, quiet: bool = True) -> ThreadingHTTPServer:
    """A server for ``store`` bound to ``host:port`` (0: any free port), not yet serving:
    call ``serve_forever()`` (``server.view`` is the :class:`~.view_store.ViewStore`)."""
    from hollowtree.pipeline.view_store import ViewStore  # numpy, zarr: not for `hollowtree --help`

    view = ViewStore(store)
    pages = {name: _static(name) for name, _ in STATIC.values()}
    loopback = host in _LOCAL_NAMES or host.startswith("127.")
    handler = type("ViewHandler", (_Handler,), {"view": view, "pages": pages, "quiet": quiet, "loopback": loopback})
    try:
        server = ThreadingHTTPServer((host, port), handler)
    except OSError as exc:
        raise ConfigError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    server.daemon_threads = True
    server.view = view  # type: ignore[attr-defined]
    return server


def _port(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port must be 0..65535, not {text!r}")
    return port


def add_parser(sub: Any) -> None:
    """Add ``view`` to ``sub`` (the subparsers of ``hollowtree``)."""
    v = sub.add_parser("view", help="look at a labelled run store in the browser (a local web server)",
                       description="Serve a read-only 3-D view of a labelled run store (a path or an fsspec "
                                   "URL) on 127.0.0.1: points by class, instance, segment, score or RGB, "
                                   "click a point for its element and tree path.")
    v.add_argument("store", help="run store")
    v.add_argument("--port", type=_port, default=8765, help="port (default 8765; 0 = any free port)")
    v.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    v.add_argument("--open", action="store_true", help="open the page in the default browser")
    v.add_argument("--log", action="store_true", help="log every request on stderr")
    v.set_defaults(func=cmd_view)


def cmd_view(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    server = make_server(args.store, host=args.host, port=args.port, quiet=not args.log)
    host, port = server.server_address[:2]
    url = f"http://{host}:{port}/"
    view = server.view  # type: ignore[attr-defined]
    print(f"hollowtree view: {args.store} ({view.counts.sum():,} points, {len(view.tiles)} tiles) at {url} "
          f"(opened in {time.perf_counter() - t0:.1f} s; Ctrl-C stops)", flush=True)
    if args.open:
        import webbrowser

        threading.Timer(0.3, webbrowser.open, (url,)).start()
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("hollowtree view: stopped", file=sys.stderr)
    finally:
        server.server_close()
    return 0


def _main(argv: list[str] | None = None) -> int:
    """``python -m hollowtree.pipeline.view STORE``: the command without the whole CLI."""
    parser = argparse.ArgumentParser(prog="hollowtree view")
    add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["view", *(sys.argv[1:] if argv is None else argv)])
    try:
        return cmd_view(args)
    except PipelineError as exc:
        print(f"hollowtree view: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(_main())
