"""`jaxrb._compile_notice.CompileNotice`: the command line's line while XLA compiles."""

import time

import jax
import jax.numpy as jnp

from jaxrb._compile_notice import CACHE_HIT, COMPILED, LOWERED, CompileNotice

AFTER = 0.05  # s: the notice's delay in these tests
WAIT = 0.5  # s: ten times that


def _notice(cached=True):
    said = []
    return CompileNotice(said.append, cached=cached, after=AFTER), said


def test_a_long_compile_is_announced_once():
    notice, said = _notice()
    for _ in range(2):  # two long compiles: one line
        notice.on_duration(LOWERED, 0.1)
        time.sleep(WAIT)
        notice.on_duration(COMPILED, WAIT)
    assert said == [notice.message()]
    assert "later runs of it load it from the cache" in said[0]
    assert "--no-cache" in _notice(cached=False)[0].message()


def test_a_quick_compile_or_a_program_read_from_the_cache_says_nothing():
    notice, said = _notice()
    notice.on_duration(LOWERED, 0.1)
    notice.on_duration(COMPILED, 0.01)  # done before the delay
    notice.on_duration(LOWERED, 0.1)
    notice.on_event(CACHE_HIT)  # served by the persistent cache
    time.sleep(WAIT)
    notice.on_duration(COMPILED, 0.01)
    assert said == []


def test_it_hears_jax_s_compiles_only_inside_its_block():
    """A real compile inside the block starts and ends a wait (too short to speak here);
    outside it, JAX's events no longer reach the notice."""
    said = []
    heard = []

    class Counting(CompileNotice):
        def on_duration(self, event, duration, **kwargs):
            heard.append(event)
            super().on_duration(event, duration, **kwargs)

    with Counting(said.append, cached=True, after=60.0) as notice:
        jax.jit(lambda x: jnp.sin(x) + 3.0)(1.0).block_until_ready()
    assert LOWERED in heard and COMPILED in heard
    assert notice._timer is None and said == []
    heard.clear()
    jax.jit(lambda x: jnp.cos(x) + 4.0)(1.0).block_until_ready()
    assert heard == []
