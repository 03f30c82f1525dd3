"""Parameter sweeps: a vmapped function over grids or random draws, chunked, resumable, sharded.

`sweep(fn, inputs)` evaluates `fn` on every row of `inputs` (a pytree of arrays sharing a
leading axis N) with `jax.vmap`, `chunk_size` rows at a time, so memory stays bounded. With
`directory=...` each finished chunk is written as `chunk_XXXXX.npz` plus a `manifest.json`
holding a fingerprint of the sweep (the inputs' bytes, the function's name, the chunk size);
a rerun with the same fingerprint loads finished chunks instead of recomputing them (resume
after an interruption), and a directory holding a different sweep is refused, never
overwritten.

Compiled once per process (per function and input structure); with `speed_up_compilation`
(the command line calls it) the traced program is also kept on disk for the next process
when `fn` is jaxrb's or comes from `program_sources` there (`persistent_jit`).

Devices: `devices=jax.local_devices()` (or a `jax.sharding.Mesh` with one axis) shards each
chunk along its leading axis with `NamedSharding(mesh, P(axis))` over one process's devices.

Processes (several hosts, or several processes on one): start every process with
`jax.distributed.initialize(coordinator_address, num_processes, process_id)` (on a cluster
with a scheduler JAX knows, no arguments are needed), then run the same
`sweep(..., directory=SHARED, processes=True)` in every one of them. Process p computes
chunks p, p + P, p + 2P, ... on its own devices and writes them to the shared directory (a
filesystem every process sees); every process then waits for all the chunks and returns the
whole sweep. The processes share nothing but the directory (no collective operations), so a
slow or restarted process only delays the others, and a rerun resumes from the chunks on
disk. On GPU hosts, start one process per host (its `devices` its local GPUs) or one per GPU.
"""

import functools
import hashlib
import json
import os
import time
from collections.abc import Callable
from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ._persistent import entry_point

_MANIFEST = "manifest.json"
_FORMAT = 1


def grid(**axes) -> dict[str, np.ndarray]:
    """Full Cartesian grid of named 1-D axes, flattened: each value has shape (prod(len),).

    Example: `grid(mass=[1, 2], e=[0.5, 0.7, 0.9])` gives 6 rows (C order, last axis fastest).
    """
    names = list(axes)
    arrays = [np.asarray(axes[k]) for k in names]
    for k, a in zip(names, arrays, strict=True):
        if a.ndim != 1 or a.size == 0:
            raise ValueError(f"grid axis {k!r} must be a non-empty 1-D array, got shape {a.shape}")
    mesh = np.meshgrid(*arrays, indexing="ij")
    return {k: m.reshape(-1) for k, m in zip(names, mesh, strict=True)}


def random_draws(key, n: int, **samplers: Callable) -> dict[str, np.ndarray]:
    """`n` random draws per name: `samplers[name](key, (n,))` with independent keys.

    Example:
    `random_draws(key, 1000, a=lambda k, s: jax.random.uniform(k, s, minval=0.5, maxval=1.5))`.
    """
    keys = jax.random.split(key, len(samplers))
    return {
        name: np.asarray(f(k, (n,))) for (name, f), k in zip(samplers.items(), keys, strict=True)
    }


def _fingerprint(leaves, treedef, fn, chunk_size, tag) -> str:
    h = hashlib.sha256()
    h.update(str(treedef).encode())
    for x in leaves:
        h.update(str((x.shape, x.dtype.str)).encode())
        h.update(np.ascontiguousarray(x).tobytes())
    name = getattr(fn, "__qualname__", type(fn).__qualname__)
    h.update(f"{getattr(fn, '__module__', '')}.{name}|{chunk_size}|{tag}".encode())
    return h.hexdigest()


def _as_mesh(devices) -> Mesh | None:
    if devices is None:
        return None
    if isinstance(devices, Mesh):
        if len(devices.axis_names) != 1:
            raise ValueError("devices: give a Mesh with exactly one axis (the batch axis)")
        return devices
    devices = list(devices)
    if not devices:
        raise ValueError("devices must not be empty")
    return Mesh(np.asarray(devices), ("batch",))


def _vmapped(fn, treedef, rows):
    """`fn` on every row of `rows` (the leaves of the inputs, each with a leading axis)."""
    return jax.vmap(lambda row: fn(jax.tree.unflatten(treedef, row)))(rows)


_rows = entry_point(_vmapped)


@functools.lru_cache(maxsize=32)
def _compiled(fn, treedef, mesh):
    """The jitted, vmapped (and sharded) function; cached so repeated sweeps reuse it."""
    if mesh is None:
        return functools.partial(_rows, fn, treedef)
    batched = functools.partial(_vmapped, fn, treedef)
    sharding = NamedSharding(mesh, PartitionSpec(mesh.axis_names[0]))
    return jax.jit(batched, in_shardings=sharding, out_shardings=sharding)


def _chunk_path(directory, i):
    return os.path.join(directory, f"chunk_{i:05d}.npz")


def _savez(f, arrays):
    np.savez(f, **arrays)


def _write_atomic(path, write):
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        write(f)
    os.replace(tmp, path)


def _wait_for(paths, timeout, what):
    """Wait until every file in `paths` exists (written by other processes)."""
    deadline = time.monotonic() + timeout
    missing = [p for p in paths if not os.path.exists(p)]
    while missing:
        if time.monotonic() > deadline:
            names = ", ".join(os.path.basename(p) for p in missing[:5])
            raise TimeoutError(
                f"sweep: waited {timeout:g} s for {what} of the other processes; missing "
                f"{len(missing)}: {names}"
            )
        time.sleep(0.1)
        missing = [p for p in missing if not os.path.exists(p)]


def sweep(
    fn: Callable,
    inputs: Any,
    *,
    chunk_size: int = 1024,
    directory: str | os.PathLike | None = None,
    devices=None,
    progress: bool = True,
    tag: str = "",
    callback: Callable | None = None,
    processes: bool = False,
    wait_timeout: float = 86400.0,
) -> Any:
    """Evaluate `fn` on every row of `inputs`, vmapped and chunked; optionally resumable/sharded.

    **Arguments:**

    - `fn`: a per-row function `fn(row) -> pytree of arrays` (row = `inputs` with the
      leading axis removed); pure and jittable (e.g. a `jaxrb.simulate` call and a summary).
      Use `simulate(..., throw=False)` and return the `result` code to keep failures per row.
    - `inputs`: a pytree (dict, tuple, `State`, ...) of arrays sharing the leading axis N:
      `grid(...)`, `random_draws(...)`, or your own.
    - `chunk_size`: rows per vmapped call (bounds memory); the last chunk is padded by
      repeating its last row so the compiled function is reused, and the padding dropped.
      Rounded up to a multiple of the device count when sharding.
    - `directory`: where to write one `.npz` per chunk plus `manifest.json`; reruns resume.
      A directory whose manifest belongs to a different sweep raises `FileExistsError`.
    - `devices`: None (default device), a list of devices, or a one-axis `Mesh`: each chunk
      is sharded along the batch axis across them.
    - `progress`: show a tqdm bar over chunks.
    - `tag`: an extra string in the fingerprint (e.g. a version of `fn`'s code, which the
      fingerprint cannot see: only its name).
    - `callback`: called as `callback(index, outputs)` after each newly computed chunk
      (NumPy outputs); an exception there stops the sweep after that chunk was saved.
    - `processes`: split the chunks among the JAX processes (`jax.distributed`; module
      docstring): needs a `directory` that every process sees; each process computes its
      share and returns the whole sweep once every chunk is on disk.
    - `wait_timeout`: (s) how long a process waits for the others' chunks before raising
      `TimeoutError` naming the chunks missing.

    **Returns:** the outputs of `fn` stacked along a leading axis N, as NumPy arrays.
    """
    leaves, treedef = jax.tree.flatten(inputs)
    if not leaves:
        raise ValueError("inputs has no arrays")
    leaves = [np.asarray(x) for x in leaves]
    n = leaves[0].shape[0] if leaves[0].ndim else None
    for x in leaves:
        if x.ndim == 0 or x.shape[0] != n:
            raise ValueError(
                "every array in inputs needs the same leading (batch) axis; got shapes "
                f"{[tuple(y.shape) for y in leaves]}"
            )
    if n == 0:
        raise ValueError("inputs has zero rows")
    if int(chunk_size) < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    mesh = _as_mesh(devices)
    rank, size = (jax.process_index(), jax.process_count()) if processes else (0, 1)
    if processes and directory is None:
        raise ValueError("processes=True needs a directory that every process sees")
    chunk_size = int(chunk_size)
    d = 1 if mesh is None else mesh.devices.size
    chunk_size = min(-(-chunk_size // d) * d, -(-n // d) * d)  # a multiple of d, <= N rounded up
    n_chunks = -(-n // chunk_size)

    manifest = None
    if directory is not None:
        directory = os.fspath(directory)
        os.makedirs(directory, exist_ok=True)
        fingerprint = _fingerprint(leaves, treedef, fn, chunk_size, tag)
        mpath = os.path.join(directory, _MANIFEST)
        if rank > 0:  # the first process writes the manifest: wait for it
            _wait_for([mpath], wait_timeout, "the manifest of process 0")
        if os.path.exists(mpath):
            with open(mpath) as f:
                manifest = json.load(f)
            if manifest.get("fingerprint") != fingerprint:
                raise FileExistsError(
                    f"{directory} holds a different sweep (its manifest's fingerprint differs: "
                    "other inputs, function, chunk size or tag); refusing to overwrite it. "
                    "Use a new directory or delete this one."
                )
        else:
            manifest = dict(
                format=_FORMAT,
                fingerprint=fingerprint,
                n=n,
                chunk_size=chunk_size,
                n_chunks=n_chunks,
                done=[],
            )
            _write_atomic(mpath, lambda f: f.write(json.dumps(manifest).encode()))

    compiled = _compiled(fn, treedef, mesh)
    if mesh is not None:
        sharding = NamedSharding(mesh, PartitionSpec(mesh.axis_names[0]))

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(range(rank, n_chunks, size)), desc="sweep", unit="chunk")
    outputs, out_treedef = [None] * n_chunks, None
    try:
        for i in range(n_chunks):
            lo, hi = i * chunk_size, min((i + 1) * chunk_size, n)
            path = None if directory is None else _chunk_path(directory, i)
            # with several processes a chunk file is written whole or not at all (atomic
            # rename), and only the first process keeps the manifest's list
            done = manifest is not None and (size > 1 or i in manifest["done"])
            if i % size != rank:
                continue  # another process's chunk: read below
            if done and os.path.exists(path):
                with np.load(path) as data:
                    outputs[i] = [data[f"out_{j}"] for j in range(len(data.files))]
            else:
                idx = np.minimum(np.arange(lo, lo + chunk_size), n - 1)  # pad with the last row
                rows = [x[idx] for x in leaves]
                if mesh is not None:
                    rows = [jax.device_put(x, sharding) for x in rows]
                result = compiled(rows)
                out_leaves, out_treedef = jax.tree.flatten(result)
                outputs[i] = [np.asarray(x)[: hi - lo] for x in out_leaves]
                if manifest is not None:
                    arrays = {f"out_{j}": x for j, x in enumerate(outputs[i])}
                    _write_atomic(path, functools.partial(_savez, arrays=arrays))
                    manifest["done"] = sorted(set(manifest["done"]) | {i})
                    if rank == 0:
                        mpath = os.path.join(directory, _MANIFEST)
                        _write_atomic(mpath, lambda f: f.write(json.dumps(manifest).encode()))
                if callback is not None:
                    callback(i, jax.tree.unflatten(out_treedef, outputs[i]))
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    if size > 1:  # the other processes' chunks, once they are on disk
        others = [i for i in range(n_chunks) if i % size != rank]
        _wait_for([_chunk_path(directory, i) for i in others], wait_timeout, "chunks")
        for i in others:
            with np.load(_chunk_path(directory, i)) as data:
                outputs[i] = [data[f"out_{j}"] for j in range(len(data.files))]
        if rank == 0:
            manifest["done"] = list(range(n_chunks))
            mpath = os.path.join(directory, _MANIFEST)
            _write_atomic(mpath, lambda f: f.write(json.dumps(manifest).encode()))
    if out_treedef is None:  # everything came from disk: get the structure by tracing
        row = jax.tree.unflatten(
            treedef, [jax.ShapeDtypeStruct(x.shape[1:], x.dtype) for x in leaves]
        )
        out_treedef = jax.tree.structure(jax.eval_shape(fn, row))
    stacked = [np.concatenate([o[j] for o in outputs]) for j in range(len(outputs[0]))]
    return jax.tree.unflatten(out_treedef, stacked)
