"""``qpavoid.sweep``: safety sweeps mapped over any executor, as earlier releases had them
here. The engine lives in :mod:`qpavoid.experiments.sweep`; this module only names it."""

from qpavoid.experiments.sweep import (
    ApproachCheck,
    CloseWorkCheck,
    StrikeCheck,
    SweepSpec,
    TouchCounts,
    as_dicts,
    check_log,
    safety_sweep,
    strike_sweep,
    summarize,
    sweep,
)

__all__ = [
    "ApproachCheck",
    "CloseWorkCheck",
    "StrikeCheck",
    "SweepSpec",
    "TouchCounts",
    "as_dicts",
    "check_log",
    "safety_sweep",
    "strike_sweep",
    "summarize",
    "sweep",
]
