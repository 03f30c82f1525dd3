"""Property test of scene files: any mutation of a shipped example either parses into a scene
whose parameters and initial state are valid, or raises `SceneFileError` naming the file.
Nothing else: no other exception, no silent NaN. Parsing compiles nothing, so this is cheap.
"""

import copy
import math
import tomllib

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import example, given, settings, strategies as st

import jaxrb
from jaxrb._inputs import input_result
from jaxrb._scene_examples import example_path
from jaxrb._scene_file import SceneFileError, parse_scene

EXAMPLES = {
    name: tomllib.loads(example_path(name).read_text())
    for name in ("die", "coin", "pendulum", "heavy_top")
}

HOSTILE = st.one_of(
    st.sampled_from(
        [math.nan, math.inf, -math.inf, -1.0, 0.0, 1e308, -1e308, 1e-320, 10**30, True, "", "x"]
    ),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-(10**20), 10**20),
    st.text(max_size=8),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=5),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


def _paths(node, prefix=()):
    """Every (path to a leaf or table) in a TOML document."""
    if isinstance(node, dict):
        yield prefix
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        yield prefix
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))
    else:
        yield prefix


def _set(doc, path, value):
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value


def _delete(doc, path):
    node = doc
    for key in path[:-1]:
        node = node[key]
    if isinstance(node, dict):
        del node[path[-1]]
    else:
        node.pop(path[-1])


@st.composite
def mutated_scenes(draw):
    name = draw(st.sampled_from(sorted(EXAMPLES)))
    doc = copy.deepcopy(EXAMPLES[name])
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(doc) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        if draw(st.booleans()):
            _set(doc, path, draw(HOSTILE))
        else:
            _delete(doc, path)
    return name, doc


def _with_subnormal_mass():
    """Found by this test: a mass of 1e-320 kg (subnormal) was accepted by the reader and
    flagged by the simulation's check."""
    doc = copy.deepcopy(EXAMPLES["pendulum"])
    doc["body"]["mass"] = 1e-320
    return "pendulum", doc


@settings(max_examples=400, deadline=None)
@given(mutated_scenes())
@example(_with_subnormal_mass())
def test_mutated_scene_file_parses_or_names_the_problem(case):
    name, doc = case
    try:
        spec = parse_scene(doc, source=f"{name}.toml")
    except SceneFileError as e:
        assert str(e).startswith(f"{name}.toml"), str(e)
        assert "\n" not in str(e), str(e)  # one line, as the command line prints it
        return
    # accepted: the parameters and the initial state must be valid, the save times usable
    result = input_result(spec.scene, spec.state0, jnp.asarray(spec.ts))
    assert result == jaxrb.RESULTS.successful, (doc, result)
    assert np.all(np.isfinite(spec.ts)) and np.all(np.diff(spec.ts) >= 0)
    leaves = jax.tree.leaves((spec.scene, spec.state0))
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in leaves if hasattr(x, "dtype"))
