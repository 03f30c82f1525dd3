"""The names of the files `jaxrb run` writes, in order (known before anything is drawn, so
without importing matplotlib)."""

__all__ = ["run_outputs", "run_plot_names"]


def run_plot_names(scene) -> list[str]:
    """The PNG files `jaxrb.plotting.save_run_plots` writes for `scene`."""
    names = ["height_attitude.png", "angular_velocity.png", "energy.png"]
    return names + (["reaction.png"] if scene.joint is not None else [])


def run_outputs(scene, *, plots: bool, animate: bool) -> list[str]:
    """Every file `jaxrb run` writes for `scene`: the trajectory, the scene as run, the plots
    (`plots`), the animation (`animate`) and the summary."""
    names = ["trajectory.npz", "trajectory.csv", "scene.toml"]
    if plots:
        names += run_plot_names(scene)
    if animate:
        names.append("animation.gif")
    return names + ["summary.txt"]
