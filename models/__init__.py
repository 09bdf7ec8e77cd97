"""ladder's physics: scenarios, geometry, contact kinematics, solvers and the model family.

`models` never imports `planner`.
"""

import warnings as _warnings

from numba.core.errors import NumbaPerformanceWarning as _NumbaPerformanceWarning

# Small dense products on non-contiguous views are fine here; keep users' terminals clean.
_warnings.filterwarnings("ignore", category=_NumbaPerformanceWarning)
