"""Sweeps: chunked vmap == direct vmap, resume after interruption, refusal to overwrite,
sharding over 4 CPU devices (subprocess) == unsharded, two processes (jax.distributed) ==
one."""

import json
import os
import subprocess
import sys
import textwrap

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb
from jaxrb._sweep import grid, random_draws, sweep


def _final_omega(row):
    """Torque-free body with inertia (1, a, 3), omega0 = (1, 0.1, w3): omega at t = 1."""
    body = jaxrb.RigidBody(
        1.0, jnp.stack([jnp.ones_like(row["a"]), row["a"], 3.0 * jnp.ones_like(row["a"])])
    )
    state0 = jaxrb.make_state(
        omega=jnp.stack([jnp.ones_like(row["w3"]), 0.1 * jnp.ones_like(row["w3"]), row["w3"]])
    )
    traj = jaxrb.simulate(
        jaxrb.Scene(body),
        state0,
        jnp.array([0.0, 1.0]),
        solver=dfx.Tsit5(),
        stepsize_controller=dfx.ConstantStepSize(),
        dt0=0.05,
        throw=False,
    )
    return {"omega": traj.states.omega[-1], "result": traj.result._value}


@pytest.fixture(scope="module")
def inputs():
    return grid(a=np.linspace(2.0, 2.5, 5), w3=np.array([1.0, 1.5, 2.0]))


def test_grid_and_draws(getkey):
    g = grid(x=[1.0, 2.0], y=[10.0, 20.0, 30.0])
    np.testing.assert_array_equal(g["x"], [1, 1, 1, 2, 2, 2])
    np.testing.assert_array_equal(g["y"], [10, 20, 30, 10, 20, 30])
    d = random_draws(getkey(), 7, u=lambda k, s: jax.random.uniform(k, s, minval=2.0, maxval=3.0))
    assert d["u"].shape == (7,) and np.all((d["u"] >= 2) & (d["u"] <= 3))
    with pytest.raises(ValueError, match="grid axis 'x'"):
        grid(x=np.zeros((2, 2)))


def test_chunked_equals_direct_vmap(inputs):
    chunked = sweep(
        _final_omega, inputs, chunk_size=4, progress=False
    )  # 15 rows: last chunk padded
    assert chunked["omega"].shape == (15, 3)
    direct = jax.jit(jax.vmap(_final_omega))({k: v[:4] for k, v in inputs.items()})
    np.testing.assert_array_equal(chunked["omega"][:4], np.asarray(direct["omega"]))
    # the padded last chunk (rows 12, 13, 14 + one pad row) == those rows swept alone (a batch
    # of 3: XLA vectorises a different batch size differently, so allow 1 ulp)
    single = sweep(
        _final_omega, {k: v[12:] for k, v in inputs.items()}, chunk_size=4, progress=False
    )
    np.testing.assert_allclose(chunked["omega"][12:], single["omega"], rtol=5e-16, atol=0)
    assert np.all(chunked["result"] == 0)


def test_interrupted_sweep_resumes(inputs, tmp_path):
    full = sweep(_final_omega, inputs, chunk_size=4, progress=False, directory=tmp_path / "a")

    class Stop(Exception):
        pass

    def stop_after_two(i, out):
        if i == 1:
            raise Stop

    with pytest.raises(Stop):
        sweep(
            _final_omega,
            inputs,
            chunk_size=4,
            progress=False,
            directory=tmp_path / "b",
            callback=stop_after_two,
        )
    manifest = json.loads((tmp_path / "b" / "manifest.json").read_text())
    assert manifest["done"] == [0, 1] and manifest["n_chunks"] == 4
    computed = []
    resumed = sweep(
        _final_omega,
        inputs,
        chunk_size=4,
        progress=False,
        directory=tmp_path / "b",
        callback=lambda i, out: computed.append(i),
    )
    assert computed == [2, 3]  # finished chunks were loaded, not recomputed
    for k in full:
        np.testing.assert_array_equal(resumed[k], full[k])
    # everything on disk: a rerun computes nothing and returns the same
    again = sweep(
        _final_omega,
        inputs,
        chunk_size=4,
        progress=False,
        directory=tmp_path / "b",
        callback=lambda i, out: computed.append(i),
    )
    assert computed == [2, 3]
    np.testing.assert_array_equal(again["omega"], full["omega"])


def test_refuses_to_overwrite_a_different_sweep(inputs, tmp_path):
    sweep(_final_omega, inputs, chunk_size=8, progress=False, directory=tmp_path)
    other = {k: v * 1.01 for k, v in inputs.items()}
    with pytest.raises(FileExistsError, match="different sweep"):
        sweep(_final_omega, other, chunk_size=8, progress=False, directory=tmp_path)
    with pytest.raises(FileExistsError, match="different sweep"):
        sweep(_final_omega, inputs, chunk_size=4, progress=False, directory=tmp_path)
    with pytest.raises(FileExistsError, match="different sweep"):
        sweep(_final_omega, inputs, chunk_size=8, progress=False, directory=tmp_path, tag="v2")


def test_bad_inputs():
    with pytest.raises(ValueError, match="same leading"):
        sweep(_final_omega, {"a": np.ones(3), "w3": np.ones(4)}, progress=False)
    with pytest.raises(ValueError, match="chunk_size"):
        sweep(_final_omega, {"a": np.ones(3), "w3": np.ones(3)}, chunk_size=0, progress=False)
    with pytest.raises(ValueError, match="no arrays"):
        sweep(_final_omega, {}, progress=False)


_SHARDED = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    sys.path.insert(0, sys.argv[1])
    from test_sweep import _final_omega
    from jaxrb._sweep import grid, sweep
    inputs = grid(a=np.linspace(2.0, 2.5, 5), w3=np.array([1.0, 1.5, 2.0]))
    devices = jax.devices("cpu")
    seen = []
    sharded = sweep(_final_omega, inputs, chunk_size=6, devices=devices, progress=False,
                    directory=sys.argv[2])
    plain = sweep(_final_omega, inputs, chunk_size=6, progress=False)
    print(json.dumps(dict(n_devices=len(devices), omega_sharded=sharded["omega"].tolist(),
                          omega_plain=plain["omega"].tolist(),
                          manifest=json.load(open(sys.argv[2] + "/manifest.json")))))
    """
)


def test_sharded_sweep_on_4_cpu_devices_equals_unsharded(tmp_path):
    env = dict(
        os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu"
    )
    out = subprocess.run(
        [sys.executable, "-c", _SHARDED, os.path.dirname(__file__), str(tmp_path)],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["n_devices"] == 4
    assert report["manifest"]["chunk_size"] == 8  # rounded up to a multiple of 4 devices
    sharded, plain = np.array(report["omega_sharded"]), np.array(report["omega_plain"])
    assert sharded.shape == (15, 3)
    np.testing.assert_allclose(sharded, plain, rtol=0, atol=1e-14)
    in_process = sweep(
        _final_omega,
        grid(a=np.linspace(2.0, 2.5, 5), w3=np.array([1.0, 1.5, 2.0])),
        chunk_size=6,
        progress=False,
    )
    np.testing.assert_allclose(sharded, in_process["omega"], rtol=0, atol=1e-14)


_PROCESS = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    port, rank, directory = sys.argv[2], int(sys.argv[3]), sys.argv[4]
    jax.distributed.initialize(f"localhost:{port}", num_processes=2, process_id=rank)
    import numpy as np
    sys.path.insert(0, sys.argv[1])
    from test_sweep import _final_omega
    from jaxrb._sweep import grid, sweep
    inputs = grid(a=np.linspace(2.0, 2.5, 5), w3=np.array([1.0, 1.5, 2.0]))
    own = []
    out = sweep(_final_omega, inputs, chunk_size=4, directory=directory, processes=True,
                progress=False, wait_timeout=240, callback=lambda i, _: own.append(i))
    print(json.dumps(dict(rank=jax.process_index(), count=jax.process_count(), own=own,
                          omega=out["omega"].tolist(), result=out["result"].tolist())))
    jax.distributed.shutdown()
    """
)


def test_sweep_split_over_two_processes_equals_one_process(tmp_path, inputs):
    """Two JAX processes on this machine (`jax.distributed`, CPU) share a sweep through its
    directory: each computes every other chunk, both return the whole sweep, equal to the
    one-process sweep bit for bit."""
    import socket

    with socket.socket() as s:
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("XLA_FLAGS", None)
    here = os.path.dirname(__file__)
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _PROCESS, here, str(port), str(rank), str(tmp_path)],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for rank in (0, 1)
    ]
    reports = []
    for p in procs:
        stdout, stderr = p.communicate(timeout=300)
        assert p.returncode == 0, stderr[-3000:]
        reports.append(json.loads(stdout.strip().splitlines()[-1]))
    one = sweep(_final_omega, inputs, chunk_size=4, progress=False)
    assert [r["count"] for r in reports] == [2, 2]
    assert [r["own"] for r in reports] == [[0, 2], [1, 3]]  # 15 rows in 4 chunks
    for r in reports:
        np.testing.assert_array_equal(np.array(r["omega"]), one["omega"])
        np.testing.assert_array_equal(np.array(r["result"]), one["result"])
    manifest = json.load(open(tmp_path / "manifest.json"))
    assert manifest["done"] == [0, 1, 2, 3]
    # a rerun resumes from the chunks on disk: nothing is computed again
    computed = []
    again = sweep(
        _final_omega,
        inputs,
        chunk_size=4,
        directory=tmp_path,
        progress=False,
        callback=lambda i, _: computed.append(i),
    )
    assert computed == []
    np.testing.assert_array_equal(again["omega"], one["omega"])
