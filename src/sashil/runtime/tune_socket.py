"""The tuning socket of a running loop: a Unix socket in the run folder, and its client.

``sashil run`` listens on ``RUN_FOLDER/tune.sock`` while its loop runs (:class:`TuneServer`).
The socket is created with owner-only permissions (0600): only a user who can open it can tune,
and it accepts parameter values only, never code. It is removed when the run ends.

A Unix socket's path is limited to about 107 bytes; a run folder deeper than that gets its socket
in a private temporary directory (0700) and ``tune.sock`` as a symbolic link to it. The client
follows the link.

One request, one answer, each a line of JSON:

* ``{"set": {"c_sky": 2.0}, "ramp_s": null}`` → ``{"ok": true, "law": ..., "events": [...]}``,
  once a cycle applied the change (:meth:`sashil.runtime.tuning.LiveTuning.submit`);
* ``{"get": true}`` → ``{"ok": true, "law": ..., "parameters": {...}}``;
* anything refused → ``{"ok": false, "error": "<one line>"}``.

Connections are served one after another on the server's thread, so two callers racing are
applied in the order they connected, each whole.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import select
import shutil
import socket
import tempfile
import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from sashil.errors import ConfigError, SashilError
from sashil.runtime.tuning import LiveTuning, TuneEvent

#: the socket's name in the run folder
SOCKET_NAME = "tune.sock"
#: longest socket path bound in place (sockaddr_un's sun_path is 108 bytes with its NUL)
MAX_SOCKET_PATH = 100
#: a request larger than this is refused (parameter changes are a few hundred bytes)
MAX_REQUEST_BYTES = 65536
#: seconds a client may take to send its request, and the client waits for an answer (longer than
#: the run waits for its loop to take a change: sashil.runtime.tuning.DEFAULT_WAIT_S)
IO_TIMEOUT_S = 40.0


class TuningError(SashilError):
    """The tuning socket cannot be reached or refused a change (exit 2: bad input, nothing changed)."""

    exit_code = 2


def _jsonable(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


class TuneServer:
    """Serves ``tuning`` on ``folder/tune.sock`` from its own thread; ``start()``, then ``stop()``."""

    def __init__(
        self,
        folder: str | Path,
        tuning: LiveTuning | None = None,
        handler: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
    ):
        """Serve ``tuning`` (a law in this process), or pass each decoded request to ``handler``
        (a law in the loop process: :mod:`sashil.runtime.loop_process`)."""
        if (tuning is None) == (handler is None):
            raise ValueError("give the tuning or a handler")
        self.folder = Path(folder)
        self.tuning = tuning
        self.handler = handler
        self.path = self.folder / SOCKET_NAME
        self._private_dir: str | None = None
        self._listener: socket.socket | None = None
        self._wake_r, self._wake_w = -1, -1
        self._thread: threading.Thread | None = None
        self.requests = 0

    def start(self) -> TuneServer:
        bind_path = str(self.path)
        if len(os.fsencode(bind_path)) > MAX_SOCKET_PATH:
            self._private_dir = tempfile.mkdtemp(prefix="sashil-tune-")  # 0700
            bind_path = os.path.join(self._private_dir, SOCKET_NAME)
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        old_umask = os.umask(0o177)  # the socket file is born 0600: no moment where others may connect
        try:
            listener.bind(bind_path)
        finally:
            os.umask(old_umask)
        os.chmod(bind_path, 0o600)
        if self._private_dir is not None:
            os.symlink(bind_path, self.path)
        listener.listen(4)
        self._listener = listener
        self._wake_r, self._wake_w = os.pipe()
        self._thread = threading.Thread(target=self._serve, name="sashil-tune", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving, join the thread, remove the socket (and its private directory)."""
        if self._thread is not None:
            os.write(self._wake_w, b"x")
            self._thread.join()
            self._thread = None
        if self._listener is not None:
            self._listener.close()
            self._listener = None
        for fd in (self._wake_r, self._wake_w):
            if fd >= 0:
                os.close(fd)
        self._wake_r = self._wake_w = -1
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
        if self._private_dir is not None:
            shutil.rmtree(self._private_dir, ignore_errors=True)
            self._private_dir = None

    # -- the server's thread ---------------------------------------------------------------------
    def _serve(self) -> None:
        listener = self._listener
        assert listener is not None
        while True:
            ready, _, _ = select.select([listener.fileno(), self._wake_r], [], [])
            if self._wake_r in ready:
                return
            try:
                conn, _ = listener.accept()
            except OSError:
                continue
            with conn:
                try:
                    self._answer(conn)
                except OSError:  # the caller went away: nothing to answer
                    pass

    def _answer(self, conn: socket.socket) -> None:
        conn.settimeout(IO_TIMEOUT_S)
        raw = b""
        while not raw.endswith(b"\n"):
            chunk = conn.recv(4096)
            if not chunk:
                break
            raw += chunk
            if len(raw) > MAX_REQUEST_BYTES:
                break
        self.requests += 1
        conn.sendall((json.dumps(self.handle(raw), default=str) + "\n").encode())

    def handle(self, raw: bytes) -> dict[str, Any]:
        """The answer to one request line (see the module doc): decoded here, answered by the
        ``handler`` given (the run's loop process) or by :func:`answer` on the tuning."""
        if len(raw) > MAX_REQUEST_BYTES:
            return {"ok": False, "error": f"request larger than {MAX_REQUEST_BYTES} bytes"}
        try:
            request = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as err:
            return {"ok": False, "error": f"not a JSON request: {err}"}
        if not isinstance(request, dict):
            return {"ok": False, "error": "expected a JSON object ({'set': {...}} or {'get': true})"}
        if self.handler is not None:
            return self.handler(request)
        assert self.tuning is not None
        return answer(self.tuning, request, self.tuning.submit)


def answer(
    tuning: Any, request: dict[str, Any], submit: Callable[[Mapping[str, Any], Any], list[TuneEvent]]
) -> dict[str, Any]:
    """The answer to one decoded request: ``get`` the law's values, or ``set`` them through
    ``submit(changes, ramp_s)`` (which returns the applied events or raises ConfigError)."""
    law = tuning.law
    if request.get("get"):
        values = {key: _jsonable(value) for key, value in law.parameter_values().items()}
        return {"ok": True, "law": law.name, "parameters": values, "ramp_s": tuning.ramp_s}
    changes = request.get("set")
    if not isinstance(changes, dict):
        return {"ok": False, "error": "expected {'set': {param: value, ...}}"}
    try:
        events = submit(changes, request.get("ramp_s"))
    except ConfigError as err:
        return {"ok": False, "error": str(err)}
    return {"ok": True, "law": law.name, "events": [event.as_dict() for event in events]}


# -- the client ----------------------------------------------------------------------------------
def socket_path(folder: str | Path) -> str:
    """The path to connect to for the run in ``folder`` (the link's target when it is one);
    TuningError when ``folder`` is not a run folder or holds no live run."""
    folder = Path(folder)
    if not folder.is_dir():
        raise TuningError(f"{folder}: no such run folder")
    if not (folder / "config.yaml").is_file():
        raise TuningError(f"{folder}: not a run folder (no config.yaml)")
    path = folder / SOCKET_NAME
    if not path.is_socket():
        raise TuningError(f"{folder}: {_not_live(folder)}")
    return os.path.realpath(path)


def _not_live(folder: Path) -> str:
    """Why ``folder`` has no live run, from its summary.json when it has one."""
    summary = folder / "summary.json"
    if summary.is_file():
        try:
            status = json.loads(summary.read_text()).get("exit_status", "?")
        except (OSError, ValueError):
            status = "?"
        return f"holds no live run: the run has ended (summary.json exit_status {status})"
    return f"holds no live run: no {SOCKET_NAME} (only `sashil run` with a law can be tuned while it runs)"


def request(folder: str | Path, message: dict[str, Any], timeout_s: float = IO_TIMEOUT_S) -> dict[str, Any]:
    """Send one request to the run in ``folder`` and return its answer; TuningError when the run
    cannot be reached or refused the request."""
    path = socket_path(folder)
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as conn:
        conn.settimeout(timeout_s)
        try:
            conn.connect(path)
        except (ConnectionRefusedError, FileNotFoundError):
            raise TuningError(f"{folder}: {_not_live(Path(folder))}") from None
        except PermissionError:
            raise TuningError(f"{folder}/{SOCKET_NAME}: permission denied (the run belongs to another user)") from None
        conn.sendall((json.dumps(message) + "\n").encode())
        raw = b""
        try:
            while not raw.endswith(b"\n"):
                chunk = conn.recv(4096)
                if not chunk:
                    break
                raw += chunk
        except TimeoutError:
            raise TuningError(f"{folder}: the run did not answer within {timeout_s:g} s") from None
    try:
        answer = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise TuningError(f"{folder}: the run ended before it answered") from None
    if not answer.get("ok"):
        raise TuningError(str(answer.get("error", "refused")))
    return dict(answer)
