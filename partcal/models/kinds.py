"""The table of model kinds: one row per kind, the one place callers look a kind up.

A run config names a kind (``kind: series``), a model file names it too
(``"kind": "global"``), and the study layer (config, model files, a run's stages,
predictor) and the report ask the kind's estimator what they need: its
parameters and their rules, its section of a model file, its smallest sample
count, its description. They find the estimator here, never by testing types.
A row states what a kind may be (named in a config, a partition's local model,
a residual); nothing else in partcal states it.

Adding a kind is one estimator class (a subclass of ``ErrorModelBase``
that implements ``fit``, ``predict``, ``file_section`` and
``from_file_section``) and one call of :func:`register_kind`; see
docs/architecture.md, "Adding a model kind". The mechanism (rows, the
file body of any kind) is :mod:`partcal.models.kindtable`.
"""

from __future__ import annotations

from . import kindtable
from .gp import GaussianProcessErrorModel
from .kindtable import (INPUT_SPACES, KINDS, Kind, body_of, config_kinds, kind_of, may_be_residual, model_from_body,
                        register_kind, residual_kinds, unregister_kind)
from .kinematic import KinematicModel
from .partitioned import PartitionedErrorModel
from .pose import PoseErrorModel
from .series import ErrorModel

for _row in (
    Kind("series", ErrorModel, regions=True),
    Kind("gaussian_process", GaussianProcessErrorModel, regions=True),
    Kind("kinematic", KinematicModel, residual=False),
    Kind("partitioned", PartitionedErrorModel, in_config=False),
    Kind("pose", PoseErrorModel, in_config=False),        # a run of pose errors makes it, of a residual's kind too
):
    kindtable.add_built_in(_row)

BUILT_IN = tuple(KINDS)

__all__ = ["BUILT_IN", "INPUT_SPACES", "KINDS", "Kind", "body_of", "config_kinds", "kind_of", "may_be_residual",
           "model_from_body", "register_kind", "residual_kinds", "unregister_kind"]
