"""The learned 6D chooser (rl/imitation/) and its data: a labelled state's observation is rebuilt
from its recorded pose; `label` labels train objects only, along DAgger's mixture, and resumes;
`fit-chooser` fits the value network to the labels and writes a run folder that `evaluate`
plays; the choice rule and the fit do what they say on data built to tell."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from corn_drake.errors import InputError
from corn_drake.rl.primitive.value_chooser.features import BASE_FEATURES, PRIOR_COLUMN
from corn_drake.rl.imitation.fit import agreement, fit_value
from corn_drake.rl.primitive.value_chooser.value_model import ValueNet, choose_index

TINY = ["--set", "planner.random_motions=0", "--set", "planner.beam=1", "--set",
        "primitive.max_primitives=2"]


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    from tests.fixtures import write_loadable_library

    return write_loadable_library(tmp_path_factory.mktemp("chooser") / "lib", 2, 1)


def test_the_choice_is_the_most_valuable_of_the_most_rewarding_beam():
    reward = np.array([0.5, 0.1, 0.4, 0.9, 0.2])
    value = np.array([1.0, 9.0, 2.0, 0.5, 3.0])
    # The beam of 2 is candidates 3 and 0; 1 is worth most but is outside it.
    assert choose_index(reward, value, 2) == 0
    assert choose_index(reward, value, 5) == 1
    assert choose_index(reward, value, 1) == 3
    assert choose_index(np.zeros(3), np.zeros(3), 2) == 0  # ties: the first


def _synthetic(states: int, seed: int) -> dict:
    """States of 6 candidates whose reward is a known function of two feature columns, the
    expert choosing the best: a network that learns the function agrees with it."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(states * 6, BASE_FEATURES)).astype(np.float32)
    x[:, PRIOR_COLUMN] = 0.0  # no prior: all of it must be learned
    reward = (np.tanh(x[:, 0]) - 0.5 * x[:, 1] ** 2).astype(np.float32)
    state = np.repeat(np.arange(states), 6)
    chosen = np.array([np.flatnonzero(state == s)[np.argmax(reward[state == s])]
                       for s in range(states)])
    value = np.full_like(reward, np.nan)
    value[chosen] = reward[chosen]
    return {"x": x, "reward": reward, "value": value, "state": state, "chosen": chosen,
            "object": np.array(["o"] * states)}


def test_the_fit_learns_a_ranking_it_can_and_is_the_same_for_the_same_seed():
    torch.set_num_threads(1)
    train, held = _synthetic(300, 0), _synthetic(100, 1)
    untrained = agreement(ValueNet(BASE_FEATURES).eval(), held, False, 1)
    model = fit_value(train, False, 1500, seed=0)
    fitted = agreement(model, held, False, 1)
    assert fitted["agreement"] > 0.6 > untrained["agreement"]
    assert fitted["pick_reward"] > untrained["pick_reward"]
    assert fitted["best_reward"] == pytest.approx(fitted["expert_reward"])
    again = fit_value(train, False, 1500, seed=0)
    assert all(torch.equal(a, b) for a, b in zip(model.state_dict().values(),
                                                 again.state_dict().values()))


def test_the_early_stop_keeps_the_weights_that_pick_best_on_held_out_objects():
    """Held-out objects whose best candidates follow another rule than the fitted ones': the fit
    keeps the weights before its first update (the prior), which pick better there than what it
    learned; held-out objects that follow the same rule: it keeps learned weights."""
    from corn_drake.rl.imitation.fit import select_states, split_objects

    torch.set_num_threads(1)
    train = _synthetic(300, 0)
    other = _synthetic(100, 1)
    other["reward"] = -other["reward"]  # another rule: the fitted one's best is their worst
    other["x"][:, PRIOR_COLUMN] = other["reward"]  # and the prior knows their rule
    other["chosen"] = np.array([np.flatnonzero(other["state"] == s)[
        np.argmax(other["reward"][other["state"] == s])] for s in range(100)])
    model = fit_value(train, False, 600, seed=0, held=other, beam=1)
    assert model.kept_update == 0
    assert agreement(model, other, False, 1)["agreement"] == 1.0  # the prior's picks
    alike = _synthetic(100, 2)
    model = fit_value(train, False, 600, seed=0, held=alike, beam=1)
    assert model.kept_update > 0 and agreement(model, alike, False, 1)["agreement"] > 0.6
    # The split holds whole objects out: no object's states on both sides.
    data = dict(train, object=np.array([f"o{s % 5}" for s in range(300)]))
    kept, held = split_objects(data, 0.2, seed=0)
    assert len(set(held["object"])) == 1 and not set(held["object"]) & set(kept["object"])
    assert len(kept["chosen"]) + len(held["chosen"]) == 300
    assert np.all(kept["state"][kept["chosen"]] == np.arange(len(kept["chosen"])))
    again = select_states(data, np.arange(300))
    assert np.array_equal(again["chosen"], data["chosen"])


def test_an_untrained_network_chooses_as_its_prior():
    x = torch.zeros(4, BASE_FEATURES)
    x[:, PRIOR_COLUMN] = torch.tensor([0.1, 0.7, 0.3, 0.2])
    out = ValueNet(BASE_FEATURES).eval()(x).detach().numpy()
    assert choose_index(out[:, 0], out[:, 1], 4) == 1


def test_a_labelled_state_is_rebuilt_from_its_pose(library):
    """The observation the expert searched from and the one rebuilt from the recorded pose
    agree to the pose's micrometre, at every decision of an episode."""
    from corn_drake.assets.library import list_objects, load_object_spec
    from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
    from corn_drake.config.planner import PlannerConfig, PlannerRunConfig
    from corn_drake.rl.envs.primitive_env import PrimitiveEnv
    from corn_drake.rl.planner.labels import labelled_states
    from corn_drake.rl.planner.search import Planner
    from corn_drake.rl.planner.sources import make_sources

    run_cfg = PlannerRunConfig(env=load_primitive_env_config("full6d"))
    primitive = dataclasses.replace(run_cfg.primitive, max_primitives=3)
    config = PlannerConfig(sources=["push", "turn"], per_kind=1, depth=1)
    spec = load_object_spec(library, list_objects(library, "train")[0])
    env = PrimitiveEnv(run_cfg.env, primitive, spec)
    planner = Planner(config, make_sources(config, primitive, run_cfg.env.task))
    obs, _ = env.reset(seed=5)
    planner.reset(5)
    seen = []
    for _ in range(3):
        seen.append(obs)
        obs, _, terminated, truncated, _ = planner.act(env, obs)
        if terminated or truncated:
            break
    record = {"seed": 5, "decisions": planner.decisions}
    rebuilt = list(labelled_states(PrimitiveEnv(run_cfg.env, primitive, spec), record, []))
    assert len(rebuilt) == len(seen) >= 2
    moved = np.abs(seen[-1]["object_position"] - seen[0]["object_position"]).max()
    assert moved > 1e-3  # the states differ, so agreeing below means something
    for (again, _, distance), original in zip(rebuilt, seen):
        assert distance == 0.0
        for key in ("cloud", "normals", "object_keypoints", "goal", "physics"):
            np.testing.assert_allclose(again[key], original[key], atol=5e-6, err_msg=key)


def test_label_fit_and_evaluate_end_to_end(library, tmp_path, capsys, monkeypatch):
    """Labels of the expert, a chooser fitted to them, its run evaluated; a round with that
    run as the learner executes its choices and labels where they lead; a rerun resumes."""
    from corn_drake.cli import main
    from corn_drake.rl.planner.labels import read_labels

    out = tmp_path / "labels" / "r0"
    assert main(["label", "--objects", str(library), "--episodes", "2", "--no-progress", *TINY,
                 "--out", str(out)]) == 0
    settings, _, records = read_labels(out.with_name("r0.labels.jsonl.gz"))
    assert settings["library_content_hash"] and "learner" not in settings
    assert {r["object"] for r in records} == set(settings["objects"])  # train objects only
    assert all(len(d["pose"]) == 7 for r in records for d in r["decisions"])
    # The state each beam candidate reached is labelled too (its candidates' rewards).
    reached = [c for r in records for d in r["decisions"] for c in d["children"]]
    assert reached and all(len(c["pose"]) == 7 and c["labels"] for c in reached)
    assert all(row[-1] is None for c in reached for row in c["labels"])
    run = tmp_path / "chooser"
    assert main(["fit-chooser", "--labels", str(out.parent), "--objects", str(library),
                 "--out-run", str(run), "--updates", "20", "--tokens", "--no-progress",
                 "--cache", str(tmp_path / "cache"), "--validate",
                 str(out.with_name("r0.labels.jsonl.gz"))]) == 0
    printed = capsys.readouterr().out
    assert "validation: picks the expert's candidate" in printed
    searched = sum(len(r["decisions"]) for r in records)
    assert f"states ({searched} searched" in printed
    assert f"labels of {searched + len(reached)} states" in printed
    # Cached by episode: a labels file holding one of these episodes rebuilds nothing.
    from corn_drake.rl.imitation import dataset
    from corn_drake.storage.gz_lines import read_lines, write_lines

    assert len(list((tmp_path / "cache").glob("*.npz"))) == len(records)
    part = tmp_path / "part.labels.jsonl.gz"
    write_lines(part, read_lines(out.with_name("r0.labels.jsonl.gz"))[0][:2])
    with monkeypatch.context() as m:
        m.setattr(dataset, "_replay_context", lambda *a: pytest.fail("rebuilt a cached episode"))
        one = dataset.file_arrays(part, library, tmp_path / "cache")
    assert len(one["chosen"]) == sum(1 + len(d["children"]) for d in records[0]["decisions"])
    assert main(["fit-chooser", "--labels", str(out.parent), "--objects", str(library),
                 "--out-run", str(run), "--no-progress"]) == 2  # never replaces a folder
    report = tmp_path / "eval.json"
    assert main(["evaluate", "--run", str(run), "--objects", str(library), "--split", "unseen",
                 "--episodes", "1", "--record", "0", "--no-progress", "--set",
                 "primitive.max_primitives=2", "--report", str(report)]) == 0
    assert json.loads(report.read_text())["chooser"] == "expert_value"
    # DAgger: the learner acts at every state (beta 0); each state is still searched.
    again = tmp_path / "labels" / "r1"
    argv = ["label", "--objects", str(library), "--episodes", "1", "--no-progress", *TINY,
            "--learner", str(run), "--seed", "1", "--out", str(again)]
    assert main(argv) == 0
    settings, _, records = read_labels(again.with_name("r1.labels.jsonl.gz"))
    assert settings["learner"] == str(run) and settings["beta"] == 0.0
    assert {d["actor"] for d in records[0]["decisions"]} == {"learner"}
    assert all(d["labels"] for d in records[0]["decisions"])
    before = again.with_name("r1.labels.jsonl.gz").read_bytes()
    assert main(argv) == 0
    assert again.with_name("r1.labels.jsonl.gz").read_bytes() == before  # resumed: nothing new


@pytest.mark.parametrize("extra, said", [
    (["--beta", "0.5"], "without --learner only the expert can act"),
    (["--learner", "models/weights/full6d_outcome", "--beta", "1.5"], "a probability"),
    (["--episodes-from", "3"], "no episodes before --episodes"),
])
def test_label_refuses_bad_settings_in_one_line(library, tmp_path, capsys, extra, said):
    from corn_drake.cli import main

    assert main(["label", "--objects", str(library), "--episodes", "2", "--out",
                 str(tmp_path / "r"), *extra]) == 2
    assert said in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_label_does_not_replace_another_runs_report(library, tmp_path, capsys):
    from corn_drake.cli import main

    theirs = tmp_path / "eval_push.json"
    theirs.write_text(json.dumps({"run": "models/weights/push_primitive", "success_rate": 0.84,
                                  "episodes": []}))
    assert main(["label", "--objects", str(library), "--out", str(tmp_path / "eval_push")]) == 2
    assert "push_primitive" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eval_push.json"]


def test_label_refuses_a_library_without_train_objects(tmp_path, capsys):
    from corn_drake.cli import main
    from tests.fixtures import write_loadable_library

    unseen_only = write_loadable_library(tmp_path / "lib", 0, 1)
    assert main(["label", "--objects", str(unseen_only), "--out", str(tmp_path / "r")]) == 2
    assert "no train objects" in capsys.readouterr().err


def test_labels_of_other_objects_are_refused(library, tmp_path):
    """A labels file whose library hash is not the library's: replaying it would describe other
    states, so it is refused, naming the file."""
    from corn_drake.rl.imitation.dataset import state_arrays

    path = tmp_path / "x.labels.jsonl"
    settings = {"objects": ["box_00"], "library_content_hash": "0" * 64, "task": "full6d",
                "seed": 0, "planner": {"sources": ["policy"]}}
    path.write_text(json.dumps({"settings": settings, "columns": []}) + "\n")
    with pytest.raises(InputError, match="content hash differs"):
        state_arrays(path, library)


@pytest.fixture
def own_ray():
    """A Ray this test starts and stops: the tests after it find none."""
    import ray

    yield
    ray.shutdown()


def test_label_over_ray_workers_writes_the_same_episodes(library, tmp_path, own_ray):
    """`label --workers 2`: the episodes played in two Ray worker processes, the objects sent
    through the object store, land in the rows and labels files as one process writes them (the
    same episodes, objects and seeds, every state labelled), and a rerun resumes."""
    from corn_drake.cli import main
    from corn_drake.rl.planner.labels import read_labels

    argv = ["label", "--objects", str(library), "--episodes", "3", "--no-progress", *TINY]
    assert main([*argv, "--out", str(tmp_path / "one")]) == 0
    assert main([*argv, "--workers", "2", "--out", str(tmp_path / "two")]) == 0
    one = read_labels(tmp_path / "one.labels.jsonl.gz")
    two = read_labels(tmp_path / "two.labels.jsonl.gz")
    assert one[0] == two[0]  # the same settings: parts of one labelling merge
    key = lambda r: (r["episode"], r["object"], r["seed"])  # noqa: E731
    assert sorted(map(key, one[2])) == sorted(map(key, two[2])) and len(two[2]) == 3
    assert all(d["labels"] for r in two[2] for d in r["decisions"])
    report = json.loads((tmp_path / "two.json").read_text())
    assert report["complete"] and len(report["episodes"]) == 3
    before = (tmp_path / "two.rows.jsonl").read_text()
    assert main([*argv, "--workers", "2", "--out", str(tmp_path / "two")]) == 0
    assert (tmp_path / "two.rows.jsonl").read_text() == before


def test_a_planner_worker_that_dies_is_replaced_and_its_episode_played_again(library, tmp_path,
                                                                             own_ray):
    """The first worker to unpack episode 0's object dies (its process exits, as a killed or
    lost node's would); a new worker plays the episode again from its seed: every episode comes
    back once."""
    import os

    from corn_drake.assets.library import list_objects, load_object_spec
    from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
    from corn_drake.config.planner import PlannerConfig, PlannerRunConfig
    from corn_drake.evaluation.planner_workers import play_on_workers
    from corn_drake.rl.planner.search import PlannerPolicy
    from corn_drake.rl.workers.ray_workers import init_ray

    marker = tmp_path / "died_once"

    def dies_once(spec):
        if not marker.exists():
            marker.write_text("x")
            os._exit(1)
        return spec

    class DyingSpec:  # unpickled in the worker: the first unpickling ends its process
        def __init__(self, spec):
            self.spec = spec

        def __reduce__(self):
            return dies_once, (self.spec,)

    run_cfg = PlannerRunConfig(env=load_primitive_env_config("full6d"))
    primitive = dataclasses.replace(run_cfg.primitive, max_primitives=1)
    policy = PlannerPolicy(PlannerConfig(sources=["push"], per_kind=1, depth=1), primitive)
    object_id = list_objects(library, "train")[0]
    spec = load_object_spec(library, object_id)
    init_ray()
    rows = []
    jobs = [(0, object_id, DyingSpec(spec), 11), (1, object_id, spec, 12)]
    play_on_workers(jobs, policy, run_cfg.env, None, None, 2, rows.append)
    assert marker.exists()  # a worker did die
    assert sorted(r["episode"] for r in rows) == [0, 1]
    assert all(r["seed"] == seed for r, seed in zip(sorted(rows, key=lambda r: r["episode"]),
                                                    (11, 12)))
