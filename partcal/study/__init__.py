"""Studies: run configs, a run's stages (prepare, fit, rank) and its results, run outputs, model files and the downstream predictor.

Above ``partcal.data`` and ``partcal.models``: a study reads data sets, fits
models, writes what it found, and serves fitted models to downstream code.
Each command of the command line is one function here (imported on first use,
PEP 562, so that importing one stage does not load every command's modules).
"""

from importlib import import_module

from .predictor import Predictor, load_predictor

_COMMANDS = {
    "run_command": ["check_run", "run_and_write"],
    "downstream": ["compensate_file", "compensate_points", "compensate_program_file", "model_equations",
                   "predict_points"],
    "data_files": ["import_file", "import_run", "simulate_files"],
    "plan_command": ["PlanOptions", "run_plan"],
    "iso_figures": ["iso_report"],
    "export": ["export_files"],
    "check": ["check_file"],
    "update": ["update_file", "update_model"],
}
_WHERE = {name: module for module, names in _COMMANDS.items() for name in names}
__all__ = ["Predictor", "load_predictor", *_WHERE]


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'partcal.study' has no attribute {name!r}")
