"""Fit physical parameters from observed motion: Levenberg–Marquardt through the
differentiable simulation, with Gauss–Newton uncertainties and identifiability reports. A
trial step where the model cannot be evaluated (an invalid parameter, a failed simulation) is
rejected and a shorter one tried; `FitResult.converged`, `reason` and `num_steps` say how the
fit ended.

- `fit_inertia`: full inertia tensor (products included) from attitude / angular velocity.
- `fit_drag`: drag coefficient from a tracked flight.
- `fit_restitution`: restitution from bounce times and/or apex heights.
- `fit_contact`: restitution and friction from a tracked trajectory with bounces.
- `least_squares_fit`: the shared driver, for your own residual functions.
"""

from ._contact import fit_contact as fit_contact
from ._drag import fit_drag as fit_drag
from ._inertia_id import fit_inertia as fit_inertia
from ._least_squares import (
    ConvergenceWarning as ConvergenceWarning,
    FitResult as FitResult,
    IdentifiabilityWarning as IdentifiabilityWarning,
    least_squares_fit as least_squares_fit,
)
from ._parameterisation import (
    inertia_to_log_cholesky as inertia_to_log_cholesky,
    log_cholesky_to_inertia as log_cholesky_to_inertia,
    pseudo_inertia as pseudo_inertia,
)
from ._restitution import fit_restitution as fit_restitution
