"""The table of model kinds: one row per kind, the one place callers look a kind up.

A run config names a kind (``kind: series``), a model file names it too
(``"kind": "global"``), and the study layer (config, model files, a run's stages,
predictor) and the report ask the kind's estimator what they need: its
parameters and their rules, its section of a model file, its smallest sample
count, its description. They find the estimator here, never by testing types.
A row states what a kind may be (named in a config, a partition's local model,
a residual) and what only some kinds can answer (swarm runs, equations, an
identification, ...: the row's columns, see :class:`~partcal.models.kindtable.Kind`);
nothing else in partcal states it, and callers ask through the functions here
(``equations_of(model)``, ``regions_of(model)``, ...).

Adding a kind is one estimator class (a subclass of ``ErrorModelBase``
that implements ``fit``, ``predict``, ``file_section`` and
``from_file_section``) and one call of :func:`register_kind`; see
docs/architecture.md, "Adding a model kind". The mechanism (rows, the
file body of any kind) is :mod:`partcal.models.kindtable`.
"""

from __future__ import annotations

from . import kindtable
from .gp import GP_REGIONS, GaussianProcessErrorModel
from .kindtable import (INPUT_SPACES, KINDS, Kind, RegionFit, body_of, check_body, config_kinds, equations_of,
                        fits_pose_errors, identification_of, is_physical, kind_of, may_be_residual, model_from_body,
                        own_prior, pso_rms_ratio, reads_targets, regions_kinds, regions_of, register_kind,
                        residual_kinds, run_summary, swarm_runs, unregister_kind)
from .kinematic import KinematicModel
from .partitioned import PartitionedErrorModel
from .pose import PoseErrorModel
from .series import SERIES_REGIONS, ErrorModel

for _row in (
    Kind("series", ErrorModel, regions=True, region_fit=SERIES_REGIONS, swarm=True, equations=True),
    Kind("gaussian_process", GaussianProcessErrorModel, regions=True, region_fit=GP_REGIONS),
    Kind("kinematic", KinematicModel, residual=False, takes_residual=True, pose_errors=True, own_prior=True,
         holds_regions=True, identified=True),
    Kind("partitioned", PartitionedErrorModel, in_config=False, swarm=True, holds_regions=True, flat_file=True),
    # a run of pose errors makes it, of a residual's kind too; it answers what its parts answer
    Kind("pose", PoseErrorModel, in_config=False, swarm=True, equations=True, holds_regions=True),
):
    kindtable.add_built_in(_row)

BUILT_IN = tuple(KINDS)

__all__ = ["BUILT_IN", "INPUT_SPACES", "KINDS", "Kind", "RegionFit", "body_of", "check_body", "config_kinds",
           "equations_of", "fits_pose_errors", "identification_of", "is_physical", "kind_of", "may_be_residual",
           "model_from_body", "own_prior", "pso_rms_ratio", "reads_targets", "regions_kinds", "regions_of",
           "register_kind", "residual_kinds", "run_summary", "swarm_runs", "unregister_kind"]
