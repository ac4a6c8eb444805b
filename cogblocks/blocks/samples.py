"""What counts as a usable motion sample: finite and physically plausible.

Motion-capture streams carry NaN for lost markers, but a corrupted packet can also carry a finite
number no hand reaches (1e300). Blocks of the 3D and Amplification chains treat both alike, as bad
data, through :func:`plausible`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MEASURABLE", "PLAUSIBLE", "plausible"]

#: A coordinate (mm) or velocity (mm/s) at or beyond a kilometre (per second) is no hand motion.
PLAUSIBLE = 1e6
#: A number at or beyond this is a corrupted value in any unit (mm, m, sensor counts): blocks that work in the
#: signal's own units use it instead of :data:`PLAUSIBLE`; squares and sums of such numbers stay far from overflow.
MEASURABLE = 1e100


def plausible(x: np.ndarray, limit: float = PLAUSIBLE) -> bool:
    """Whether every element is finite and below ``limit`` (:data:`PLAUSIBLE` by default) in magnitude.

    ``abs(nan) < limit`` is False, so NaN fails as well as ±inf.
    """
    return bool(np.all(np.abs(x) < limit))
