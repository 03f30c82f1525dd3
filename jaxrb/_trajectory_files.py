"""The trajectory files `jaxrb run` writes: `trajectory.npz` and `trajectory.csv`.

One row (npz: one leading index) per save time. Frames and units: `pos`, `vel` world frame
(m, m/s); `quat` scalar first, body -> world; `omega` body frame (rad/s); `energy` (J). A
scene with a joint adds the joint reaction (N, the force the joint exerts on the body;
`jaxrb/_reaction.py` defines the components): world components and |O|, and for a hinge its
angle (rad) and the components O_n (along the line from the mass centre to the axis,
positive towards the axis), O_t (across it, positive against increasing angle) and O_a
(along the axis).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

# npz key -> CSV column names (one per component), in file order
_COLUMNS = {
    "t": ["t"],
    "pos": ["x", "y", "z"],
    "quat": ["e0", "e1", "e2", "e3"],
    "vel": ["vx", "vy", "vz"],
    "omega": ["wx", "wy", "wz"],
    "energy": ["energy"],
    "joint_angle": ["theta"],
    "reaction": ["Ox", "Oy", "Oz"],
    "reaction_normal": ["On"],
    "reaction_tangential": ["Ot"],
    "reaction_axial": ["Oa"],
    "reaction_magnitude": ["Omag"],
}

_CSV_COMMENT = (
    "# jaxrb trajectory: pos/vel world frame (m, m/s); quat scalar first body->world; "
    "omega body frame (rad/s); energy (J)"
)
_CSV_JOINT_COMMENT = (
    "; joint reaction on the body (N): Ox..Oz world frame, Omag = |O|"
    "; hinge: theta (rad, about the axis, 0 at the start), On towards the axis along the line "
    "from the mass centre, Ot across it against increasing theta, Oa along the axis"
)


def file_keys(scene) -> list[str]:
    """The per-save keys of `trajectory.npz` for `scene`, in file order."""
    import jaxrb

    keys = ["t", "pos", "quat", "vel", "omega", "energy"]
    if scene.joint is not None:
        keys += ["reaction", "reaction_magnitude"]
    if isinstance(scene.joint, jaxrb.Hinge):
        keys += ["joint_angle", "reaction_normal", "reaction_tangential", "reaction_axial"]
    return [k for k in _COLUMNS if k in keys]


def bytes_per_save(scene) -> int:
    """Bytes of float64 that one save time adds to `trajectory.npz` for `scene`."""
    return 8 * sum(len(_COLUMNS[k]) for k in file_keys(scene))


def file_arrays(traj, scene) -> dict:
    """The arrays of `trajectory.npz` (numpy, one leading index per save time)."""
    from ._host import energy as host_energy
    from ._reaction import reaction_arrays
    from .plotting import impact_summary

    s = traj.states
    arrays = {
        "t": np.asarray(traj.ts, float),
        "pos": np.asarray(s.pos, float),
        "quat": np.asarray(s.quat, float),
        "vel": np.asarray(s.vel, float),
        "omega": np.asarray(s.omega, float),
        "energy": np.asarray(host_energy(scene, s), float),
    }
    if scene.joint is not None:
        arrays |= reaction_arrays(traj, scene)
    impacts = impact_summary(traj, scene)
    arrays["impact_times"] = impacts["times"]
    arrays["impact_energy_lost"] = impacts["energy_lost"]
    return arrays


def write_trajectory(arrays: dict, outdir: Path) -> list[str]:
    """Write `trajectory.npz` (all of `arrays`) and `trajectory.csv` (the per-save columns);
    returns the file names."""
    np.savez(outdir / "trajectory.npz", **arrays)
    keys = [k for k in _COLUMNS if k in arrays]
    header = [c for k in keys for c in _COLUMNS[k]]
    table = np.column_stack([arrays[k] for k in keys])
    comment = _CSV_COMMENT + (_CSV_JOINT_COMMENT if "reaction" in arrays else "")
    with open(outdir / "trajectory.csv", "w", newline="") as f:
        f.write(comment + "\n")
        w = csv.writer(f)
        w.writerow(header)
        w.writerows([f"{v:.12g}" for v in row] for row in table)
    return ["trajectory.npz", "trajectory.csv"]
