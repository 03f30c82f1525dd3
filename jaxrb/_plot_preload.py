"""matplotlib loaded on a second thread while `jaxrb run` waits on XLA.

Loading a kept executable (about 1.5 s on a 2-core x86 CPU) and compiling one (10-20 s)
run in XLA's C++ code without Python's global lock, so another thread can run Python
meanwhile. matplotlib's import and its first drawing (fonts found and loaded: about
0.6 s together) then cost the command nothing. The thread draws only a figure of its own,
off screen, through the object interface (no pyplot state), and the main thread waits for
it before drawing anything: the two never use matplotlib at once.
"""

import io
import threading

__all__ = ["PlotPreload"]


def _load_and_draw_once() -> None:
    try:
        import matplotlib.pyplot  # noqa: F401  (the plotting module's import, done here)
        from matplotlib.figure import Figure

        fig = Figure(figsize=(2.0, 2.0))
        ax = fig.add_subplot()
        ax.plot([0.0, 1.0], [0.0, 1.0], label="x")
        ax.set(title="t", xlabel="t (s)")
        ax.legend()
        fig.savefig(io.BytesIO(), format="png", dpi=20, bbox_inches="tight")
    except Exception:  # the main thread's own import and drawing report any problem
        pass


class PlotPreload:
    """Starts loading matplotlib on a daemon thread; `wait()` before drawing."""

    def __init__(self):
        self._thread = threading.Thread(
            target=_load_and_draw_once, name="jaxrb-plot-preload", daemon=True
        )
        self._thread.start()

    def wait(self) -> None:
        self._thread.join()
