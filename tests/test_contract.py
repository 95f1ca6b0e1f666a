"""No module outside corn_drake/contract.py hard-codes an observation or action size or the
free-body state layout, and everything built from the contract agrees with it.

Two halves:
  * a source scan (AST) of every module of the package for the ways sizes were hard-coded
    before the contract existed: integer literals as port / state / noise sizes, redefinitions
    of contract names, hand-summed sizes (`9 + 20 + 14 + 5`), literal slices of the free-body
    state or the action (`[4:7]`, `[:4]`, `prev[:13]`, `phys[6:13]`), literal sizes in array
    shapes and `*_dim` defaults equal to a contract size;
  * import checks: the systems' ports, the observation layout, the gymnasium spaces, the
    networks' input and output sizes and Drake's own free-body state agree with the contract.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import corn_drake
from corn_drake import contract
from corn_drake.rl.policy_kinds import POLICY_KINDS

PACKAGE = Path(corn_drake.__file__).resolve().parent
CONTRACT = PACKAGE / "contract.py"

# Contract names (constants and tuples): defining one anywhere else is a second source of truth.
CONTRACT_NAMES = {n for n in vars(contract) if n.isupper()}
KEY_TUPLES = [contract.OBS_KEYS, contract.STUDENT_OBS_KEYS, contract.CONTEXT_KEYS]
# Sizes that identify a layout when they appear as a literal in an array shape or a default.
LAYOUT_SIZES = {contract.ACTION_DIM, contract.CONTEXT_DIM, contract.FREE_BODY_STATE_DIM,
                contract.KEYPOINTS_DIM, contract.STATE_FEATURE_DIM, contract.ROBOT_STATE_DIM,
                contract.POSE9_DIM}
# Calls that size a Drake port, state or noise source: (callable name, positional index, keyword)
SIZED_CALLS = {"DeclareVectorInputPort": (1, "size"), "DeclareVectorOutputPort": (1, "size"),
               "DeclareDiscreteState": (0, None), "RandomSource": (1, "num_outputs"),
               "ZeroOrderHold": (1, "vector_size"), "Multiplexer": (0, "input_sizes"),
               "MakeVectorVariable": (0, None)}
ARRAY_CONSTRUCTORS = {"zeros", "ones", "empty", "full", "randn", "rand", "standard_normal",
                      "normal", "uniform"}
# Literal slices of the free-body state [q_wxyz (0:4), p (4:7), w (7:10), v (10:13)].
FREE_BODY_SLICES = {(None, 4), (0, 4), (4, 7), (7, 10), (10, 13)}


def _literal_int(node) -> int | None:
    """The value of an expression made only of integer literals and + - * (else None)."""
    if isinstance(node, ast.Constant) and type(node.value) is int:
        return node.value
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult)):
        left, right = _literal_int(node.left), _literal_int(node.right)
        if left is not None and right is not None:
            return {ast.Add: left + right, ast.Sub: left - right,
                    ast.Mult: left * right}[type(node.op)]
    return None


def _call_name(call: ast.Call) -> str:
    f = call.func
    return f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""


def _sized_argument(call: ast.Call, index: int, keyword: str | None):
    for kw in call.keywords:
        if keyword and kw.arg == keyword:
            return kw.value
    return call.args[index] if len(call.args) > index else None


def _slice_bound(node) -> int | None:
    return None if node is None else _literal_int(node)


def hard_coded_sizes(source: str, filename: str = "<source>") -> list[str]:
    """Each hard-coded layout size in `source`, as 'file:line: what'."""
    tree = ast.parse(source, filename)
    found = []

    def flag(node, what):
        found.append(f"{filename}:{node.lineno}: {what}")

    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            name = _call_name(node)
            if name in SIZED_CALLS:
                arg = _sized_argument(node, *SIZED_CALLS[name])
                sizes = arg.elts if isinstance(arg, (ast.List, ast.Tuple)) else [arg]
                for size in sizes:
                    value = _literal_int(size) if size is not None else None
                    if value is not None and value > 1:
                        flag(node, f"{name} sized by the literal {value}")
            if name in ARRAY_CONSTRUCTORS or name == "reshape":
                shape_parts = []
                for arg in [*node.args, *(kw.value for kw in node.keywords if kw.arg in ("size", "shape"))]:
                    shape_parts += arg.elts if isinstance(arg, ast.Tuple) else [arg]
                for part in shape_parts:
                    if _literal_int(part) in LAYOUT_SIZES:
                        flag(node, f"{name} shaped by the literal {_literal_int(part)}")
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names = [t.id for t in targets if isinstance(t, ast.Name)]
            names += [e.id for t in targets if isinstance(t, ast.Tuple) for e in t.elts
                      if isinstance(e, ast.Name)]
            for target in names:
                if target in CONTRACT_NAMES or target.endswith("_DIM"):
                    flag(node, f"assigns {target} (a contract name or a *_DIM size)")
            value = node.value
            if isinstance(value, (ast.Tuple, ast.List)) and all(
                    isinstance(e, ast.Constant) and isinstance(e.value, str) for e in value.elts):
                strings = tuple(e.value for e in value.elts)
                if any(set(strings) == set(keys) for keys in KEY_TUPLES):
                    flag(node, f"copies a contract key tuple {strings}")
            if (value is not None and isinstance(value, ast.BinOp)
                    and _literal_int(value) is not None):
                flag(node, f"assigns a hand-summed size ({ast.unparse(value)})")
        elif isinstance(node, ast.Subscript):
            # x[a:b], and each axis of x[a:b, c:d]
            axes = node.slice.elts if isinstance(node.slice, ast.Tuple) else [node.slice]
            for axis in axes:
                if not isinstance(axis, ast.Slice):
                    continue
                lower, upper = _slice_bound(axis.lower), _slice_bound(axis.upper)
                if (lower, upper) in FREE_BODY_SLICES and (axis.lower is None or lower is not None):
                    flag(node, f"slices [{ast.unparse(axis)}] (the free-body state layout)")
                elif {lower, upper} & {contract.FREE_BODY_STATE_DIM, contract.ACTION_DIM}:
                    flag(node, f"slices [{ast.unparse(axis)}] (a state or action size)")
        elif isinstance(node, ast.arguments):
            params = [*node.posonlyargs, *node.args, *node.kwonlyargs]
            defaults = [None] * (len(node.posonlyargs) + len(node.args) - len(node.defaults)) \
                + list(node.defaults) + list(node.kw_defaults)
            for param, default in zip(params, defaults):
                if (default is not None and param.arg.endswith("_dim")
                        and _literal_int(default) in LAYOUT_SIZES):
                    flag(default, f"parameter {param.arg} defaults to the literal "
                                  f"{_literal_int(default)}")
    return found


def _package_modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if p != CONTRACT)


def test_no_module_outside_the_contract_hard_codes_a_layout_size():
    found = []
    for path in _package_modules():
        found += hard_coded_sizes(path.read_text(), str(path.relative_to(PACKAGE.parent)))
    assert not found, "hard-coded sizes (import them from corn_drake/contract.py):\n" + \
        "\n".join(found)


# The scanner must catch each way a size was hard-coded before: one planted example per rule.
@pytest.mark.parametrize("planted", [
    'self.DeclareVectorInputPort("object_state", 13)',
    'self.DeclareVectorOutputPort("action", 20, self._calc)',
    'self.DeclareVectorInputPort("goal", size=9)',
    "self._state = self.DeclareDiscreteState(3 * 7 + 20)",
    'RandomSource(RandomDistribution.kGaussian, 7, 0.1)',
    "Multiplexer([13, 9, 1])",
    "ZeroOrderHold(0.1, 23, 0.0)",
    "CONTEXT_DIM = 9 + 20 + 14 + 5",
    "ACTION_DIM = 20",
    "GOAL_DIM = goal_size()",
    "NUM_JOINTS = 7",
    "PREVIOUS_SIZE = 13 + 9 + 1",
    'OBS_KEYS = ("cloud", "hand_state", "robot_state", "previous_action", "goal", "physics", "object_keypoints")',
    'KEYS = ("cloud", "hand_state", "robot_state", "previous_action", "goal")',
    'CONTEXT = ["goal", "previous_action", "robot_state", "physics"]',
    "p = x[4:7]",
    "q = x[:4]",
    "obj, hand = prev[:13], prev[13:16]",
    "kp = phys[6:13]",
    "S[0:3, 4:7] = np.eye(3)",
    "a = np.zeros(20)",
    "hand = torch.randn(batch, 9)",
    "x = obs.reshape(-1, 48)",
    "def f(hand_dim: int = 9): pass",
])
def test_the_scan_catches_a_planted_size(planted):
    assert hard_coded_sizes(planted), planted


@pytest.mark.parametrize("fine", [
    'self.DeclareVectorInputPort("object_state", FREE_BODY_STATE_DIM)',
    'self.DeclareVectorInputPort("object_radius", 1)',
    'self.DeclareVectorOutputPort("points", 3 * cfg.num_points, self._calc)',
    "Multiplexer([n, ROBOT_STATE_DIM])",
    "p = x[FREE_BODY_POSITION]",
    "xy = p[:2]",
    "position, quaternion = pose[:3], pose[3:]",
    "CHECKPOINT_KEYS = ('policy', 'agent')",
    "from corn_drake.contract import ACTION_DIM",
    "def f(token_dim: int = 128): pass",
])
def test_the_scan_leaves_contract_uses_alone(fine):
    assert hard_coded_sizes(fine) == []


# --- everything built from the contract agrees with it ---------------------------------------
def test_contract_sizes_are_consistent():
    assert contract.ACTION_DIM == sum(contract.slice_size(s) for s in contract.ACTION_SLICES.values())
    ends = sorted((s.start, s.stop) for s in contract.ACTION_SLICES.values())
    assert ends[0][0] == 0 and ends[-1][1] == contract.ACTION_DIM
    assert all(a[1] == b[0] for a, b in zip(ends, ends[1:]))  # contiguous, no overlap
    parts = (contract.FREE_BODY_QUATERNION, contract.FREE_BODY_POSITION,
             contract.FREE_BODY_ANGULAR_VELOCITY, contract.FREE_BODY_LINEAR_VELOCITY)
    assert sum(contract.slice_size(s) for s in parts) == contract.FREE_BODY_STATE_DIM
    assert contract.CONTEXT_DIM == sum(contract.observation_size(k) for k in contract.CONTEXT_KEYS)
    shapes = contract.observation_shapes(100)
    assert tuple(shapes) == contract.OBS_KEYS and shapes["cloud"] == (100, 3)
    assert set(contract.STUDENT_OBS_KEYS) <= set(contract.OBS_KEYS)
    assert contract.student_observation_shapes(100) == {k: shapes[k] for k in contract.STUDENT_OBS_KEYS}


def test_drake_free_body_state_has_the_contract_layout():
    """Drake's state output of a model instance with one free body is [q_wxyz, p, w, v]."""
    from pydrake.math import RigidTransform, RollPitchYaw
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.multibody.math import SpatialVelocity
    from pydrake.multibody.tree import SpatialInertia

    plant = MultibodyPlant(0.0)
    instance = plant.AddModelInstance("object")
    body = plant.AddRigidBody("object", instance, SpatialInertia.SolidBoxWithMass(1, .1, .1, .1))
    plant.Finalize()
    ctx = plant.CreateDefaultContext()
    X = RigidTransform(RollPitchYaw(0.3, -0.2, 1.1), [0.1, -0.2, 0.5])
    plant.SetFreeBodyPose(ctx, body, X)
    plant.SetFreeBodySpatialVelocity(ctx, body, SpatialVelocity([1, 2, 3], [4, 5, 6]))
    x = plant.get_state_output_port(instance).Eval(ctx)
    assert x.shape == (contract.FREE_BODY_STATE_DIM,)
    p, R = contract.free_body_pose(x)
    np.testing.assert_allclose(p, X.translation())
    np.testing.assert_allclose(R, X.rotation().matrix(), atol=1e-12)
    np.testing.assert_allclose(x[contract.FREE_BODY_ANGULAR_VELOCITY], [1, 2, 3])
    np.testing.assert_allclose(x[contract.FREE_BODY_LINEAR_VELOCITY], [4, 5, 6])
    q = X.rotation().ToQuaternion()
    np.testing.assert_allclose(x[contract.FREE_BODY_QUATERNION], [q.w(), q.x(), q.y(), q.z()],
                               atol=1e-12)


def _port_sizes(system, kind: str) -> dict[str, int]:
    count = getattr(system, f"num_{kind}_ports")()
    get = getattr(system, f"get_{kind}_port")
    return {get(i).get_name(): get(i).size() for i in range(count)
            if get(i).get_data_type().name == "kVectorValued"}


def test_teacher_systems_and_env_follow_the_contract():
    from corn_drake.rl.envs.teacher_env import TeacherEnv
    from corn_drake.systems.policies.policy import PolicySystem

    env = TeacherEnv()
    n = env.cfg.scene.object.cloud_points
    shapes = contract.observation_shapes(n)
    assert {k: s.shape for k, s in env.observation_space.items()} == shapes
    assert env.action_space.shape == (contract.ACTION_DIM,)
    obs, _ = env.reset(seed=0)
    assert {k: v.shape for k, v in obs.items()} == shapes
    outputs = _port_sizes(env.handles.observations, "output")
    assert {k: outputs[k] for k in contract.OBS_KEYS} == \
        {k: contract.observation_size(k, n) for k in contract.OBS_KEYS}
    assert env.handles.observations.layout.shapes == shapes
    ik_inputs = _port_sizes(env.handles.ik, "input")
    assert ik_inputs["action"] == contract.ACTION_DIM
    assert ik_inputs["object_state"] == contract.FREE_BODY_STATE_DIM
    assert _port_sizes(env.handles.reward, "input")["object_state"] == contract.FREE_BODY_STATE_DIM
    plant_state = env.diagram.GetOutputPort("plant.object_state").size()
    assert plant_state == contract.FREE_BODY_STATE_DIM
    policy = PolicySystem(object(), n, stochastic=True)
    assert _port_sizes(policy, "input") == {"observation": sum(contract.observation_size(k, n)
                                                               for k in contract.OBS_KEYS),
                                            "unit_noise": contract.ACTION_DIM}
    assert _port_sizes(policy, "output") == {"action": contract.ACTION_DIM}


def test_student_observations_follow_the_contract():
    from corn_drake.systems.student_observations import StudentObservations

    system = StudentObservations(64, 0.0, 0.0)
    sizes = {k: int(np.prod(s)) for k, s in contract.student_observation_shapes(64).items()}
    assert _port_sizes(system, "output") == sizes
    assert [system.get_output_port(i).get_name() for i in range(system.num_output_ports())] == \
        list(contract.STUDENT_OBS_KEYS)


@pytest.mark.parametrize("kind", POLICY_KINDS)
def test_networks_take_the_contract_sizes(kind):
    import torch

    from corn_drake.rl.ppo.agent import TeacherAgent, obs_to_tensors
    from corn_drake.rl.pretrained_encoders import make_encoder

    agent = TeacherAgent(kind, make_encoder(kind))
    assert agent.context_normalizer.mean.shape == (contract.CONTEXT_DIM,)
    assert agent.log_std.shape == (contract.ACTION_DIM,)
    batch = {k: np.random.default_rng(0).normal(size=(2, *s)).astype(np.float32)
             for k, s in contract.observation_shapes().items()}
    obs = obs_to_tensors(batch)
    assert obs["context"].shape == (2, contract.CONTEXT_DIM)
    with torch.no_grad():
        mu, value = agent(obs)
    assert mu.shape == (2, contract.ACTION_DIM) and value.shape == (2,)
    assert agent.act({k: v[0] for k, v in batch.items()}).shape == (contract.ACTION_DIM,)
