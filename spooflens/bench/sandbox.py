"""Run `spooflens` commands, each in a process of its own, with a time limit and a memory cap.

A fresh interpreter per input spends seconds importing numpy, pandas and the compiled navigation
kernels before it reads a byte. So a sandbox is a small server process, started as a fresh interpreter, that
imports the CLI and warms the kernels once, then forks one child per request: the child runs
`spooflens.cli.main(argv)` exactly as the command line would, with its stdout and stderr in files, its
address space capped (RLIMIT_AS, so a runaway allocation is a MemoryError, not a machine swapping), and
is killed when it runs past its time or its resident memory passes the cap. The server is
single-threaded, so forking it is safe; the caller (which may draw progress bars with a thread) only
talks to it through a pipe.
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import signal
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

POLL_S = 0.02


@dataclass(frozen=True)
class Limits:
    timeout_s: float = 120.0
    rss_cap_mb: float = 1024.0  # killed above this resident size
    address_space_mb: float = 4096.0  # RLIMIT_AS of the child


@dataclass(frozen=True)
class RunResult:
    """How one command ended: `exit_code` when it exited by itself, else `killed` says why."""

    exit_code: int | None
    killed: str | None  # "timeout", "rss" (our kill), "signal N" (anything else)
    peak_rss_mb: float
    seconds: float
    stderr_tail: str

    @property
    def outcome(self) -> str:
        """exit-0/2/3/4 (as documented), internal (exit 1 or an undocumented code), timeout, rss, signal."""
        if self.killed is not None:
            return self.killed.split()[0]
        if self.exit_code in (0, 2, 3, 4):
            return f"exit-{self.exit_code}"
        return "internal"


def _read_rss_mb(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/status") as f:  # noqa: PTH123 - a proc file, read once per poll
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0.0


def _child(argv: list[str], workdir: Path, limits: Limits) -> None:
    """In the forked child: cap memory, redirect output, run the command, exit with its code."""
    code = 1
    try:
        os.chdir(workdir)
        cap = int(limits.address_space_mb * 1024 * 1024)
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
        for fd, name in ((1, "stdout.txt"), (2, "stderr.txt")):
            out = os.open(workdir / name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(out, fd)
            os.close(out)
        from spooflens.cli import main

        code = main(argv)
    except BaseException as err:  # noqa: BLE001 - whatever escapes main is an internal error, reported
        with contextlib.suppress(BaseException):
            os.write(2, f"escaped main: {type(err).__name__}: {err}\n".encode())
        code = 1
    finally:
        with contextlib.suppress(BaseException):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(code if 0 <= code < 256 else 1)


def run_forked(argv: list[str], workdir: Path, limits: Limits) -> RunResult:
    """Fork, run `argv` in the child, watch it; only call from a single-threaded process."""
    workdir.mkdir(parents=True, exist_ok=True)
    start = time.monotonic()
    pid = os.fork()
    if pid == 0:
        _child(argv, workdir, limits)
    killed: str | None = None
    peak = 0.0
    while True:
        wpid, status, usage = os.wait4(pid, os.WNOHANG)
        if wpid:
            break
        rss = _read_rss_mb(pid)
        peak = max(peak, rss)
        if killed is None and time.monotonic() - start > limits.timeout_s:
            killed = "timeout"
        elif killed is None and rss > limits.rss_cap_mb:
            killed = "rss"
        if killed is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            _, status, usage = os.wait4(pid, 0)
            break
        time.sleep(POLL_S)
    seconds = time.monotonic() - start
    peak = max(peak, usage.ru_maxrss / 1024)  # ru_maxrss is in KiB on Linux
    exit_code: int | None = None
    if os.WIFEXITED(status):
        exit_code = os.WEXITSTATUS(status)
    elif killed is None:
        killed = f"signal {os.WTERMSIG(status)}"
    if killed is None and peak > limits.rss_cap_mb:
        killed = "rss"
    return RunResult(exit_code, killed, peak, seconds, _stderr_tail(workdir / "stderr.txt"))


def _stderr_tail(path: Path) -> str:
    """The command's own error lines (`spooflens: ...`), else the last lines it wrote."""
    try:
        lines = path.read_text(errors="replace").strip().splitlines()
    except OSError:
        return ""
    own = [line for line in lines if line.startswith("spooflens:")]
    return "\n".join(own[-3:] or lines[-3:])


def serve(warm_argv: list[str]) -> None:
    """The server's main: import and warm up once, then run each request (a JSON line on stdin) in a
    forked child and answer with a JSON line on the original stdout."""
    answers = os.fdopen(os.dup(1), "w")
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    os.dup2(null, 2)
    import spooflens.cli

    if warm_argv:
        with contextlib.suppress(Exception):
            spooflens.cli.main(warm_argv)
    answers.write("ready\n")
    answers.flush()
    for line in sys.stdin:
        request = json.loads(line)
        result = run_forked(request["argv"], Path(request["workdir"]), Limits(**request["limits"]))
        answers.write(json.dumps(asdict(result)) + "\n")
        answers.flush()


class Sandbox:
    """One server process; `submit` a command, `result` waits for it. Use as a context manager."""

    def __init__(self, warm_argv: list[str] | None = None) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", __name__, json.dumps(warm_argv or [])],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.process.stdin is not None and self.process.stdout is not None
        self._in, self._out = self.process.stdin, self.process.stdout
        if self._out.readline().strip() != "ready":
            raise RuntimeError("sandbox server did not start")
        self.busy = False

    def fileno(self) -> int:
        """The answer pipe, for selectors waiting on several sandboxes."""
        return self._out.fileno()

    def submit(self, argv: list[str], workdir: Path, limits: Limits) -> None:
        self._in.write(json.dumps({"argv": argv, "workdir": str(workdir), "limits": asdict(limits)}) + "\n")
        self._in.flush()
        self.busy = True

    def result(self) -> RunResult:
        line = self._out.readline()
        if not line:
            raise RuntimeError("sandbox server died")
        self.busy = False
        return RunResult(**json.loads(line))

    def run(self, argv: list[str], workdir: Path, limits: Limits) -> RunResult:
        self.submit(argv, workdir, limits)
        return self.result()

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._in.close()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self._out.close()

    def __enter__(self) -> Sandbox:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


if __name__ == "__main__":
    serve(json.loads(sys.argv[1]))
