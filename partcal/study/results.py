"""What a run produced: each model's result, the run's plan and the finished run.

These are plain records: the stages of a run (:mod:`partcal.study.prepare`,
:mod:`partcal.study.fitting`, :mod:`partcal.study.runner`) fill them, and the
outputs, the printed tables and the report read them. They import no stage,
so nothing imports back.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..data.measurements import Measurements
from ..data.registration import Registration
from ..models.kinds import is_physical, regions_of
from ..robot.kinematics import Robot
from .config import ModelSpec, RunConfig
from .plan import run_indices
from .selection import CVPlan, rank_reason


@dataclass
class ModelResult:
    """One fitted model of a run with everything measured about it."""

    spec: ModelSpec
    model: object                       # any partcal error model (series, partitioned, GP, kinematic)
    fit_seconds: float                  # the final fit on the identification set, nothing else
    cv_rms_3d: float                    # on the run's shared folds; nested for lists of granularities or prior strengths
    metrics: dict[str, dict]
    predictions: dict[str, NDArray[np.float64]]
    rms_ratio: float | None = None
    granularity: list[dict] | None = None
    compensation: dict[str, dict] = field(default_factory=dict)
    cv_seconds: float = 0.0             # cross-validation (and the granularity choice)
    nested: bool = False
    cv_regions: list[int] | None = None  # partitioned: [fewest, most] regions of the CV fold fits
    cv_se: float = float("nan")         # standard error of cv_rms_3d, over the identification poses
    effective_parameters: float = float("nan")   # what "simpler" means when two CV scores are close
    notes: list[str] = field(default_factory=list)   # fits on a bound and the like: warned, and in the report
    rank_on: str = "position"           # cv_rms_3d and cv_se are of the position (mm) or the orientation (mrad)
    spreads: dict[str, NDArray[np.float64]] = field(default_factory=dict)  # std of each prediction, by data set
    spread_seconds: float = 0.0         # calibrating the spread (config ``spread``): the fits it added
    prior_strength: list[dict] | None = None   # a list of prior strengths: each one's CV score, the chosen marked

    def score(self, rank_by: str) -> float:
        """The number the run ranks by: the CV score, or the RMS on the validation set (3-D, mm; with ``rank_on:
        orientation`` the orientation's RMS angle, mrad)."""
        if rank_by == "cv":
            return self.cv_rms_3d
        validation = self.metrics["validation"]
        return validation["orientation"]["rms_angle"] if self.rank_on == "orientation" else validation["rms_3d"]

    @property
    def n_regions(self) -> int:
        part = regions_of(self.model)
        return part.partition_.n_regions if part is not None else 1


@dataclass(frozen=True)
class RunPlan:
    """What a run will fit: its cross-validation, the entries it can fit (granularities that no fold
    supports left out; every kind that takes a robot given the run's, registered), the notes about what was
    left out, and the repeat scatter of the data (mm)."""

    cv: CVPlan
    models: tuple[ModelSpec, ...]
    notes: tuple[str, ...] = ()
    repeat_scatter_mm: float | None = None


@dataclass
class RunResult:
    """A finished run: its config, data sets (in the base frame), the robot (with the registered tool), the
    figures of doing nothing, every model's result and the best model's name."""

    config: RunConfig
    datasets: dict[str, Measurements]
    robot: Robot | None
    uncompensated: dict[str, dict]
    models: list[ModelResult]
    best: str
    seconds: float
    registrations: dict[str, Registration] = field(default_factory=dict)
    plan: RunPlan | None = None
    iso9283: dict[str, dict] = field(default_factory=dict)   # ISO 9283 pose figures of each test set (iso_figures)

    @functools.cached_property
    def design(self):
        """The observability of the identification set (:func:`partcal.study.plan.run_indices`; None without a
        robot), computed once for what ``partcal run`` prints and the report shows."""
        if self.robot is None:
            return None
        return run_indices(self.robot, self.datasets["identification"].q_deg)

    @property
    def best_caveats(self) -> list[str]:
        """Where the best model leaves the part the run does not rank on worse than doing nothing, in words.

        In a pose run (``predict: pose``) ranked on the position, the orientation's RMS angle on each data
        set against the uncompensated one (ranked on the orientation, the position's 3-D RMS). The rule
        that chooses does not change: the choice is by cross-validation on the ranked part, and the
        caveats only say what it costs (warned, in metrics.json as ``best_caveats`` and in the report).
        """
        if self.config.predict != "pose":
            return []
        best = next(r for r in self.models if r.spec.name == self.best)
        other, unit = ("orientation", "mrad") if self.config.rank_on == "position" else ("position", "mm")
        out = []
        for name, before in self.uncompensated.items():
            after = best.metrics.get(name)
            if after is None or "orientation" not in before or "orientation" not in after:
                continue
            b, a = ((before["orientation"]["rms_angle"], after["orientation"]["rms_angle"]) if other == "orientation"
                    else (before["rms_3d"], after["rms_3d"]))
            if a > b:
                out.append(f"the best model, {self.best!r}, leaves the {other} of {name} worse than doing nothing: "
                           f"{a:.3f} {unit} RMS against {b:.3f} uncompensated (the run ranks on the "
                           f"{self.config.rank_on}; rank_on: {other}, or a model identified from the {other} too, "
                           f"avoids it)")
        return out

    @property
    def best_reason(self) -> str:
        """Which rule chose ``best``, in words (metrics.json, the report and the printed table say it)."""
        best = next(r for r in self.models if r.spec.name == self.best)
        return rank_reason(self.config, self.plan.cv if self.plan else None, is_physical(best.model))
