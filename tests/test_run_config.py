"""The run's config: base diagram -> task overlay -> --set, each layer type-checked by pydrake's
loader; train writes it into the run and evaluate runs on exactly it."""

import json
import pickle

import pytest
import yaml

from corn_drake.config.plumbing import diagram_files as run_config
from corn_drake.cli import main
from corn_drake.config.scene import ObjectConfig
from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.config.training import TrainConfig
from corn_drake.config.plumbing.yaml_io import config_fields
from corn_drake.errors import InputError
from corn_drake.config.plumbing.overrides import apply_sets, config_changes
from corn_drake.config.plumbing.diagram_files import load_teacher_config
from corn_drake.run_folders.config_file import load_run_config

# A task overlay: only what differs from the base (keys every TaskConfig keeps).
OVERLAY = "task:\n  name: mytask\n  episode_steps: 7\ncontroller:\n  max_position_delta: 0.03\n"


@pytest.fixture
def tasks_dir(tmp_path, monkeypatch):
    """diagrams/tasks/ replaced by a folder holding two overlays."""
    folder = tmp_path / "tasks"
    folder.mkdir()
    (folder / "mytask.yaml").write_text(OVERLAY)
    (folder / "short.yaml").write_text("task:\n  episode_steps: 20\n")
    monkeypatch.setattr(run_config, "TASKS_DIR", folder)
    return folder


def test_the_base_diagram_names_only_what_differs_from_the_defaults():
    named = yaml.safe_load(run_config.BASE_DIAGRAM.read_text()) or {}
    defaults = config_fields(TeacherDiagramConfig())
    base = config_fields(load_teacher_config())
    # Every key the file names changes its default, and nothing else changes (today: no key;
    # the dataclass defaults are the paper's task).
    assert set(_leaves(named)) == {k for k in defaults if base[k] != defaults[k]}


def _leaves(data, prefix=""):
    if not isinstance(data, dict):
        return [prefix]
    return [leaf for k, v in data.items() for leaf in _leaves(v, f"{prefix}.{k}" if prefix else k)]


def test_a_task_overlay_changes_only_what_it_names(tasks_dir, tmp_path):
    base = config_fields(load_teacher_config())
    for task in ("mytask", tasks_dir / "mytask.yaml", str(tasks_dir / "mytask.yaml")):
        cfg = load_teacher_config(task)
        assert (cfg.task.name, cfg.task.episode_steps) == ("mytask", 7)
        assert cfg.controller.max_position_delta == 0.03
        changed = {c.key for c in config_changes(load_teacher_config(), cfg)}
        assert changed == {"task.name", "task.episode_steps", "controller.max_position_delta"}
    # Without task.name the task is named by its file.
    assert load_teacher_config("short").task.name == "short"
    other = tmp_path / "elsewhere" / "wide_push.yml"
    other.parent.mkdir()
    other.write_text("task:\n  episode_steps: 20\n")
    assert load_teacher_config(other).task.name == "wide_push"
    assert config_fields(load_teacher_config(None)) == base


def test_task_names_and_files_are_checked(tasks_dir, tmp_path):
    with pytest.raises(InputError, match="--task nosuch: no such task; the tasks are "
                                         "mytask, short"):
        load_teacher_config("nosuch")
    with pytest.raises(FileNotFoundError, match="nowhere.yaml"):
        load_teacher_config(tmp_path / "nowhere.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("controller:\n  max_position_delta: far\n")
    with pytest.raises(InputError, match=r"bad.yaml.*controller.max_position_delta"):
        load_teacher_config(bad)
    bad.write_text("task:\n  episode_stepz: 3\n")
    with pytest.raises(InputError, match=r"bad.yaml.*episode_stepz"):
        load_teacher_config(bad)


def test_set_overrides_address_the_run_config_and_say_what_they_changed():
    before = TrainConfig()
    after = apply_sets(before, ["ppo.lr=1e-4", "env.task.episode_steps=50",
                                "controller.max_position_delta=0.03", "encoder=123",
                                "scene.physics.plant.time_step=0.01",
                                "task.goal_x=[-0.1, 0.1]"])
    assert after.ppo.lr == 1e-4 and after.env.task.episode_steps == 50
    assert after.encoder == "123"  # a string field takes the text as it is
    assert after.env.scene.physics.time_step == 0.01
    assert after.env.task.goal_x == [-0.1, 0.1]
    assert before.ppo.lr == 3e-4 and before.env.task.episode_steps == 300  # not mutated
    changes = {c.key: (c.old, c.new) for c in config_changes(before, after)}
    assert changes == {"ppo.lr": (3e-4, 1e-4), "env.task.episode_steps": (300, 50),
                       "env.controller.max_position_delta": (0.06, 0.03),
                       "encoder": ("", "123"), "env.scene.physics.plant.time_step": (0.0125, 0.01),
                       "env.task.goal_x": ([-0.16, 0.16], [-0.1, 0.1])}
    assert "total_steps 20000 -> 40000" in [str(c) for c in config_changes(
        before, apply_sets(before, ["total_steps=40000"]))]


@pytest.mark.parametrize("item, named", [
    ("ppo.lrr=1", "unknown key 'ppo.lrr'; did you mean 'ppo.lr'? ppo has gamma"),
    ("nosection.x=1", "unknown key 'nosection'"),
    ("policy.x=1", "policy is a value"),
    ("task.episode_steps=lots", "env.task.episode_steps = 'lots'"),
    ("ppo.epochs=1.5", "epochs"),
    ("seed", "expected KEY=VALUE"),
])
def test_a_bad_set_item_is_named(item, named):
    with pytest.raises(InputError, match=f"--set {item}") as error:
        apply_sets(TrainConfig(), [item])
    assert named in str(error.value)


def test_set_may_be_limited_to_the_env():
    assert apply_sets(TrainConfig(), ["task.episode_steps=5"], only="env").env.task.episode_steps == 5
    with pytest.raises(InputError, match="only env"):
        apply_sets(TrainConfig(), ["ppo.lr=1e-4"], only="env")


def test_physics_holds_drakes_plant_config():
    from pydrake.common.yaml import yaml_dump_typed
    from pydrake.multibody.plant import MultibodyPlantConfig

    from corn_drake.builders.teacher import build_teacher_diagram

    cfg = apply_sets(TrainConfig(), ["scene.physics.plant.time_step=0.01",
                                     "scene.physics.plant.discrete_contact_approximation=lagged"])
    physics = cfg.env.scene.physics
    assert isinstance(physics.plant, MultibodyPlantConfig) and physics.time_step == 0.01
    dumped = yaml.safe_load(yaml_dump_typed(physics))
    assert "time_step" not in dumped and dumped["plant"]["time_step"] == 0.01  # one home
    # Ray pickles configs to its workers; Drake's struct alone does not pickle.
    again = pickle.loads(pickle.dumps(cfg))
    assert config_fields(again) == config_fields(cfg)
    plant = build_teacher_diagram(cfg.env).scene.plant
    assert plant.time_step() == 0.01
    assert plant.get_discrete_contact_approximation().name == "kLagged"
    # The physics step is still settable through physics.time_step (the stable-pose drops).
    physics.time_step = 0.002
    assert physics.plant.time_step == 0.002


def test_object_config_names_one_object_or_all_train_objects():
    assert not ObjectConfig().cycles_library
    whole = ObjectConfig(kind="library", library="lib", library_objects="train")
    assert whole.cycles_library
    assert not ObjectConfig(kind="library", library="lib", object_id="a").cycles_library
    for bad, named in [(ObjectConfig(kind="library", library="lib"), "object_id is empty"),
                       (ObjectConfig(kind="library"), "library is empty"),
                       (ObjectConfig(kind="library", library="lib", library_objects="some"),
                        "library_objects must be one of one, train"),
                       (ObjectConfig(kind="library", library="lib", library_objects="train",
                                     object_id="a"), "give one or the other"),
                       (ObjectConfig(kind="sphere"), "kind must be one of")]:
        with pytest.raises(InputError, match=named):
            bad.check()
    from corn_drake.builders.teacher import object_spec_from_config

    with pytest.raises(InputError, match="library_objects: train"):
        object_spec_from_config(whole)


def test_run_trained_on_a_task_overlay_evaluates_on_that_task(tmp_path, capsys):
    """Must show (issue 19): `evaluate --run RUN` with no config argument runs on the task the
    run was trained on: its name, its action step and its episode length."""
    task = tmp_path / "overlay.yaml"
    task.write_text(OVERLAY)
    run = tmp_path / "run"
    assert main(["train", "--task", str(task), "--policy", "state", "--steps", "256",
                 "--envs-per-worker", "2", "--rollout-steps", "16", "--out", str(run),
                 "--no-progress"]) == 0
    recorded = load_run_config(run)
    assert (recorded.env.task.name, recorded.env.task.episode_steps) == ("mytask", 7)
    assert recorded.env.controller.max_position_delta == 0.03
    report = tmp_path / "eval.json"
    capsys.readouterr()
    assert main(["evaluate", "--run", str(run), "--episodes", "3", "--record", "0",
                 "--report", str(report)]) == 0
    assert "on task mytask" in capsys.readouterr().out
    data = json.loads(report.read_text())
    assert (data["task"], data["action_step"], data["overrides"]) == ("mytask", 0.03, [])
    steps = [e["steps"] for e in data["episodes"]]
    assert max(steps) == 7 and all(1 <= s <= 7 for s in steps), steps  # 7-step episodes
    # An explicit override is applied, printed and recorded.
    assert main(["evaluate", "--run", str(run), "--episodes", "2", "--record", "0",
                 "--set", "task.episode_steps=3", "--report", str(report), "--overwrite"]) == 0
    assert "env.task.episode_steps 7 -> 3" in capsys.readouterr().out
    data = json.loads(report.read_text())
    assert data["overrides"] == [{"key": "env.task.episode_steps", "old": 7, "new": 3}]
    assert max(e["steps"] for e in data["episodes"]) == 3 and data["task"] == "mytask"
    # A reference controller takes the task by --task; without it, the paper's task.
    report = tmp_path / "eval_still.json"  # its own report: the run's is not its to replace
    assert main(["evaluate", "--run", "still", "--task", str(task), "--episodes", "1",
                 "--record", "0", "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    assert (data["task"], data["action_step"]) == ("mytask", 0.03)
    assert [e["steps"] for e in data["episodes"]] == [7]
    assert main(["evaluate", "--run", "still", "--set", "task.episode_steps=2", "--episodes", "1",
                 "--record", "0", "--report", str(report), "--overwrite"]) == 0
    data = json.loads(report.read_text())
    assert (data["task"], data["action_step"]) == ("full6d", 0.06)
    # `curves` labels the run with its policy and task, from the same config.
    from corn_drake.commands.reporting.curves import run_history

    assert run_history(run)[0] == "state on mytask (run)"


def test_overrides_apply_to_any_run_config_and_refuse_unknown_keys():
    # The one override mechanism serves DistillConfig as well as TrainConfig: its env sections
    # are named without `env.`, and the config given is not modified.
    from corn_drake.config.plumbing.overrides import apply_sets
    from corn_drake.config.training import DistillConfig

    cfg = DistillConfig()
    out = apply_sets(cfg, ["cameras.mode=tracking", "window=4", "env.tracker.min_points=30"])
    assert (out.env.cameras.mode, out.window, out.env.tracker.min_points) == ("tracking", 4, 30)
    assert (cfg.env.cameras.mode, cfg.window) == ("fixed", 8)
    with pytest.raises(InputError, match="unknown key 'bogus'"):
        apply_sets(cfg, ["bogus=1"])
    with pytest.raises(InputError, match="teacher is a value"):
        apply_sets(cfg, ["teacher.seed=1"])
