"""`spooflens view OUT.rrd`: open a recording in the Rerun viewer, with its usage analytics off.

In depth: docs/outputs.md."""

from __future__ import annotations

import http.client
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import quote

import click

from spooflens.errors import ReaderError, SpooflensError


class ViewerError(SpooflensError):
    """The viewer could not be started."""


RRD_MAGIC = b"RRF2"
LOOPBACK = "127.0.0.1"


@contextmanager
def private_rerun_config(base: Mapping[str, str] | None = None) -> Iterator[dict[str, str]]:
    """An environment for a Rerun process whose analytics are off; the config lives as long as the block."""
    with tempfile.TemporaryDirectory(prefix="spooflens-rerun-") as home:
        config = Path(home, "rerun")
        config.mkdir()
        (config / "analytics.json").write_text(
            json.dumps(
                {
                    "analytics_enabled": False,
                    "analytics_id": "spooflens-analytics-off",
                    "metadata": {},
                    "config_file_path": str(config / "analytics.json"),
                    "data_dir_path": str(Path(home, "analytics-data")),
                }
            )
        )
        env = dict(os.environ if base is None else base)
        env["XDG_CONFIG_HOME"] = home
        yield env


def rerun_binary() -> str:
    """The viewer executable rerun-sdk ships. Started directly, not through `python -m rerun`, whose
    wrapper process would leave the viewer running when it is itself stopped."""
    import rerun_cli.__main__ as cli  # type: ignore[import-untyped]

    here = Path(cli.__file__).parent
    bundled = here / "Rerun.app" / "Contents" / "MacOS" / "Rerun"
    for candidate in (os.environ.get("RERUN_CLI_PATH"), bundled if sys.platform == "darwin" else None, here / "rerun"):
        if candidate and Path(candidate).exists():
            return str(candidate)
    found = shutil.which("rerun")
    if found is None:
        raise ViewerError("the Rerun viewer executable was not found (pip install rerun-sdk)")
    return found


def rerun_command(recording: Path, web_port: int | None = None, grpc_port: int = 9876) -> list[str]:
    """The viewer's command line: a native window, or with `web_port` Rerun's web server on loopback."""
    cmd = [rerun_binary()]
    if web_port is not None:
        cmd += ["--serve-web", "--bind", LOOPBACK, "--web-viewer-port", str(web_port), "--port", str(grpc_port)]
    return [*cmd, str(recording)]


def content_security_policy(grpc_port: int) -> str:
    """What the web viewer page may load and connect to: this server, and the recording's data port."""
    data = f"http://{LOOPBACK}:{grpc_port} http://localhost:{grpc_port}"
    return (
        "default-src 'self'; script-src 'self' 'unsafe-inline' 'wasm-unsafe-eval'; "
        "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; font-src 'self' data:; "
        f"worker-src 'self' blob:; connect-src 'self' {data}"
    )


def viewer_url(port: int, grpc_port: int) -> str:
    return f"http://{LOOPBACK}:{port}/?url=" + quote(f"rerun+http://{LOOPBACK}:{grpc_port}/proxy", safe="")


_HOP_BY_HOP = {"connection", "keep-alive", "transfer-encoding", "te", "trailer", "upgrade", "proxy-authenticate"}


def _proxy_handler(upstream_port: int, policy: str) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        """GET from Rerun's web server, passed on with the policy added (the viewer only ever GETs here)."""

        def do_GET(self) -> None:  # http.server's name
            conn = http.client.HTTPConnection(LOOPBACK, upstream_port, timeout=30)
            try:
                conn.request("GET", self.path, headers={"Accept-Encoding": self.headers.get("Accept-Encoding", "")})
                up = conn.getresponse()
                body = up.read()
            except OSError as err:
                self.send_error(502, f"Rerun web server not reachable: {err}")
                return
            finally:
                conn.close()
            self.send_response(up.status)
            for key, value in up.getheaders():
                if key.lower() not in _HOP_BY_HOP | {"content-length", "content-security-policy"}:
                    self.send_header(key, value)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Content-Security-Policy", policy)
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, format: str, *args: object) -> None:  # quiet, like the viewer
            return

    return Handler


def free_port() -> int:
    with socket.socket() as s:
        s.bind((LOOPBACK, 0))
        port: int = s.getsockname()[1]
        return port


def _wait_for_port(port: int, proc: subprocess.Popen[bytes], timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and proc.poll() is None:
        with socket.socket() as s:
            if s.connect_ex((LOOPBACK, port)) == 0:
                return
        time.sleep(0.1)
    raise ViewerError(f"the Rerun web server did not start on {LOOPBACK}:{port}")


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def serve_web(recording: Path, port: int, grpc_port: int) -> int:
    """Rerun's web server on a private loopback port, our policy-adding proxy on `port`, until Ctrl-C."""
    upstream = free_port()
    signal.signal(signal.SIGTERM, _interrupt)  # a terminated `view` still stops its viewer
    with private_rerun_config() as env:
        proc = subprocess.Popen(rerun_command(recording, upstream, grpc_port), env=env)
        server = ThreadingHTTPServer((LOOPBACK, port), _proxy_handler(upstream, content_security_policy(grpc_port)))
        serving = threading.Thread(target=server.serve_forever, daemon=True)
        try:
            _wait_for_port(upstream, proc)
            serving.start()
            click.echo(f"open {viewer_url(port, grpc_port)} (this machine only); Ctrl-C stops it", err=True)
            return proc.wait()
        except KeyboardInterrupt:
            return 0
        finally:
            if serving.is_alive():
                server.shutdown()
            server.server_close()
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()


def check_recording(path: Path) -> None:
    if not path.is_file():
        raise ReaderError(path, "no such recording (write one with `spooflens analyze LOG -o OUT.rrd`)")
    with path.open("rb") as f:
        head = f.read(4)
    if head != RRD_MAGIC:
        raise ReaderError(path, f"not a Rerun recording (starts with {head!r}, expected {RRD_MAGIC!r})")


@click.command()
@click.argument("recording", type=click.Path(path_type=Path))
@click.option("--web", is_flag=True, help=f"Serve the web viewer on {LOOPBACK} instead of opening a window.")
@click.option("--port", type=int, default=9090, show_default=True, help="Web viewer HTTP port (with --web).")
@click.option("--grpc-port", type=int, default=9876, show_default=True, help="Data (gRPC) port (with --web).")
def view(recording: Path, web: bool, port: int, grpc_port: int) -> int:
    """Open RECORDING (.rrd) in the Rerun viewer, usage analytics off; --web serves it on 127.0.0.1."""
    check_recording(recording)
    if web:
        return serve_web(recording, port, grpc_port)
    with private_rerun_config() as env:
        try:
            return subprocess.run(rerun_command(recording), env=env, check=False).returncode
        except KeyboardInterrupt:
            return 0
