"""The warm-up's care of numba's on-disk cache."""

from __future__ import annotations

from pathlib import Path


def test_the_warm_up_empties_numbas_cache_when_any_kernel_source_changed(tmp_path: Path) -> None:
    """Numba keys a kernel's cache by its own file: a kernel inlining one from another file kept stale
    code when only that file changed. The warm-up empties the whole cache when any kernel source differs
    from its last run's, and leaves it when none does."""
    from spooflens.compile.warmup import clear_stale_numba_cache

    package, other = tmp_path / "pkg", tmp_path / "other"
    for folder in (package, other):
        (folder / "__pycache__").mkdir(parents=True)
    (package / "update.py").write_text("@njit(cache=True)\ndef update(x):\n    return x\n")
    (other / "loop.py").write_text(
        "from pkg.update import update\n@njit(cache=True)\ndef loop(x):\n    return update(x)\n"
    )
    cached = [other / "__pycache__" / "loop.loop-3.py311.nbi", other / "__pycache__" / "loop.loop-3.py311.1.nbc"]

    def fill() -> None:
        for path in cached:
            path.write_bytes(b"machine code")

    fill()
    assert clear_stale_numba_cache((package, other))  # no record of a warm-up: emptied
    assert not any(p.exists() for p in cached)
    fill()
    assert not clear_stale_numba_cache((package, other))  # nothing changed: kept
    assert all(p.exists() for p in cached)
    (package / "update.py").write_text("@njit(cache=True)\ndef update(x):\n    return x + 1\n")
    assert clear_stale_numba_cache((package, other))  # only the callee's file changed: the caller's goes too
    assert not any(p.exists() for p in cached)
