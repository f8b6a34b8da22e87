"""The chain's analytic derivatives against central differences, for the two parametrizations on a six-row and an
eight-row arm, with every kind of joint error and every parameter off nominal (turns of the complete rows and of
the base included): the positions' Jacobian and the flange's angular velocity per parameter, the latter against
differences of the flange's rotation matrices (the survivors of mutation testing on ``chain.py`` and
``joint_errors.py``: slices and strides that only a robot of another row count notices, turns that only matter
away from zero)."""

import numpy as np
import pytest

from partcal import load_robot
from partcal.calibration.chain import chain_at
from partcal.calibration.joint_errors import JointErrors
from partcal.calibration.parameters import geometric_size, nominal_values, parameter_names


def _angular_velocity(up, down, middle, step):
    """The turn (radians per unit) that carries ``middle`` (n, 3, 3) along, from rotations a step either side."""
    spin = (up - down) / (2 * step) @ np.transpose(middle, (0, 2, 1))         # skew: [w]x
    return np.stack([spin[:, 2, 1], spin[:, 0, 2], spin[:, 1, 0]], axis=1)


@pytest.mark.parametrize("name", ["universal_robots_ur10", "motoman_sk120"])
@pytest.mark.parametrize("parametrization", ["dh", "complete"])
def test_the_jacobian_and_the_turns_match_central_differences(name, parametrization):
    robot = load_robot(name)
    rng = np.random.default_rng(12)
    q = rng.uniform(-120, 120, (6, 6))
    errors = JointErrors.for_robot(robot, [2, 3], [1, 2, 1, 0, 0, 1])
    names = [n for n, _ in parameter_names(robot, errors, parametrization)]
    size = geometric_size(robot, parametrization)
    values = nominal_values(robot, errors, parametrization)
    values[:size] += rng.normal(0, 0.5, size)                      # mm and degrees: rows' turns, base turn
    values[size:] = rng.normal(0, 0.3, errors.size)
    values[[k for k, n in enumerate(names) if n.startswith("compliance")]] = 2e-4
    payload = rng.uniform(0, 80, len(q))

    def at(v, jacobian=False):
        return chain_at(robot, errors, q, v, payload, parametrization, True, jacobian)

    chain = at(values, True)
    assert chain.jac.shape == chain.omega.shape == (len(q), 3, values.size)
    for k in range(values.size):
        step = 1e-5 * max(1.0, abs(values[k]))
        up, down = values.copy(), values.copy()
        up[k] += step
        down[k] -= step
        high, low = at(up), at(down)
        position = (high.positions - low.positions) / (2 * step)
        turn = _angular_velocity(high.rotations, low.rotations, chain.rotations, step)
        scale = max(np.abs(position).max(), 1.0)
        np.testing.assert_allclose(chain.jac[:, :, k], position, atol=1e-6 * scale, err_msg=names[k])
        np.testing.assert_allclose(chain.omega[:, :, k], turn, atol=1e-8 + 1e-6 * np.abs(turn).max(),
                                   err_msg=names[k])
