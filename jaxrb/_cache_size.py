"""A size bound on jaxrb's compilation cache directory.

The directory `speed_up_compilation` sets up holds JAX's compiled programs (`<key>-cache`,
with `<key>-atime` where JAX's own size limit is on) and jaxrb's kept programs in its
`programs` folder (`<key>.bin`, `<key>.<machine>.exe`). Nothing there is ever replaced: an
upgrade of jaxrb or JAX, or an edit to the code a program is keyed on, adds new files beside
the old. `prune_cache` removes the least recently used files until the directory holds at
most a given size; `speed_up_compilation` calls it once per process, before the first
compile, with `DEFAULT_MAX_MB` or `$JAXRB_CACHE_MAX_MB`.

A file's last use is the later of its access and modification times. Most file systems
(Linux's default `relatime`) advance a file's access time on a read only where it is a day
old or older than the file's last write, so a read is marked by hand: jaxrb marks a kept
program used when it loads it (`mark_used`), and, once `hook_jax_cache` has run (as
`speed_up_compilation` and `JAXRB_PROGRAMS=1` do), every file JAX's persistent cache reads
back. (Counting a JAX file as used up to a day after its access time, as jaxrb did before,
ranked every file JAX had read that day above every kept program, those of the code just
edited included: the first prune after an edit removed all the traced programs it had
kept, and the next run of the test suite traced them all again.)
A file another process is reading or writing at that moment may be removed under it: JAX
and jaxrb then compile that program again.

JAX writes a file of its cache in place, without a lock where its own size limit is off
(jaxrb's default): another process (a second test worker, a second `jaxrb run`) could read
it half-written, fail to decompress it and compile the program again. `hook_jax_cache`
also makes those writes atomic: the entry goes to a temporary file (`*.tmp`) that is
then renamed, so a reader finds the whole entry or none.
"""

import functools
import os
import stat
import threading
import time
from pathlib import Path

DEFAULT_MAX_MB = 1024.0  # megabytes (2**20 bytes): a test suite's programs take ~250 MB
KEEP_FRACTION = 0.8  # a prune leaves this share of the bound, so that it is not run every time
STALE_TEMPORARY_S = 3600.0  # a half-written file (`*.tmp`) older than this is left over


def cache_max_bytes(max_mb: float | None) -> int | None:
    """The size bound in bytes: `max_mb` (megabytes, None: `$JAXRB_CACHE_MAX_MB`, else
    `DEFAULT_MAX_MB`); None where the bound is off (`max_mb` or the variable <= 0, or
    "none")."""
    if max_mb is None:
        text = os.environ.get("JAXRB_CACHE_MAX_MB", "").strip()
        if text.lower() == "none":
            return None
        try:
            max_mb = float(text) if text else DEFAULT_MAX_MB
        except ValueError:
            raise ValueError(
                f"JAXRB_CACHE_MAX_MB must be a number of megabytes or 'none', got {text!r}"
            ) from None
    if max_mb <= 0:
        return None
    return int(max_mb * 2**20)


def mark_used(path: Path) -> None:
    """Record that the cached file `path` was used now (its access and modification
    times), so that a prune keeps it over files used longer ago."""
    try:
        os.utime(path)
    except OSError:
        pass


def hook_jax_cache() -> None:
    """From now on, in this process, mark every file JAX's persistent compilation cache
    reads back as used (`mark_used`), so that a prune ranks it by its last use, and write
    its new files atomically where JAX takes no lock (module docstring). Wraps the read and
    the write of JAX's file cache (`jax._src.lru_cache.LRUCache.get` and `.put`, a private
    class: where it is missing, JAX's cache is left as it is). Idempotent."""
    try:
        from jax._src import lru_cache
    except ImportError:
        return
    cache = getattr(lru_cache, "LRUCache", None)
    read, write = getattr(cache, "get", None), getattr(cache, "put", None)
    suffix = getattr(lru_cache, "_CACHE_SUFFIX", None)
    if read is None or write is None or suffix is None or getattr(read, "hooked", False):
        return

    @functools.wraps(read)
    def get(self, key):
        value = read(self, key)
        if value is not None:
            try:
                mark_used(Path(str(self.path)) / f"{key}{suffix}")
            except Exception:  # noqa: BLE001  (a cache elsewhere than a local folder)
                pass
        return value

    @functools.wraps(write)
    def put(self, key, value):
        local = getattr(lru_cache, "_is_local_filesystem", lambda _: False)(str(self.path))
        if not key or getattr(self, "eviction_enabled", True) or not local:
            return write(self, key, value)  # JAX's own (under its lock, or a remote store)
        path = Path(str(self.path)) / f"{key}{suffix}"
        if path.exists():
            return None  # as JAX: an entry is never replaced
        write_atomically(path, value)
        return None

    get.hooked = put.hooked = True
    cache.get, cache.put = get, put


def write_atomically(path: Path, value: bytes) -> None:
    """Write `value` to `path` through a temporary file beside it, renamed when complete, so
    that a reader in another process sees the whole file or none."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.{os.getpid()}-{threading.get_ident()}.tmp")
    try:
        tmp.write_bytes(value)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _entries(directory: Path) -> list[tuple[float, int, list[Path]]]:
    """(last use, size, files) of every cache entry in `directory` and its `programs`
    folder; a JAX entry is its `-cache` file with its `-atime` file."""
    entries = []
    now = time.time()
    for folder in (directory, directory / "programs"):
        try:
            names = os.listdir(folder)
        except OSError:
            continue
        for name in names:
            if name.startswith(".") or name.endswith("-atime"):
                continue  # JAX's lock file; an -atime file goes with its -cache file
            path = folder / name
            try:
                st = path.stat()
            except OSError:  # removed meanwhile by another process
                continue
            if not stat.S_ISREG(st.st_mode):  # a folder (`programs`) or another kind
                continue
            files, used = [path], max(st.st_atime, st.st_mtime)
            if name.endswith(".tmp"):
                if now - st.st_mtime < STALE_TEMPORARY_S:
                    continue  # another process is writing it
                used = 0.0  # left over by a process that stopped while writing: first out
            if name.endswith("-cache"):  # JAX's own LRU mark, where on, goes with it
                files.append(folder / (name[: -len("-cache")] + "-atime"))
            entries.append((used, st.st_size, files))
    return entries


def prune_cache(directory, max_bytes: int | None) -> int:
    """Remove the least recently used entries of the cache `directory` (module docstring)
    while it holds more than `max_bytes`, down to `KEEP_FRACTION` of it; returns the bytes
    removed (0 where it holds no more, or `max_bytes` is None)."""
    if max_bytes is None:
        return 0
    entries = _entries(Path(directory))
    total = sum(size for _, size, _ in entries)
    if total <= max_bytes:
        return 0
    target = KEEP_FRACTION * max_bytes
    removed = 0
    for _, size, files in sorted(entries, key=lambda e: e[0]):
        if total - removed <= target:
            break
        for f in files:
            try:
                f.unlink()
            except OSError:  # already removed by another process
                pass
        removed += size
    return removed
