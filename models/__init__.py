"""ladder's physics: scenarios, geometry, contact kinematics, solvers and the model family.

`models` never imports `planner`.
"""

import warnings as _warnings

# The CPU the kernels are tuned for: before numba is imported here (or, where it was imported
# before, re-reads its configuration at once).
from models import cpu_target as _cpu_target

_cpu_target.install()

from numba.core.errors import NumbaPerformanceWarning as _NumbaPerformanceWarning  # noqa: E402

# Small dense products on non-contiguous views are fine here; keep users' terminals clean.
_warnings.filterwarnings("ignore", category=_NumbaPerformanceWarning)

# Every kernel's cache entry is stamped with the whole package's digest (numba stamps it with
# its own module's only, and missed edits to the helpers it inlines): before any kernel exists.
from models import kernel_cache as _kernel_cache  # noqa: E402

_kernel_cache.install()

# The kernels marked `nonnegative_indices` compile without numba's wraparound of negative
# indices: before any kernel is compiled.
from models import nonnegative as _nonnegative  # noqa: E402

_nonnegative.install()
