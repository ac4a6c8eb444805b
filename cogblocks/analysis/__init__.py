"""Analysis tools: λ stability of the blender, linearisation of diagrams (casadi, python-control)."""

from cogblocks.analysis.linearize import KuramotoLinearization, kuramoto_jacobian, kuramoto_linearization, linearize
from cogblocks.analysis.stability import LambdaReport, check_blender, lambda_report

__all__ = [
    "KuramotoLinearization",
    "LambdaReport",
    "check_blender",
    "kuramoto_jacobian",
    "kuramoto_linearization",
    "lambda_report",
    "linearize",
]
