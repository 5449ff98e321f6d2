"""Numba flags in one place (STYLE: one switch for cache/nogil/fastmath), where the compiled
kernels are cached, and the one intrinsic the kernel needs that numba lacks (a cache prefetch).

``nogil=True`` keeps Dask worker heartbeats alive during long kernel calls;
``fastmath`` stays off so that incremental and full costs agree and runs are bit-identical.
"""

import hashlib
import shutil
import time
from pathlib import Path

import numba
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

_PACKAGE = Path(__file__).resolve().parent
# Every module with jitted code, and the modules whose constants it compiles in.
_KERNEL_SOURCES = ("_jit.py", "engine", "kernel", "model")


def kernel_digest() -> str:
    """SHA-256 (16 hex digits) of the kernels' source: every ``.py`` file of :data:`_KERNEL_SOURCES`."""
    digest = hashlib.sha256()
    for name in _KERNEL_SOURCES:
        root = _PACKAGE / name
        for path in sorted(root.rglob("*.py")) if root.is_dir() else [root]:
            digest.update(path.relative_to(_PACKAGE).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def kernel_cache_dir() -> Path:
    """Where numba caches this package's kernels: one directory per version of their source,
    shared by every copy of the package (a clone, its editable install, a site-packages copy)."""
    from numba.misc.appdirs import AppDirs

    return Path(AppDirs(appname="vasc_pipeline", appauthor=False).user_cache_dir) / f"numba-{kernel_digest()}"


def _install_cache_locator() -> None:
    """Cache the kernels in :func:`kernel_cache_dir` instead of beside each copy of the source.

    Numba keys its cache by the source file's directory, so a run inside the clone (which imports
    the clone) and one elsewhere (the installed copy) compiled the same kernels twice. Keyed by the
    content of every kernel module instead, a copy with the same source finds the cache, and an
    edit of any kernel module (also of a callee inlined into another module's kernel, which numba's
    own per-file check misses) starts a fresh one. ``NUMBA_CACHE_DIR``, when set, keeps numba's own
    layout under it; an unwritable user cache falls back to numba's locations.
    """
    from numba.core import caching
    from numba.core import config as numba_config

    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    base = getattr(caching, "_CacheLocator", None)
    mixin = getattr(caching, "_SourceFileBackedLocatorMixin", None)
    if impl is None or base is None or mixin is None:  # another numba layout: its default cache
        return
    cache_dir = kernel_cache_dir()
    if not numba_config.CACHE_DIR and not cache_dir.exists():
        _prune(cache_dir.parent)

    class KernelCacheLocator(mixin, base):
        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._cache_path = str(cache_dir / Path(py_file).resolve().parent.relative_to(_PACKAGE))

        def get_cache_path(self):
            return self._cache_path

        def get_source_stamp(self):
            # The directory is named by the content of every kernel module, this file's among
            # them; a file's mtime, numba's stamp, differs between copies of the same source.
            return cache_dir.name

        @classmethod
        def from_function(cls, py_func, py_file):
            if numba_config.CACHE_DIR or not Path(py_file).resolve().is_relative_to(_PACKAGE):
                return None
            return super().from_function(py_func, py_file)

    if not any(c.__name__ == KernelCacheLocator.__name__ for c in impl._locator_classes):
        impl._locator_classes.insert(0, KernelCacheLocator)


def _prune(root: Path, max_age_days: float = 30.0) -> None:
    """Remove the caches of kernel sources unchanged for ``max_age_days`` (earlier versions of
    an edited package); at worst a kernel compiles again."""
    cutoff = time.time() - max_age_days * 86400.0
    for old in root.glob("numba-*"):
        try:
            if old.stat().st_mtime < cutoff:
                shutil.rmtree(old, ignore_errors=True)
        except OSError:
            continue


_install_cache_locator()

_FLAGS = dict(nogil=True, cache=True, fastmath=False, error_model="numpy")

jit = numba.njit(**_FLAGS)

# Small helpers called per voxel or per row: inlined by numba itself, since calls between
# separately compiled functions cost more than the helpers' own work.
jit_inline = numba.njit(**_FLAGS, inline="always")

# Without reference counting (numba's ``_nrt=False``): for functions that take arrays (also
# inside named tuples) but never allocate or return one. Numba increfs every array argument
# on entry to a function that calls another and decrefs it on exit, an atomic operation
# each: with the kernel's Model and State (29 arrays) that was a third of the time per
# move. The caller keeps every array alive for the call, so the counts are not needed.
jit_norc = numba.njit(**_FLAGS, _nrt=False)
jit_norc_inline = numba.njit(**_FLAGS, _nrt=False, inline="always")


@intrinsic
def prefetch(typingctx, array, index):
    """Ask the CPU to bring ``array[index]`` towards the cache (LLVM's prefetch: read,
    high locality). Only a hint: no value changes, and an address past the array may be
    given without a fault, though callers keep inside it."""

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        address = builder.gep(data, [args[1]])
        i32 = ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [address.type, i32, i32, i32])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.prefetch.p0")
        builder.call(fn, [address, i32(0), i32(3), i32(1)])  # read, keep in all levels, data
        return context.get_dummy_value()

    return types.void(array, index), codegen
