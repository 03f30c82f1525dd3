"""A line on the terminal while XLA compiles a program from scratch.

A scene's first run compiles its program (a contact scene's takes tens of seconds on a small
CPU) before it integrates for milliseconds; without a word the command line looks stuck.
`CompileNotice` listens to JAX's compile events (`jax.monitoring`) and, when one compile has
run for `after` seconds without JAX's persistent cache serving it, says so once. A program
read back from that cache, or one jaxrb kept (no compile at all), says nothing; so does a
long integration after a quick compile.

JAX's events for each compile: the lowering's duration (`LOWERED`, when the lowering ends
and the compile begins); where the persistent cache serves the program, a hit (`CACHE_HIT`,
once the program is read back); and the compile's duration (`COMPILED`, at its end, also
after a hit). A miss is recorded only after the compile (JAX 0.10), too late to use. A
1.8 MB contact program took 1.2-1.3 s to read back on a 2-core x86 CPU, hence `after` = 3 s.
"""

import threading

import jax

LOWERED = "/jax/core/compile/jaxpr_to_mlir_module_duration"
CACHE_HIT = "/jax/compilation_cache/cache_hits"
COMPILED = "/jax/core/compile/backend_compile_duration"


class CompileNotice:
    """Within `with CompileNotice(say, cached=...)`: `say(message)` once, from another
    thread, when a compile has run for `after` seconds (s) without the persistent cache
    serving it. `cached`: whether that cache is on (only the message's wording)."""

    def __init__(self, say, *, cached: bool, after: float = 3.0):
        self.say = say
        self.cached = cached
        self.after = after
        self.said = False
        self._timer = None
        self._lock = threading.Lock()

    def message(self) -> str:
        later = (
            "later runs of it load it from the cache"
            if self.cached
            else "--no-cache compiles it on every run"
        )
        return (
            "compiling the scene's program (a scene's first run: tens of seconds on a small "
            f"CPU; {later}) ..."
        )

    def _fire(self):
        with self._lock:
            if self._timer is None or self.said:
                return
            self._timer = None
            self.said = True
        self.say(self.message())

    def _start(self):
        with self._lock:
            if self.said or self._timer is not None:
                return
            self._timer = threading.Timer(self.after, self._fire)
            self._timer.daemon = True
            self._timer.start()

    def _stop(self):
        with self._lock:
            timer, self._timer = self._timer, None
        if timer is not None:
            timer.cancel()

    def on_event(self, event, **kwargs):
        if event == CACHE_HIT:
            self._stop()

    def on_duration(self, event, duration, **kwargs):
        if event == LOWERED:
            self._start()
        elif event == COMPILED:
            self._stop()

    def __enter__(self):
        jax.monitoring.register_event_listener(self.on_event)
        jax.monitoring.register_event_duration_secs_listener(self.on_duration)
        return self

    def __exit__(self, *exc):
        self._stop()
        jax.monitoring.unregister_event_listener(self.on_event)
        jax.monitoring.unregister_event_duration_listener(self.on_duration)
        return False
