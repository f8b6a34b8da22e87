"""Studies: run configs, a run's stages (prepare, fit, rank) and its results, run outputs, model files and the downstream predictor.

Above ``partcal.data`` and ``partcal.models``: a study reads data sets, fits
models, writes what it found, and serves fitted models to downstream code.
"""

from .predictor import Predictor, load_predictor

__all__ = ["Predictor", "load_predictor"]
