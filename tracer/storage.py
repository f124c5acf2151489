"""Files gridcost writes: the one atomic write, and where the user cache lives.

Every file gridcost writes (results, stored points, caches, downloads) goes through
:func:`atomic_write` or :func:`atomic_savez`: the bytes go to a temporary file in the same folder
and are moved into place with ``os.replace``, so a kill or a full disk leaves either the old file or
the new one, never half of one. Caches use ``strict=False``: a read-only or full cache is not an
error (the value is recomputed next time); results use the default and fail loudly.
"""
from __future__ import annotations

import errno
import io
import os
import sys
import tempfile
from pathlib import Path


def cache_root() -> Path:
    """The user cache: ``$GRIDCOST_CACHE``, else ``platformdirs.user_cache_dir("gridcost")`` (on Linux
    ``~/.cache/gridcost``). Parsed meshes, downloads, stand-ins, oracle answers, the machine probe
    and the compiled kernels live here."""
    from tracer.settings import current
    env = current().cache
    if env:
        return Path(env)
    try:
        import platformdirs
        return Path(platformdirs.user_cache_dir("gridcost", appauthor=False))
    except ImportError:  # a dependency, but the loader must not fail without it
        return Path.home() / ".cache" / "gridcost"


def atomic_write(path, data: str | bytes, *, strict: bool = True, mode: int | None = None) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then ``os.replace``).

    ``strict=False`` swallows an ``OSError`` (for caches); ``mode`` sets the file's permissions
    (``mkstemp`` creates files 0600)."""
    path = Path(path)
    payload = data.encode() if isinstance(data, str) else data
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
        if mode is not None:
            os.chmod(tmp, mode)
        os.replace(tmp, path)
        tmp = None
    except OSError as e:
        if not strict:
            return path
        if e.errno in (errno.ENOSPC, errno.EDQUOT):  # name the file and what it needed (the CLI exits 2)
            raise OSError(e.errno, f"{e.strerror}: {len(payload):,} bytes needed", str(path)) from e
        raise
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
    return path


def atomic_savez(path, *, strict: bool = False, **arrays) -> Path:
    """``np.savez`` through :func:`atomic_write` (a cache write by default: ``strict=False``)."""
    import numpy as np

    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return atomic_write(path, buf.getvalue(), strict=strict)


def load_cached_npz(path, keys: tuple[str, ...], what: str) -> dict | None:
    """The arrays ``keys`` of the cache file ``path`` (an ``.npz`` written by :func:`atomic_savez`), or
    None when it is absent. A file that cannot be read or lacks a key (cut short by a kill before
    writes were atomic, a full disk, another version) is removed with one line on stderr naming it
    and ``what`` (e.g. "oracle answer"), and the caller rebuilds it."""
    import numpy as np

    path = Path(path)
    if not path.is_file():
        return None
    try:
        with np.load(path) as z:
            missing = [k for k in keys if k not in z.files]
            if missing:
                raise KeyError(f"no {', '.join(missing)}")
            return {k: z[k] for k in z.files}
    except Exception as exc:  # noqa: BLE001 - any unreadable cache entry is dropped and rebuilt
        print(f"gridcost: the cached {what} {path} is unreadable ({type(exc).__name__}: {exc}); "
              "dropped and rebuilt", file=sys.stderr)
        try:
            path.unlink()
        except OSError:
            pass
        return None
