"""The live part of a rerun recording: a viewer to stream to, on 127.0.0.1 only.

A native viewer when a display exists (and the ``rerun`` executable), else a rerun web-viewer
server process bound to 127.0.0.1, whose URL is printed; the server is stopped with the
recording (or kept serving until Ctrl-C, :meth:`LiveViewer.wait`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from typing import Any

__all__ = ["LiveViewer"]


def port_open(port: int) -> bool:
    """A TCP server listens on 127.0.0.1:``port``."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


def has_display() -> bool:
    """An X11 or Wayland display is available."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class LiveViewer:
    """A viewer for a recording stream (see the module docstring).

    Attributes
    ----------
    server : subprocess.Popen or None
        the web-viewer server process started here (None with a native viewer).
    url : str or None
        the viewer's URL.
    """

    def __init__(self) -> None:
        self.server: subprocess.Popen[bytes] | None = None
        self.url: str | None = None

    def sink(self, rr: Any, rec: Any, web_port: int, grpc_port: int) -> Any:
        """A native viewer if there is a display, else a rerun web-viewer server process
        bound to 127.0.0.1 (gRPC on ``grpc_port``, the page on ``web_port``); returns the
        sink streaming ``rec`` to it (``rr`` the rerun module)."""
        grpc_url = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
        if has_display() and shutil.which("rerun") is not None:
            rr.spawn(port=grpc_port, connect=False, recording=rec)
            self.url = grpc_url
            print(f"rerun viewer spawned ({grpc_url})", file=sys.stderr, flush=True)
            return rr.GrpcSink(grpc_url)
        self.server = subprocess.Popen(
            [sys.executable, "-m", "rerun", "--serve-web", "--bind", "127.0.0.1", "--port",
             str(grpc_port), "--web-viewer-port", str(web_port)],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True)
        deadline = time.monotonic() + 30.0
        while not port_open(grpc_port):
            if self.server.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"the rerun web viewer did not start on 127.0.0.1:"
                                   f"{grpc_port}/{web_port} (ports in use?)")
            time.sleep(0.1)
        self.url = f"http://127.0.0.1:{web_port}/?url={grpc_url}"
        print(f"rerun web viewer: {self.url}", file=sys.stderr, flush=True)
        return rr.GrpcSink(grpc_url)

    def stop(self) -> None:
        """Stop the web-viewer server started here (SIGTERM, then SIGKILL). Idempotent."""
        p = self.server
        if p is None or p.poll() is not None:
            return
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(p.pid, signal.SIGTERM)
        try:
            p.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=5.0)

    def wait(self) -> None:
        """Block until Ctrl-C while the web viewer keeps serving; then stop it. No-op
        without a server."""
        if self.server is None:
            return
        print(f"rerun web viewer still serving at {self.url} (Ctrl-C to stop)",
              file=sys.stderr, flush=True)
        try:
            while self.server.poll() is None:
                time.sleep(0.5)
        except KeyboardInterrupt:
            pass
        finally:
            self.stop()
