"""Compile every numba kernel into numba's cache and ahead of time into one extension module, and the
project's modules to bytecode, before the first analysis needs them (docs/compile.md).

    python -m spooflens.compile.warmup [LOG ...]
"""

from __future__ import annotations

import compileall
import json
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from spooflens.compile import aot
from spooflens.compile.aot import PACKAGES
from spooflens.errors import one_line

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"
# the spoofed flight reaches every kernel (filter, smoother, detectors, the second pass, the coasts that
# confirm an incident); the car adds the ground-vehicle paths (course-over-ground yaw)
SAMPLE_LOGS = ("spoofed_flight.mcap", "ground_ros2.mcap")


NUMBA_CACHE_STAMP = "numba_cache_sources.json"  # in spooflens/__pycache__: the kernel sources numba's cache is of


def clear_stale_numba_cache(packages: tuple[Path, ...] = PACKAGES) -> bool:
    """Empty numba's on-disk cache when any kernel source differs from the last warm-up's; True if it did.

    Numba keys a kernel's cache by its own source file only: a kernel that inlines or calls one defined
    in another file keeps its old machine code when only that other file changed (the navigation filter
    inlines `kalman_update.update_into`). So after any change the whole cache is compiled afresh."""
    stamp = packages[0] / "__pycache__" / NUMBA_CACHE_STAMP
    current = aot.digests(aot.kernel_sources(packages), packages[0].parent)
    try:
        last = json.loads(stamp.read_text())
    except (OSError, ValueError):
        last = None
    if last == current:
        return False
    for folder in packages:
        for cached in (*folder.rglob("__pycache__/*.nbi"), *folder.rglob("__pycache__/*.nbc")):
            cached.unlink(missing_ok=True)
    stamp.parent.mkdir(exist_ok=True)
    stamp.write_text(json.dumps(current, indent=1))  # what the cache is compiled from from now on
    return True


def default_logs() -> list[Path]:
    return [SAMPLES / name for name in SAMPLE_LOGS if (SAMPLES / name).exists()]


def _simulated_spoofed_flight(folder: Path) -> Path:
    from spooflens.attacks import apply_attack, parse_attack
    from spooflens.simulation.simulate import simulate
    from spooflens.writers import write_log

    table = simulate("aircraft", seed=7, duration_s=240.0).table
    spoofed, _ = apply_attack(table, parse_attack("ramp:rate=2,axes=en,start=150"))
    path = folder / "warmup.mcap"
    write_log(spoofed, path, "mcap-ros2")
    return path


def warm(logs: list[Path] | None = None, called: list[tuple[Any, Any]] | None = None) -> list[tuple[str, float]]:
    """Analyse `logs` (default: see the module) end to end with numba (never the kernels compiled ahead of
    time); (log, seconds) of each. `called`, when given, receives each (dispatcher, signature) a call
    from Python compiled or loaded: the signatures `spooflens.compile.aot` builds."""
    done: list[tuple[str, float]] = []
    aot.disabled = True
    aot.forget()
    try:
        _warm_each(logs, called, done)
    finally:
        aot.disabled = False
        aot.forget()
    return done


def _warm_each(logs: list[Path] | None, called: list[tuple[Any, Any]] | None, done: list[tuple[str, float]]) -> None:
    from spooflens.estimation import marginalised_likelihood
    from spooflens.service import analyse_log, write_outputs

    with tempfile.TemporaryDirectory() as tmp, _recording_calls(called):
        folder = Path(tmp)
        chosen = logs or default_logs() or [_simulated_spoofed_flight(folder)]
        for log in chosen:
            t0 = time.perf_counter()
            analyses = analyse_log(log, (), None, quiet=True)
            write_outputs(analyses, folder / "warmup.rrd", folder / "warmup.json", None)
            done.append((log.name, time.perf_counter() - t0))
        # a log whose offline pass keeps too much to run its two filters side by side (a day at 1 Hz)
        # takes its bounded form, a kernel of its own: the last log once more, that way
        t0, keep = time.perf_counter(), marginalised_likelihood.OFFLINE_KEEP_BYTES
        marginalised_likelihood.OFFLINE_KEEP_BYTES = 0
        try:
            analyse_log(chosen[-1], (), None, quiet=True)
        finally:
            marginalised_likelihood.OFFLINE_KEEP_BYTES = keep
        done.append((f"{chosen[-1].name} (long-log offline pass)", time.perf_counter() - t0))


@contextmanager
def _recording_calls(called: list[tuple[Any, Any]] | None) -> Iterator[None]:
    """Within the block, every kernel signature a call from Python makes numba compile or load (its
    first call with those types in this process) is appended to `called`."""
    if called is None:
        yield
        return
    from numba.core import dispatcher

    target: Any = dispatcher.Dispatcher  # numba's own typing of the class knows no such method
    plain = target._compile_for_args

    def recording(self: Any, *args: Any, **kws: Any) -> Any:
        result = plain(self, *args, **kws)
        if not kws and not any(isinstance(a, dispatcher.OmittedArg) for a in args):
            cres = self.overloads.get(tuple(self.typeof_pyval(a) for a in args))
            if cres is not None:
                called.append((self, cres.signature))
        return result

    target._compile_for_args = recording
    try:
        yield
    finally:
        target._compile_for_args = plain


def compile_bytecode(packages: tuple[Path, ...] = PACKAGES) -> bool:
    """Write the bytecode (`__pycache__/*.pyc`) of every module under `packages`, whatever
    `PYTHONDONTWRITEBYTECODE` says; True when every module compiled."""
    compiled = [compileall.compile_dir(folder, quiet=1) for folder in packages]  # each, whatever came before
    return all(compiled)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    t0 = time.perf_counter()
    if compile_bytecode():
        print(f"spooflens warm-up: bytecode of {', '.join(p.name for p in PACKAGES)} written", flush=True)
    else:
        print("spooflens warm-up: some modules did not compile to bytecode (they compile at each import)", flush=True)
    if clear_stale_numba_cache():
        print("spooflens warm-up: kernel sources changed since the last warm-up: numba's cache made afresh", flush=True)
    called: list[tuple[Any, Any]] = []
    for name, seconds in warm([Path(a) for a in args] or None, called):
        print(f"spooflens warm-up: {name} analysed in {seconds:.1f} s", flush=True)
    print(f"spooflens warm-up: numba kernels compiled and cached in {time.perf_counter() - t0:.0f} s", flush=True)
    t1 = time.perf_counter()
    try:
        try:
            exported = aot.build(called)
        except Exception:  # noqa: BLE001 - the variants are a guess at what other logs call: without them
            exported = aot.build(called, regular=False)
    except Exception as err:  # noqa: BLE001 - without the module every kernel runs from numba's cache, as before
        print(f"spooflens warm-up: kernels not compiled ahead of time ({one_line(err)}): numba loads them", flush=True)
    else:
        took = time.perf_counter() - t1
        print(f"spooflens warm-up: {exported} kernel signatures compiled ahead of time in {took:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
