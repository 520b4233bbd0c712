"""The numba cache of the batch's compiled code (:mod:`.compiled`), stamped with everything the code is made of.

numba renews a cached function only when its own file changes.  A compiled function contains, though, the machine
code of every function it calls (numba links them in), the classes and modules it uses and the values of the
globals it reads (numba freezes them as constants when it compiles).  :func:`made_of` finds all of them by walking
the globals of the compiled Python functions, recursively, and :func:`jit` caches a function under the stamp of
their contents (:func:`stamp_of`: every source file's bytes and every constant's value), so an edit to a callee in
another module (``core/control/lqr.py``'s ``lqr_u`` in a law's ``pure_step``) or to a constant assigned elsewhere
(``estimators``' ``NIS_WINDOW_S``) is compiled afresh in the next process, and an unchanged one is only loaded.
"""
from __future__ import annotations

import hashlib
import pickle
import sys
import types
from pathlib import Path
from typing import Optional

import numba
import numpy as np
from numba.core.caching import (CompileResultCacheImpl, FunctionCache, IndexDataCacheFile, InTreeCacheLocator,
                                UserProvidedCacheLocator, UserWideCacheLocator)

__all__ = ["jit", "made_of", "stamp_of", "cache_for", "stamped_cache", "load_cached", "cached"]


def _digest(path: str) -> str:
    """sha256 of a source file's bytes, read once per process."""
    if path not in _DIGESTS:
        try:
            _DIGESTS[path] = hashlib.sha256(Path(path).read_bytes()).hexdigest()
        except OSError:   # no file (e.g. <string>): its code is stamped by name only
            _DIGESTS[path] = "-"
    return _DIGESTS[path]


_DIGESTS: dict = {}
_PLAIN = (bool, int, float, complex, str, bytes, type(None))


def _frozen(v):
    """A constant numba freezes into machine code, as text the same in every process; None if ``v`` is none."""
    if isinstance(v, _PLAIN) or isinstance(v, np.generic):
        return repr(v)
    if isinstance(v, tuple):   # a NamedTuple too (by its class's name and its values)
        parts = [_frozen(e) for e in v]
        return None if None in parts else f"{type(v).__qualname__}(" + ",".join(parts) + ")"
    if isinstance(v, np.ndarray):
        return f"array({v.dtype},{v.shape},{hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest()})"
    return None


def _names(code) -> set:
    """The global (and attribute) names ``code`` and the code nested in it read."""
    out = set(code.co_names)
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            out |= _names(c)
    return out


def _module_file(obj):
    mod = sys.modules.get(getattr(obj, "__module__", None) or "")
    return getattr(mod, "__file__", None)


def made_of(fn) -> tuple:
    """What numba compiles into ``fn``: the source files and the frozen constants, as ``(files, constants)`` (both
    sorted).  Found by walking its globals: every function or dispatcher it calls by a global name (numba links
    their machine code into ``fn``'s), recursively; every module it reads attributes of (and those attributes); the
    module of every class or other object it uses; and every constant it reads (numba freezes a global's value when
    it compiles, wherever the value was assigned: stamped by value)."""
    files, consts, seen, todo = set(), set(), set(), [fn]

    def visit(where, name, v, names, through_module=False):
        if isinstance(v, types.ModuleType):
            files.add(getattr(v, "__file__", None))
            for attr in names:   # the attributes of the module the code may read
                a = vars(v).get(attr)
                if a is not None and not isinstance(a, types.ModuleType):
                    visit(where, f"{v.__name__}.{attr}", a, (), through_module=True)
            return
        if hasattr(v, "py_func"):   # a numba dispatcher: its machine code is linked in
            todo.append(v.py_func)
            return
        if isinstance(v, types.FunctionType):
            if not through_module:   # a plain function numba is handed by name (np.sin: numba's own)
                todo.append(v)
            files.add(_module_file(v))
            return
        if isinstance(getattr(v, "_defn", None), types.FunctionType):   # a numba @intrinsic
            todo.append(v._defn)
        frozen = _frozen(v)
        if frozen is not None:
            consts.add(f"{where}:{name}={frozen}")
        else:   # a class (its module), or an object of one (its class's module, and its own where it has one)
            files.update((_module_file(v), _module_file(type(v))))

    while todo:
        f = todo.pop()
        if id(f) in seen:
            continue
        seen.add(id(f))
        files.add(f.__code__.co_filename)
        names = _names(f.__code__)
        where = f"{f.__module__}.{f.__qualname__}"
        for name in sorted(names):
            if name in f.__globals__:
                visit(where, name, f.__globals__[name], names)
        for i, d in enumerate(f.__defaults__ or ()):
            visit(where, f"default{i}", d, names)
    return tuple(sorted(p for p in files if p)), tuple(sorted(consts))


def stamp_of(fn) -> str:
    """The stamp of ``fn``'s compiled code: the contents of every file and the value of every constant it is made
    of (:func:`made_of`)."""
    files, consts = made_of(fn)
    h = hashlib.sha256()
    for p in files:
        h.update(f"{p}\0{_digest(p)}\0".encode())
    for c in consts:
        h.update(c.encode() + b"\0")
    return h.hexdigest()


class _Stamped:
    stamp = ""

    def get_source_stamp(self):
        return self.stamp   # numba's own stamp covers the function's file only


class _UserProvided(_Stamped, UserProvidedCacheLocator):
    pass


class _InTree(_Stamped, InTreeCacheLocator):
    pass


class _UserWide(_Stamped, UserWideCacheLocator):
    pass


_LOCATORS = [_UserProvided, _InTree, _UserWide]   # numba's order: NUMBA_CACHE_DIR first


class _Index(IndexDataCacheFile):
    """numba's index of a function's cache files, where an index that no longer unpickles is stale (as one of another
    stamp: the function is compiled afresh and the index written anew) instead of an error.  An index names the
    classes of its signatures by module (a NamedTuple argument: ``compiled.Inertia``), so one written before a module
    moved or a class was renamed raises ImportError or AttributeError in numba's own ``_load_index``."""

    def _load_index(self):
        try:
            return super()._load_index()
        except (ImportError, AttributeError, pickle.UnpicklingError):
            return {}


def stamped_cache(stamp: str, tag: str = "") -> type:
    """A numba function cache whose locators stamp with ``stamp``, in files of their own for ``tag``.

    numba keeps one index file per function and renews it whenever the stamp differs, so two builds of one
    function (one per lane width) under one file name would each throw the other's machine code away: a
    process without lanes after one with lanes (the tests run both) compiled everything again."""
    locs = [type(c.__name__, (c,), {"stamp": stamp}) for c in _LOCATORS]

    def get_filename_base(self, fullname, abiflags):
        return CompileResultCacheImpl.get_filename_base(self, f"{fullname}__{tag}" if tag else fullname, abiflags)
    impl = type("_Impl", (CompileResultCacheImpl,), {"_locator_classes": locs,
                                                     "get_filename_base": get_filename_base})

    def __init__(self, py_func):
        FunctionCache.__init__(self, py_func)
        self._cache_file.__class__ = _Index   # numba's index, read as above
    return type("_StampedCache", (FunctionCache,), {"_impl_class": impl, "__init__": __init__})


_CACHES: dict = {}


def cache_for(fn, tag: str = "") -> type:
    """The cache class of ``fn``'s compiled code: stamped with :func:`stamp_of`, in files of their own for
    ``tag``."""
    key = (stamp_of(fn), tag)
    if key not in _CACHES:
        _CACHES[key] = stamped_cache(*key)
    return _CACHES[key]


def jit(fn, tag: str = ""):
    """numba's nopython compilation of ``fn``, cached under the stamp of everything it is made of
    (:func:`made_of`), in files of their own for ``tag``."""
    compiled = numba.njit(error_model="numpy")(fn)
    try:
        # what ``cache=True`` sets, with the stamp above (numba's stubs do not declare the Dispatcher's _cache)
        compiled._cache = cache_for(fn, tag)(compiled.py_func)   # type: ignore[attr-defined]
    except RuntimeError:   # no writable cache directory: compile in every process
        pass
    return compiled


def load_cached(kernel, args) -> None:
    """Load ``kernel``'s machine code for ``args``' types from numba's cache, if there and not yet loaded, without
    the refresh of its whole compiler that numba's own first call makes (about 0.2 s of a sweep worker's start-up:
    numba's lowering modules and, through them, scipy.linalg); the machine code needs only numba's runtime.  Anything
    else (nothing cached, numba's internals changed) is left to the first call, which loads or compiles as usual."""
    try:
        from numba.core.compiler_lock import global_compiler_lock
        from numba.core.runtime import rtsys
        if kernel.overloads:
            return
        cache = kernel._cache
        if not hasattr(cache, "_load_overload"):
            return   # no cache (no writable directory)
        with global_compiler_lock:   # as numba's own loading
            ctx = kernel.targetctx
            sig = tuple(kernel.typeof_pyval(a) for a in args)
            rtsys.initialize(ctx)
            cres = cache._load_overload(sig, ctx)   # numba's Cache.load_overload but for its ctx.refresh()
            if cres is not None and not kernel.overloads:
                kernel.add_overload(cres)
    except Exception:  # noqa: BLE001 - the first call loads it the usual way
        pass


def cached(kernel) -> Optional[bool]:
    """Whether numba's cache holds machine code of ``kernel`` (a :func:`jit` dispatcher) for this machine under its
    current stamp: True (a call loads it), False (the first call compiles it: tens of seconds for the batch loop),
    None when it cannot tell (no cache directory, numba's internals other than these)."""
    try:
        if kernel.overloads:
            return True
        cache = kernel._cache
        if not hasattr(cache, "_cache_file"):
            return None
        target = kernel.targetctx.codegen().magic_tuple()
        return any(key[1] == target for key in cache._cache_file._load_index())
    except Exception:  # noqa: BLE001 - numba's internals changed: not known
        return None
