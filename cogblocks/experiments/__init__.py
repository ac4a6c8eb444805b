"""Experiments that span the architectures, the ready diagrams and the analyses (e.g. held-out evaluations)."""
