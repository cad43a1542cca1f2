"""Parameter studies over FMUs, specs, SSP scenarios and LinearDAEs, run on Dask.

`sweep` runs one simulation per point of a grid (a full grid of value lists
or a Latin hypercube sample of ranges) in worker processes, and returns a
pandas DataFrame with one row per run: the grid's inputs under their own
names and the metric columns `METRICS`. `recommend` picks the cheapest
point that reaches an error target; `plot_study` draws the summary plots.

Names of the grid with a meaning of their own: ``lam`` (the rate λ),
``step`` (the communication step of an FMU; the largest solver step of a
LinearDAE), ``rtol``, ``atol``, ``method`` (the integrator: 'RK45',
'DOP853', 'Radau', 'BDF'), ``offset`` (distance by which the initial
state is moved off the solution manifold), and for LinearDAEs
``completion`` and ``k``. Any other name sets the FMU variable of that
name (a parameter or a start value such as ``y_0``).
"""
from ._grid import METRICS
from ._recommend import Recommendation, plot_study, recommend
from ._sweep import sweep

__all__ = ["sweep", "recommend", "plot_study", "Recommendation", "METRICS"]
