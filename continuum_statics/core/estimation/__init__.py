"""Floor 4, estimation: what the robot is doing, from what is measured.

- :mod:`.shape_estimation`: the shape from measured cable lengths (and tensions)
- :mod:`.state_estimation`: that shape fused with sensors and the model's own error
- :mod:`.load_estimation`: the tip load from tensions, lengths and a tracker
- :mod:`.gates`: the chi-square gates and coverage quantiles every estimator uses
"""
from continuum_statics.core.estimation.load_estimation import (
    LoadModel,
    WrenchEstimate,
    load_model,
)
from continuum_statics.core.estimation.shape_estimation import ShapeEstimate, Tracking

__all__ = ['ShapeEstimate', 'Tracking', 'WrenchEstimate', 'LoadModel', 'load_model']
