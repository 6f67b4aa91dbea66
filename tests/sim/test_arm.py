"""Closed-form IK agrees with MuJoCo's own forward kinematics of the scene."""

import mujoco
import numpy as np
import pytest

from tableteach.sim import arm
from tableteach.sim.scene import load_scene


@pytest.fixture(scope="module")
def scene():
    return load_scene()


def _yaw_of(vec: np.ndarray) -> float:
    return float(np.arctan2(vec[1], vec[0]))


def test_ik_reaches_targets_in_mujoco(scene):
    model, layout = scene
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    grip = model.site("grip").id
    hand = model.body("hand").id
    for _ in range(50):
        radius, angle = rng.uniform(0.3, 0.7), rng.uniform(-1.2, 1.2)  # the tables' span
        target = np.array([radius * np.cos(angle), radius * np.sin(angle), rng.uniform(0.40, 0.62)])
        finger_yaw = rng.uniform(-np.pi, np.pi)
        q = arm.solve_ik(layout.arm, target, finger_yaw)
        data.qpos[layout.arm_qpos] = q
        mujoco.mj_kinematics(model, data)
        np.testing.assert_allclose(data.site_xpos[grip], target, atol=1e-9)
        hand_axes = data.xmat[hand].reshape(3, 3)
        np.testing.assert_allclose(hand_axes[:, 2], [0, 0, -1], atol=1e-9)  # pointing down
        closing = _yaw_of(hand_axes[:, 1])
        assert abs((closing - finger_yaw + np.pi) % (2 * np.pi) - np.pi) < 1e-9
        np.testing.assert_allclose(arm.forward(layout.arm, q)[0], target, atol=1e-9)


def test_ik_is_vectorised(scene):
    _, layout = scene
    targets = np.array([[0.4, 0.2, 0.5], [0.5, -0.3, 0.45], [0.3, 0.0, 0.6]])
    batch = arm.solve_ik(layout.arm, targets, np.array([0.0, 1.0, 2.0]))
    singles = [arm.solve_ik(layout.arm, t, y) for t, y in zip(targets, [0.0, 1.0, 2.0], strict=True)]
    np.testing.assert_allclose(batch, np.array(singles))


def test_unreachable_target_is_refused(scene):
    _, layout = scene
    with pytest.raises(arm.UnreachableError, match=r"out of reach: expected .* of the shoulder"):
        arm.solve_ik(layout.arm, np.array([1.5, 0.0, 0.4]), 0.0)
