"""Benchmarks B1-B4 and the contact throws study (see benchmarks/README.md).

On a CPU, JAX shows one device, which computes on one core. Importing this package before JAX
asks for one host device per core (unless XLA_FLAGS already sets a count), so that
`simulate_batch` can split its batch over all cores. Every other method in the tables runs on
the first device, i.e. on one core; the tables say how many devices each row used.
"""

import os
import sys

if "jax" not in sys.modules and "xla_force_host_platform_device_count" not in os.environ.get(
    "XLA_FLAGS", ""
):
    _cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "") + f" --xla_force_host_platform_device_count={_cores or 1}"
    ).strip()
