"""Numba's `njit`, with numba imported only when a kernel is called with argument types the ahead-of-time
module was not built for (docs/compile.md)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numpy as np

from spooflens.compile import aot

F = TypeVar("F", bound=Callable[..., Any])

_lock = threading.Lock()
_numba_njit: Callable[..., Any] | None = None


class LazyKernel:
    """A kernel. Called from Python, it runs the ahead-of-time build for its arguments' types when there
    is one, else numba's dispatcher (made, and numba imported, at its first such call); each call decides
    afresh, so one call numba must compile never moves the others off their ahead-of-time builds. Inside
    another kernel numba types it as its dispatcher, so kernels call (and inline) kernels as numba's own do."""

    def __init__(self, function: Callable[..., Any], options: dict[str, Any]) -> None:
        self.function = function
        self.options = options
        self._dispatcher: Callable[..., Any] | None = None
        code = function.__code__
        self._arity = code.co_argcount
        self._defaults: tuple[Any, ...] = function.__defaults__ or ()
        self.__name__ = function.__name__
        self.__qualname__ = function.__qualname__
        self.__module__ = function.__module__
        self.__doc__ = function.__doc__

    @property
    def py_func(self) -> Callable[..., Any]:
        """The Python function, as numba's dispatcher names it."""
        return self.function

    def with_defaults(self, args: tuple[Any, ...]) -> tuple[Any, ...]:
        """`args` with the defaults of the parameters left out: one signature for a call with or without
        them, the one the warm-up records and builds ahead of time."""
        missing = self._arity - len(args)
        if 0 < missing <= len(self._defaults):
            return args + self._defaults[len(self._defaults) - missing :]
        return args

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if not kwargs:
            args = self.with_defaults(args)
            ahead = aot.compiled(self.function, args)
            if ahead is not None:  # built at install for these argument types: numba need not start
                return ahead(*args)
        return self.numba_dispatcher()(*args, **kwargs)

    def numba_dispatcher(self) -> Callable[..., Any]:
        """Numba's dispatcher of the kernel (numba imported and the dispatcher made at the first need)."""
        if self._dispatcher is None:
            njit = _numba()
            with _lock:
                if self._dispatcher is None:
                    self._dispatcher = njit(**self.options)(self.function)
        return self._dispatcher

    def __repr__(self) -> str:
        return f"<kernel {self.__module__}.{self.__qualname__}>"


def kernel_array(x: np.ndarray) -> np.ndarray:
    """`x` as the kernels are built for it: C-contiguous and writeable (a view when it is both already). A
    one-epoch slice of a broadcast array is contiguous but read-only: `np.ascontiguousarray` hands it over
    as it is, an argument type no kernel is built for, which cost the first analysis of such a log a
    minute of compiling."""
    return np.require(x, requirements=["C", "W"])


def njit(**options: Any) -> Callable[[F], F]:
    """`numba.njit(**options)`, numba imported at the first call ahead-of-time code cannot answer."""

    def wrap(function: F) -> F:
        return cast(F, LazyKernel(function, options))

    return wrap


def _numba() -> Callable[..., Any]:
    """Numba's `njit`, importing numba and teaching its typing that a kernel called from a kernel is
    that kernel's dispatcher (once: another thread may have done it)."""
    global _numba_njit
    with _lock:
        if _numba_njit is None:
            from numba import njit as numba_njit
            from numba.core import types
            from numba.core.typing.typeof import typeof_impl

            @typeof_impl.register(LazyKernel)
            def _typeof_kernel(kernel: LazyKernel, context: Any) -> Any:
                return types.Dispatcher(kernel.numba_dispatcher())

            _numba_njit = numba_njit
        return _numba_njit
