"""The kernels an analysis calls, compiled ahead of time into one extension module at install, used only
while it matches what it was built from; any other call goes to numba (docs/compile.md)."""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import json
import os
import platform
import re
import sys
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

MODULE = "spooflens_aot_kernels"
FOLDER = Path(__file__).resolve().parents[1] / "__pycache__"
MANIFEST = FOLDER / f"{MODULE}.json"
PACKAGES = tuple(Path(__file__).resolve().parents[2] / name for name in ("spooflens", "readers"))
ENV = "SPOOFLENS_AOT"

Key = Any  # a nested tuple of strings and ints (see `type_key`)

_lock = threading.Lock()
_table: dict[tuple[str, Key], Callable[..., Any]] | None = None
disabled = False  # the warm-up compiles with numba: no call may bypass it there


def kernel_name(function: Callable[..., Any]) -> str:
    return f"{function.__module__}:{function.__qualname__}"


def _scalar_key(dtype: np.dtype) -> str:
    return "b1" if dtype.kind == "b" else dtype.str.lstrip("<|=")


def type_key(value: object) -> Key | None:
    """What numba's `typeof` makes of `value`, as a hashable key: arrays by dtype, dimensions, layout
    ('C' when C-contiguous, else 'F' when Fortran-contiguous, else 'A'), writeability and alignment;
    Python bool, int and float as boolean, int64 and float64; numpy scalars by their dtype; tuples
    element by element. None for anything else (never compiled ahead of time)."""
    if isinstance(value, np.ndarray):
        flags = value.flags
        layout = "C" if flags.c_contiguous else "F" if flags.f_contiguous else "A"
        return ("a", _scalar_key(value.dtype), value.ndim, layout, bool(flags.writeable), bool(flags.aligned))
    if isinstance(value, bool | np.bool_):
        return "b1"
    if isinstance(value, int):
        return "i8" if -(2**63) <= value < 2**63 else None
    if isinstance(value, float):
        return "f8"
    if isinstance(value, np.integer | np.floating):
        return _scalar_key(value.dtype)
    if isinstance(value, tuple):
        keys = tuple(type_key(v) for v in value)
        return None if any(k is None for k in keys) else ("t", *keys)
    return None


def numba_type_key(ty: Any) -> Key | None:
    """`type_key` of the values numba types as `ty` (build time: numba is imported)."""
    from numba import types
    from numba.np.numpy_support import as_dtype

    if isinstance(ty, types.Array):
        return ("a", _scalar_key(as_dtype(ty.dtype)), ty.ndim, ty.layout, bool(ty.mutable), bool(ty.aligned))
    if isinstance(ty, types.Boolean):
        return "b1"
    if isinstance(ty, types.Integer | types.Float):
        return _scalar_key(as_dtype(ty))
    if isinstance(ty, types.BaseTuple):
        keys = tuple(numba_type_key(t) for t in ty)  # type: ignore[attr-defined]  # UniTuple or Tuple
        return None if any(k is None for k in keys) else ("t", *keys)
    return None


def kernel_sources(packages: Sequence[Path] = PACKAGES) -> list[Path]:
    """The project's source files that define kernels (their text names `njit(`), and the project's
    modules those import (numba freezes a global such as a WGS84 constant into the compiled code)."""
    root = packages[0].parent
    names = {folder.name for folder in packages}
    texts = {p: p.read_text() for folder in packages for p in folder.rglob("*.py")}
    kernels = {p for p, text in texts.items() if "njit(" in text}
    imported = set()
    for path in kernels:
        for module in re.findall(r"^from ([\w.]+) import", texts[path], re.MULTILINE):
            if module.split(".")[0] in names:
                base = root.joinpath(*module.split("."))
                imported |= {p for p in (base.with_suffix(".py"), base / "__init__.py") if p.exists()}
    return sorted(kernels | imported)


def digests(paths: Iterable[Path], root: Path = PACKAGES[0].parent) -> dict[str, str]:
    """sha256 of each file, by its path relative to `root`."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in paths}


def _cpu() -> str:
    """The CPU the module is built for and runs on (model and feature flags, from the kernel)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.machine()
    lines = [ln for ln in text.splitlines() if ln.startswith(("model name", "flags", "Features", "CPU part"))]
    return hashlib.sha256("\n".join(dict.fromkeys(lines)).encode()).hexdigest()


def _build_facts() -> dict[str, str]:
    return {"python": sys.implementation.cache_tag, "numpy": np.__version__, "cpu": _cpu()}


def _library_path() -> Path:
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    return FOLDER / f"{MODULE}{suffix}"


def _load() -> dict[tuple[str, Key], Callable[..., Any]]:
    """The table of compiled kernels, or {} when the module is missing, stale or unloadable."""
    if disabled or os.environ.get(ENV, "").strip() == "0":
        return {}
    try:
        manifest = json.loads(MANIFEST.read_text())
        if manifest.get("facts") != _build_facts():
            return {}
        sources = manifest["sources"]
        root = PACKAGES[0].parent
        if digests(root / name for name in sources) != sources:
            return {}
        path = _library_path()
        loader = importlib.machinery.ExtensionFileLoader(MODULE, str(path))
        spec = importlib.util.spec_from_file_location(MODULE, path, loader=loader)
        if spec is None:
            return {}
        module = importlib.util.module_from_spec(spec)
        loader.exec_module(module)
        return {(e["kernel"], _as_key(e["key"])): getattr(module, e["name"]) for e in manifest["exports"]}
    except (OSError, ValueError, KeyError, TypeError, ImportError, AttributeError):
        return {}


def _as_key(value: Any) -> Key:
    """A key read back from JSON (lists) as the tuples `type_key` makes."""
    return tuple(_as_key(v) for v in value) if isinstance(value, list) else value


def compiled(function: Callable[..., Any], args: tuple[object, ...]) -> Callable[..., Any] | None:
    """The ahead-of-time compiled `function` for these arguments' types, or None (numba's JIT then)."""
    global _table
    if _table is None:
        with _lock:
            if _table is None:
                _table = _load()
    if not _table:
        return None
    key = type_key(args)
    return None if key is None else _table.get((kernel_name(function), key))


def forget() -> None:
    """Load the table again at the next call (after a build, or in tests)."""
    global _table
    with _lock:
        _table = None


def build(signatures: Iterable[tuple[Any, Any]], regular: bool = True) -> int:
    """Compile each (numba dispatcher, full signature) into the extension module and write its manifest;
    the number of functions exported. Run by the warm-up, with numba imported. With `regular`, each
    signature with a read-only array of any layout (a broadcast view: the filter's one measurement
    matrix of a log without odometry) is also built with that array C-contiguous and writeable (the
    same argument made whole: a log with odometry), which the warm-up's sample logs do not reach."""
    import tempfile
    import warnings

    import numba.pycc.compiler as pycc_compiler
    from numba.pycc import CC

    plain_compile: Any = pycc_compiler.compile_extra

    def compile_export(*args: Any, **kwargs: Any) -> Any:
        """pycc's compile of one export, on flags of its own that release Python's lock as the `nogil`
        kernels do (pycc has no such option, and passes every export one Flags object, which numba's
        pipeline changes: the second export lost SSA and failed to type)."""
        flags = args[5].copy()
        flags.release_gil = True
        return plain_compile(*args[:5], flags, *args[6:], **kwargs)

    exports: list[dict[str, Any]] = []
    cc = CC(MODULE)
    cc.verbose = False
    cc.output_file = _library_path().name
    cc.target_cpu = "host"  # built where it runs (the manifest names the CPU), as numba's JIT does
    seen: set[tuple[str, Key]] = set()
    for dispatcher, signature in ((d, v) for d, s in signatures for v in _variants(s, regular)):
        key = numba_type_key(_tuple_type(signature.args))
        name = kernel_name(dispatcher.py_func)
        if key is None or (name, key) in seen:
            continue
        seen.add((name, key))
        export = f"k{len(exports)}"
        cc.export(export, signature)(dispatcher.py_func)
        exports.append({"kernel": name, "key": key, "name": export})
    if not exports:
        return 0
    FOLDER.mkdir(exist_ok=True)
    MANIFEST.unlink(missing_ok=True)  # no manifest while the module is replaced: nothing loads it half-made
    with tempfile.TemporaryDirectory(dir=FOLDER) as tmp:
        cc.output_dir = tmp
        pycc_compiler.compile_extra = compile_export
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # pycc's pending deprecation, once per build
                cc.compile()
        finally:
            pycc_compiler.compile_extra = plain_compile
        # a new file in its place: a process that has the old one mapped keeps reading the old one
        (Path(tmp) / _library_path().name).replace(_library_path())
    manifest = {"facts": _build_facts(), "sources": digests(kernel_sources()), "exports": exports}
    MANIFEST.write_text(json.dumps(manifest))
    forget()
    return len(exports)


def _variants(signature: Any, regular: bool) -> Iterator[Any]:
    """The signature, and with `regular` its variant with every read-only 'A' array C and writeable."""
    yield signature
    if regular:
        args = tuple(_regular(a) for a in signature.args)
        if args != tuple(signature.args):
            yield signature.replace(args=args)


def _regular(ty: Any) -> Any:
    from numba import types

    if isinstance(ty, types.Array) and not ty.mutable and ty.layout == "A":
        return types.Array(ty.dtype, ty.ndim, "C")
    if isinstance(ty, types.BaseTuple):
        return types.Tuple(tuple(_regular(t) for t in ty))  # type: ignore[attr-defined]
    return ty


def _tuple_type(args: Sequence[Any]) -> Any:
    from numba import types

    return types.Tuple(tuple(args))
