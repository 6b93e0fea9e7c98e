"""Reference kernels run as their Python source within a block of a test.

No analysis calls the seed-000 paper's two-filter MLRT or the Willsky-Jones reference figures
(`paper_two_filter`, `full_jump_wj`, `full_jump_constants`, `two_filter_smoother`, `backward_information`):
the warm-up never compiles them, so a test that called them compiled in each CI run with numba, about
a minute and a half of compiling for inputs of a few dozen epochs. Within `python_kernels()`, a kernel
called with argument types the ahead-of-time module was built for runs that build, as in an analysis;
any other runs as its Python source (numba's semantics on these kernels: plain numpy), never compiled."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from spooflens.compile import aot, jit


def _call(self: jit.LazyKernel, *args: Any, **kwargs: Any) -> Any:
    if not kwargs:
        args = self.with_defaults(args)
        ahead = aot.compiled(self.function, args)
        if ahead is not None:
            return ahead(*args)
    return self.function(*args, **kwargs)


@contextmanager
def python_kernels() -> Iterator[None]:
    """Within the block, kernels without an ahead-of-time build for their arguments run as Python."""
    plain = jit.LazyKernel.__call__
    jit.LazyKernel.__call__ = _call  # type: ignore[method-assign]
    try:
        yield
    finally:
        jit.LazyKernel.__call__ = plain  # type: ignore[method-assign]
