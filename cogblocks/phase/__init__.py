"""Phase estimation (section 5.2.2 and section 6): online 1D and 3D estimators, phase → position, offline references."""

from cogblocks.phase.algorithm1 import Algorithm1Phase
from cogblocks.phase.computer import PhaseComputer
from cogblocks.phase.customizer import ReferenceCustomizer, customize_reference, kabsch_rotation
from cogblocks.phase.estimator import PhaseEstimator
from cogblocks.phase.estimator3d import PhaseEstimator3D
from cogblocks.phase.offline import hilbert_phase, mean_cycle, offline_phase_pca_hilbert
from cogblocks.phase.period import PeriodEstimator
from cogblocks.phase.position import PhasePositionComputer

__all__ = [
    "Algorithm1Phase",
    "PeriodEstimator",
    "PhaseComputer",
    "PhaseEstimator",
    "PhaseEstimator3D",
    "PhasePositionComputer",
    "ReferenceCustomizer",
    "customize_reference",
    "hilbert_phase",
    "kabsch_rotation",
    "mean_cycle",
    "offline_phase_pca_hilbert",
]
