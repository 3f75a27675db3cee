"""A local S3 server (moto) for the tests and benchmarks that put a run store on an object store.

Needs the dev dependencies ``moto[server]`` and ``s3fs``.
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def moto_server(log: Path | None = None) -> Iterator[dict[str, str]]:
    """Run a moto S3 server on a free port for the ``with`` block (killed after it).

    Yields the ``AWS_*`` environment variables that point boto and s3fs at it (test
    credentials). ``log``: a file for the server's output (one line per request answered);
    None discards it.
    """
    port = free_port()
    with open(log or os.devnull, "w") as out:
        server = subprocess.Popen([sys.executable, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(port)],
                                  stdout=out, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60.0  # a loaded machine starts moto in 10-20 s
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                break
            except OSError:
                if server.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"the moto S3 server did not start on port {port}") from None
                time.sleep(0.1)
        _forget_s3_clients()
        yield {"AWS_ACCESS_KEY_ID": "test", "AWS_SECRET_ACCESS_KEY": "test", "AWS_DEFAULT_REGION": "us-east-1",
               "AWS_ENDPOINT_URL": f"http://127.0.0.1:{port}"}
    finally:
        server.kill()
        server.wait()
        _forget_s3_clients()


def _forget_s3_clients() -> None:
    """Drop the S3 filesystems fsspec keeps per process: one made against an earlier
    server (its endpoint taken from the environment then) would be reused, and fail."""
    try:
        import s3fs
    except ImportError:
        return
    s3fs.S3FileSystem.clear_instance_cache()
