"""Torque law, action scaling and the DLS IK step, each on single-step outputs."""

import numpy as np
import pytest

from corn_drake.config.scene import ControllerConfig
from corn_drake.scene.franka import EFFORT_LIMITS
from corn_drake.systems.control.ik import ActionScaling, ActionToJointTargets, check_action
from corn_drake.systems.control.impedance_controller import make_impedance_controller
from corn_drake.timing import PolicyClock

BACKENDS = ["python", "symbolic"]

Q_HOME = np.array([0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.8])
BASE = np.array([-0.5, 0.0, 0.4])


def _torque(ctrl, x, q_target, gains, noise=None, std=0.0):
    ctx = ctrl.CreateDefaultContext()
    ctrl.GetInputPort("robot_state").FixValue(ctx, x)
    ctrl.GetInputPort("q_target").FixValue(ctx, q_target)
    ctrl.GetInputPort("gains").FixValue(ctx, gains)
    ctrl.GetInputPort("noise_std").FixValue(ctx, [std])
    if noise is not None:
        ctrl.GetInputPort("unit_noise").FixValue(ctx, noise)
    return ctrl.GetOutputPort("actuation").Eval(ctx)


@pytest.mark.parametrize("backend", BACKENDS)
def test_torque_equals_formula_inside_limits(backend):
    ctrl = make_impedance_controller(EFFORT_LIMITS, backend=backend)
    rng = np.random.default_rng(1)
    q, v = rng.uniform(-1, 1, 7), rng.uniform(-1, 1, 7)
    dq = rng.uniform(-0.02, 0.02, 7)
    kp = rng.uniform(10, 200, 7)
    kd = rng.uniform(0.1, 2, 7) * np.sqrt(kp)
    tau = _torque(ctrl, np.concatenate([q, v]), q + dq, np.concatenate([kp, kd]))
    expected = kp * dq - kd * v
    assert np.all(np.abs(expected) < EFFORT_LIMITS)  # the case really is inside the limits
    np.testing.assert_allclose(tau, expected, rtol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_torque_is_clamped_to_effort_limits(backend):
    ctrl = make_impedance_controller(EFFORT_LIMITS, backend=backend)
    x = np.zeros(14)
    tau = _torque(ctrl, x, np.full(7, 2.0), np.concatenate([np.full(7, 200.0), np.zeros(7)]))
    np.testing.assert_allclose(tau, EFFORT_LIMITS)
    tau = _torque(ctrl, x, np.full(7, -2.0), np.concatenate([np.full(7, 200.0), np.zeros(7)]))
    np.testing.assert_allclose(tau, -EFFORT_LIMITS)


@pytest.mark.parametrize("backend", BACKENDS)
def test_torque_noise_scales_with_its_std_input(backend):
    ctrl = make_impedance_controller(EFFORT_LIMITS, with_noise=True, backend=backend)
    unit = np.linspace(-1, 1, 7)
    tau = _torque(ctrl, np.zeros(14), np.zeros(7), np.zeros(14), noise=unit, std=0.03)
    np.testing.assert_allclose(tau, 0.03 * unit)


def test_backends_agree_on_random_inputs():
    py, sym = (make_impedance_controller(EFFORT_LIMITS, True, b) for b in BACKENDS)
    rng = np.random.default_rng(5)
    for _ in range(20):
        args = (rng.uniform(-2, 2, 14), rng.uniform(-2, 2, 7),
                np.concatenate([rng.uniform(10, 200, 7), rng.uniform(0, 30, 7)]))
        noise, std = rng.normal(size=7), rng.uniform(0, 1)
        np.testing.assert_allclose(_torque(py, *args, noise, std), _torque(sym, *args, noise, std),
                                   rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="torque_backend"):
        make_impedance_controller(EFFORT_LIMITS, backend="cuda")


def test_action_scaling_maps_bounds_and_clips():
    s = ActionScaling(ControllerConfig())
    lo, hi = s.to_physical(-np.ones(20)), s.to_physical(np.ones(20))
    np.testing.assert_allclose(lo[:6], [-0.06] * 3 + [-0.1] * 3)
    np.testing.assert_allclose(hi[6:13], 200.0)
    np.testing.assert_allclose(lo[13:], 0.1)
    np.testing.assert_allclose(s.to_physical(5 * np.ones(20)), hi)  # clipped to [-1, 1]


@pytest.mark.parametrize("bad", [np.full(20, np.nan), np.r_[np.zeros(19), np.inf], np.zeros(7)])
def test_bad_actions_are_rejected_with_a_clear_error(bad):
    with pytest.raises(ValueError, match="action"):
        check_action(bad)


def test_ik_step_reduces_end_effector_error():
    ik = ActionToJointTargets(ControllerConfig(), PolicyClock(0.1, 0.0125), BASE)
    X0 = ik.ee_pose(Q_HOME)
    rng = np.random.default_rng(2)
    for _ in range(10):
        a = np.concatenate([rng.uniform(-1, 1, 6), np.zeros(14)])
        q_t, kp, kd, phys = ik.targets(a, Q_HOME, BASE + X0.translation(), 0.05)
        target_p = X0.translation() + phys[:3]
        X1 = ik.ee_pose(q_t)
        # One damped step: most of the translation error is removed, and the orientation moves
        # by the commanded axis-angle (world frame) to first order.
        before = np.linalg.norm(phys[:3])
        after = np.linalg.norm(X1.translation() - target_p)
        assert after < 0.5 * before
        dR = (X1.rotation() @ X0.rotation().inverse()).ToAngleAxis()
        assert np.linalg.norm(dR.angle() * dR.axis() - phys[3:6]) < 0.5 * np.linalg.norm(phys[3:6])
        np.testing.assert_allclose(kd, phys[13:] * np.sqrt(kp))


def test_ik_target_is_clamped_to_the_object_box():
    cfg = ControllerConfig()
    ik = ActionToJointTargets(cfg, PolicyClock(0.1, 0.0125), BASE)
    p_ee = ik.ee_pose(Q_HOME).translation()
    radius = 0.05
    # Object far below the hand: the target may not go above object z + radius + margin.
    object_world = BASE + p_ee - np.array([0, 0, 0.5])
    a = np.zeros(20)
    a[2] = 1.0  # ask for +6 cm in z
    q_t, *_ = ik.targets(a, Q_HOME, object_world, radius)
    z_limit = (object_world - BASE)[2] + radius + cfg.object_margin
    assert ik.ee_pose(q_t).translation()[2] < p_ee[2]  # clamped target pulls the hand down
    assert z_limit < p_ee[2]
