"""The size bound on the compilation cache directory (`jaxrb._cache_size`)."""

import os
import subprocess
import sys
import time
from pathlib import Path

import jax.numpy as jnp
import pytest

import jaxrb
from jaxrb._cache_size import DEFAULT_MAX_MB, cache_max_bytes, hook_jax_cache, prune_cache

MB = 2**20


def _entry(path, size, age_s):
    """A file of `size` bytes last used `age_s` seconds ago."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"x" * size)
    used = time.time() - age_s
    os.utime(path, (used, used))
    return path


def test_the_least_recently_used_entries_go_first_down_to_the_kept_share(tmp_path):
    programs = tmp_path / "programs"
    day = 86400
    old_jax = _entry(tmp_path / "old-cache", 3 * MB, 3 * day)  # JAX's: not read for days
    old_atime = _entry(tmp_path / "old-atime", 8, 3 * day)  # JAX's own LRU mark: goes with it
    # a JAX file read 10 h ago, older than the programs below (reads are marked by hand:
    # `hook_jax_cache`; counted up to a day later, it would outrank them all)
    earlier_jax = _entry(tmp_path / "new-cache", 2 * MB, 10 * 3600)
    old_program = _entry(programs / "a.bin", 2 * MB, 300)
    middle = _entry(programs / "a.cafe.exe", 2 * MB, 200)
    newest = _entry(programs / "b.bin", 1 * MB, 0)
    lock = _entry(tmp_path / ".lockfile", 0, 1000)
    # 10 MB (and 8 bytes) over a bound of 8 MB: prune to 0.8 * 8 = 6.4 MB, oldest first
    removed = prune_cache(tmp_path, 8 * MB)
    assert removed == 5 * MB
    assert not old_jax.exists() and not old_atime.exists() and not earlier_jax.exists()
    assert old_program.exists() and middle.exists() and newest.exists() and lock.exists()
    # under the bound nothing goes
    assert prune_cache(tmp_path, 8 * MB) == 0
    assert old_program.exists()
    assert prune_cache(tmp_path, None) == 0


def test_half_written_files_are_left_to_their_writer_unless_left_over(tmp_path):
    fresh = _entry(tmp_path / "programs" / "c.123.tmp", MB, 10)
    stale = _entry(tmp_path / "programs" / "d.456.tmp", MB, 2 * 3600)
    kept = _entry(tmp_path / "e-cache", MB, 5000)  # used longer ago than the stale file
    assert prune_cache(tmp_path, int(1.5 * MB)) == MB
    assert fresh.exists() and kept.exists() and not stale.exists()


def test_the_bound_comes_from_the_argument_or_the_environment(monkeypatch):
    monkeypatch.delenv("JAXRB_CACHE_MAX_MB", raising=False)
    assert cache_max_bytes(None) == int(DEFAULT_MAX_MB * MB)
    assert cache_max_bytes(2.5) == int(2.5 * MB)
    assert cache_max_bytes(0) is None
    monkeypatch.setenv("JAXRB_CACHE_MAX_MB", "300")
    assert cache_max_bytes(None) == 300 * MB
    assert cache_max_bytes(10) == 10 * MB  # the argument wins
    monkeypatch.setenv("JAXRB_CACHE_MAX_MB", "none")
    assert cache_max_bytes(None) is None
    monkeypatch.setenv("JAXRB_CACHE_MAX_MB", "lots")
    with pytest.raises(ValueError, match="JAXRB_CACHE_MAX_MB.*'lots'"):
        cache_max_bytes(None)


def _double(x):
    return 2.0 * x


def test_a_loaded_program_is_marked_used(tmp_path):
    """A kept program read back by a new caller counts as used now, so that a prune keeps
    it over programs nobody has loaded for longer."""
    jaxrb.persistent_jit(_double, cache_dir=tmp_path)(jnp.arange(3.0))
    files = sorted(tmp_path.glob("*.bin")) + sorted(tmp_path.glob("*.exe"))
    assert files
    long_ago = time.time() - 10 * 86400
    for f in files:
        os.utime(f, (long_ago, long_ago))
    out = jaxrb.persistent_jit(_double, cache_dir=tmp_path)(jnp.arange(3.0))
    assert float(out[2]) == 4.0
    used = [max(f.stat().st_atime, f.stat().st_mtime) for f in files if f.exists()]
    assert max(used) > time.time() - 600


def test_a_program_read_back_from_jax_s_cache_is_marked_used(tmp_path):
    """In processes of their own: the first compiles a small program into the cache, the
    second reads it back; its file then counts as used now, not when it was written."""
    code = (
        "import jax, jaxrb; "
        f"jaxrb.speed_up_compilation(cache_dir={str(tmp_path)!r}, programs=False); "
        "print(jax.jit(lambda x: 3.0 * x + 1.0)(2.0))"
    )
    env = dict(os.environ, JAX_PLATFORMS="cpu", JAXRB_CACHE_MAX_MB="none")
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    run = lambda: subprocess.run(  # noqa: E731
        [sys.executable, "-c", code], env=env, check=True, timeout=120, capture_output=True
    )
    run()
    written = sorted(tmp_path.glob("jit_*-cache"))
    assert written, sorted(p.name for p in tmp_path.iterdir())
    # a read never moves a file's modification time (and on most file systems, Linux's
    # `relatime`, its access time at most once a day): the mark by hand moves both
    long_ago = time.time() - 10 * 86400
    for f in written:
        os.utime(f, (long_ago, long_ago))
    assert run().stdout.strip() == b"7.0"
    assert max(f.stat().st_mtime for f in written) > time.time() - 600
    assert sorted(tmp_path.glob("jit_*-cache")) == written  # read back, not compiled again


def test_speed_up_compilation_prunes_its_directory_once_at_the_start(tmp_path):
    """In a process of its own (the call changes process-wide settings)."""
    old = _entry(tmp_path / "old-cache", 2 * MB, 3 * 86400)
    new = _entry(tmp_path / "programs" / "new.bin", MB, 0)
    code = f"import jaxrb; jaxrb.speed_up_compilation(cache_dir={str(tmp_path)!r})"
    env = dict(os.environ, JAXRB_CACHE_MAX_MB="2.5", JAX_PLATFORMS="cpu")
    subprocess.run([sys.executable, "-c", code], env=env, check=True, timeout=120)
    assert not old.exists() and new.exists()


def test_jax_s_cache_entries_are_written_whole(tmp_path, monkeypatch):
    """JAX's file cache without its own size limit writes an entry in place, with no lock:
    another process could read it half-written. Hooked, the entry goes to a temporary file
    renamed when complete, and an existing entry is left as it is (as JAX does)."""
    from jax._src import lru_cache

    hook_jax_cache()
    cache = lru_cache.LRUCache(str(tmp_path), max_size=-1)
    renames = []
    real_replace = os.replace

    def spy(src, dst):
        renames.append((Path(dst), Path(dst).exists(), Path(src).read_bytes()))
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", spy)
    value = bytes(range(256)) * 1000
    cache.put("key", value)
    entry = tmp_path / "key-cache"
    assert renames == [(entry, False, value)]  # written whole beside it, then renamed
    assert entry.read_bytes() == value
    assert sorted(p.name for p in tmp_path.iterdir()) == ["key-cache"]  # no temporary left
    cache.put("key", b"other")
    assert entry.read_bytes() == value and len(renames) == 1
    assert cache.get("key") == value
