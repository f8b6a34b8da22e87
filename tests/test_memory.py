"""Memory of a run's fits: estimated before fitting, refused with one line; a MemoryError is one line too."""

import numpy as np
import pytest
from conftest import partcal_cli

from partcal.study import memory
from partcal.study.config import load_config
from partcal.study.prepare import check_run, load_datasets


@pytest.fixture(scope="module")
def big(tmp_path_factory, sk120):
    """20,000 poses of the SK120 (nominal = forward kinematics, measured 1 mm off) and a config with GPs."""
    tmp = tmp_path_factory.mktemp("big")
    rng = np.random.default_rng(0)
    q = rng.uniform(sk120.limits_deg[:, 0], sk120.limits_deg[:, 1], (20000, 6))
    q[:, 2] = q[:, 1] - rng.uniform(15, 115, len(q))           # inside the parallelogram's constraint
    p = sk120.positions(q)
    rows = np.hstack([q, p, p + rng.normal(0, 1, p.shape)])
    np.savetxt(tmp / "big.csv", rows, fmt="%.6f", delimiter=",",
               header="q1,q2,q3,q4,q5,q6,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas", comments="")
    return tmp


CONFIG = """name: big
robot: motoman_sk120
data:
  identification: big.csv
models:
  - {name: FDP(AI), inputs: joint, solver: {method: lstsq}}
"""


def test_the_estimate_is_the_size_of_the_matrices():
    from partcal.models.gp import GaussianProcessErrorModel
    from partcal.models.partition import KMeansPartition
    from partcal.models.partitioned import PartitionedErrorModel

    gp = GaussianProcessErrorModel(inputs="joint")              # by default the search sees 1,000 samples
    assert gp.peak_fit_bytes(20000, 6) == (8.0 * 3 * 20000**2, "hyperparameter search on 1000 samples, "
                                                                "solve on 20000")
    every = GaussianProcessErrorModel(inputs="joint", hyper_samples=20000)
    assert every.peak_fit_bytes(20000, 6) == (8.0 * 15 * 20000**2, "hyperparameter search on 20000 samples, "
                                                                    "solve on 20000")
    regions = PartitionedErrorModel(partition=KMeansPartition(8),
                                    local=GaussianProcessErrorModel(inputs="joint", hyper_samples=2000))
    assert regions.peak_fit_bytes(20000, 6) == (8.0 * 3 * 5000**2, "hyperparameter search on 2000 samples, "
                                                                    "solve on 5000")   # regions of 2 * 20000 / 8


def test_a_global_gp_on_20000_poses_is_refused_by_check_before_any_fit(big, monkeypatch):
    text = CONFIG + "  - {name: GP(AI), kind: gaussian_process, inputs: joint, hyper_samples: 20000}\n"
    (big / "gp.yaml").write_text(text)
    config = load_config(big / "gp.yaml")
    data, _, _ = load_datasets(config)
    monkeypatch.setattr(memory, "available_bytes", lambda: 16 * 1024.0**3)        # a 16 GB machine
    with pytest.raises(ValueError, match=r"models\[1\]\.hyper_samples \(line 7\): 'GP\(AI\)': its fit would need about "
                                         r"44.7 GB \(hyperparameter search on 20000 samples, solve on 20000\) but the "
                                         r"machine has 16.0 GB available: set hyper_samples"):
        check_run(config, data)
    text = CONFIG + ("  - {name: GP(AI), kind: gaussian_process, inputs: joint, hyper_samples: 2000,\n"
                     "     partition: {method: kmeans, n_regions: 16}}\n")
    (big / "gp.yaml").write_text(text)
    check_run(load_config(big / "gp.yaml"), data)                       # 2000 to search, about 2,500 per region


def test_a_memory_error_is_one_line(monkeypatch, capsys):
    from partcal import cli

    def boom(args):
        raise MemoryError()

    monkeypatch.setattr(cli, "_cmd_run", boom)
    assert cli.main(["run", "any.yaml"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("partcal: error: out of memory")


def test_check_refuses_it_from_the_command_line_on_this_machine(big):
    available = memory.available_bytes()
    if available is None or available > 8.0 * 15 * 20000**2:
        pytest.skip("this machine could hold the fit")
    (big / "gp.yaml").write_text(CONFIG + "  - {name: GP(AI), kind: gaussian_process, inputs: joint, "
                                          "hyper_samples: 20000}\n")
    res = partcal_cli("run", "--check", str(big / "gp.yaml"))
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "would need about 44.7 GB" in res.stderr, res.stderr
