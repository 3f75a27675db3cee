"""One run at a time per store: a lock object with a heartbeat that a crash cannot wedge.

``<store>/run.lock`` is a small JSON object (host, pid, a random token, start and
heartbeat times) written through fsspec, so it works for any store URL. The holder
refreshes the heartbeat every ``HEARTBEAT_S`` seconds from a daemon thread. A lock is
*stale*, and is taken over, when its process is gone (same host: the pid no longer runs)
or when its heartbeat is older than ``STALE_S`` seconds (any host: a crashed machine).
So a SIGKILLed run leaves a lock that the next run on the same machine takes over at
once, and one on another machine after ``STALE_S``.

Local stores create the lock with ``O_EXCL`` (atomic); object stores have no atomic
create in fsspec, so there the writer reads its token back after a short pause and
gives up if another run's token is there (a best effort, documented in docs/store.md).
"""

from __future__ import annotations

import json
import os
import secrets
import socket
import threading
import time
from datetime import UTC, datetime
from typing import Any

import fsspec
from fsspec.implementations.local import LocalFileSystem

from hollowtree.errors import PipelineError

__all__ = ["StoreBusyError", "StoreLock", "HEARTBEAT_S", "STALE_S"]

HEARTBEAT_S = 10.0
STALE_S = 60.0
LOCK_NAME = "run.lock"


class StoreBusyError(PipelineError, RuntimeError):
    """Another run holds the store."""


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


class StoreLock:
    """Hold ``<url>/run.lock`` while a run writes the store (a context manager)."""

    def __init__(self, url: str) -> None:
        self.url = str(url)
        self._fs, root = fsspec.core.url_to_fs(self.url)
        self._path = root.rstrip("/") + "/" + LOCK_NAME
        self._local = isinstance(self._fs, LocalFileSystem)
        self._token = secrets.token_hex(8)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._started = datetime.now(UTC).isoformat(timespec="seconds")

    # ------------------------------------------------------------------ reading
    def holder(self) -> dict[str, Any] | None:
        """The lock's content, or None when nobody holds it (or it is unreadable)."""
        try:
            with self._fs.open(self._path, "rb") as f:
                return json.loads(f.read().decode())
        except FileNotFoundError:
            return None
        except (OSError, ValueError):
            return {}

    def _stale(self, info: dict[str, Any]) -> bool:
        if not info:
            return True
        if info.get("host") == socket.gethostname() and not _pid_alive(int(info.get("pid", -1))):
            return True
        return time.time() - float(info.get("heartbeat", 0)) > STALE_S

    # ------------------------------------------------------------------ writing
    def _content(self) -> bytes:
        return json.dumps({"host": socket.gethostname(), "pid": os.getpid(), "token": self._token,
                           "started": self._started, "heartbeat": time.time()}).encode()

    def _write(self, *, exclusive: bool) -> bool:
        if self._local and exclusive:
            os.makedirs(os.path.dirname(self._path), exist_ok=True)
            try:
                fd = os.open(self._path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                return False
            with os.fdopen(fd, "wb") as f:
                f.write(self._content())
            return True
        if self._local:  # heartbeat: replace atomically
            tmp = f"{self._path}.{self._token}"
            with open(tmp, "wb") as f:
                f.write(self._content())
            os.replace(tmp, self._path)
            return True
        with self._fs.open(self._path, "wb") as f:
            f.write(self._content())
        return True

    def acquire(self) -> StoreLock:
        """Take the lock or raise :class:`StoreBusyError` naming the run that holds it."""
        for _ in range(3):
            info = self.holder()
            if info is not None:
                if not self._stale(info):
                    raise StoreBusyError(
                        f"store {self.url} is in use by another run (pid {info.get('pid')} on "
                        f"{info.get('host')}, started {info.get('started')}); wait for it to "
                        f"finish (a crashed run's lock expires after {STALE_S:.0f} s)"
                    )
                self._fs.rm(self._path)
            if self._write(exclusive=True):
                if not self._local:
                    time.sleep(0.2)
                    if (self.holder() or {}).get("token") != self._token:
                        continue
                break
        else:
            raise StoreBusyError(f"store {self.url}: another run took the lock at the same time")
        self._thread = threading.Thread(target=self._beat, name="hollowtree-lock", daemon=True)
        self._thread.start()
        return self

    def _beat(self) -> None:
        while not self._stop.wait(HEARTBEAT_S):
            try:
                if (self.holder() or {}).get("token") == self._token:
                    self._write(exclusive=False)
            except OSError:
                pass

    def release(self) -> None:
        """Stop the heartbeat and remove the lock if it is still ours."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        try:
            if (self.holder() or {}).get("token") == self._token:
                self._fs.rm(self._path)
        except OSError:
            pass

    def __enter__(self) -> StoreLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()
