"""Numba's `njit`, with numba imported only when a compiled kernel is first called (and not at all when
the ahead-of-time module has the kernel for its arguments' types; docs/compile.md)."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable
from typing import Any, TypeVar, cast

from spooflens.compile import aot

F = TypeVar("F", bound=Callable[..., Any])

# modules whose globals may hold a kernel (their own, or one imported from another module)
_PACKAGES = ("spooflens", "readers")

_lock = threading.Lock()
_pending: list[LazyKernel] = []
_numba_njit: Callable[..., Any] | None = None


class LazyKernel:
    """A kernel not compiled yet: called, it makes every pending kernel's dispatcher and calls its own."""

    def __init__(self, function: Callable[..., Any], options: dict[str, Any]) -> None:
        self.function = function
        self.options = options
        self.dispatcher: Callable[..., Any] | None = None
        self.__name__ = function.__name__
        self.__qualname__ = function.__qualname__
        self.__module__ = function.__module__
        self.__doc__ = function.__doc__

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if self.dispatcher is None:
            ahead = None if kwargs else aot.compiled(self.function, args)
            if ahead is not None:  # built at install for these argument types: numba need not start
                return ahead(*args)
            dispatch_all()
        assert self.dispatcher is not None
        return self.dispatcher(*args, **kwargs)

    def __repr__(self) -> str:
        return f"<kernel {self.__module__}.{self.__qualname__}, not compiled yet>"


def njit(**options: Any) -> Callable[[F], F]:
    """`numba.njit(**options)`, numba imported at the first call of a kernel (see the module)."""

    def wrap(function: F) -> F:
        with _lock:
            if _numba_njit is not None:
                return cast(F, _numba_njit(**options)(function))
            kernel = LazyKernel(function, options)
            _pending.append(kernel)
            return cast(F, kernel)

    return wrap


def dispatch_all() -> None:
    """Import numba, make the dispatcher of every kernel defined so far and rebind the names that held
    the wrappers (once: another thread may have done it)."""
    global _numba_njit
    with _lock:
        if _numba_njit is None:
            from numba import njit as numba_njit

            _numba_njit = numba_njit
        for kernel in _pending:
            kernel.dispatcher = _numba_njit(**kernel.options)(kernel.function)
        _pending.clear()
        for name, module in list(sys.modules.items()):
            if module is None or name.split(".", 1)[0] not in _PACKAGES:
                continue
            names = vars(module)
            for key, value in list(names.items()):
                if isinstance(value, LazyKernel) and value.dispatcher is not None:
                    names[key] = value.dispatcher
