"""Pieces of the gallery stills and of `corn-drake ship`, without a simulation."""

import numpy as np
import pytest

from corn_drake.commands.reporting.gallery import montage
from corn_drake.commands.reporting.ship import library_arguments
from corn_drake.evaluation.shipping import check_measured_weights
from corn_drake.evaluation.shipping import check_report as _check_report
from corn_drake.errors import InputError
from corn_drake.viz.gallery import pick_steps, paint


def test_paint_colours_only_points_the_depth_image_shows():
    image = np.zeros((20, 30, 3), np.uint8)
    depth = np.full((20, 30), 1.0)
    depth[:, 15:] = 0.5  # a nearer surface covers the right half
    pixels = np.array([[5.0, 5.0], [20.0, 5.0], [20.0, 15.0], [-3.0, 5.0], [5.0, 12.0]])
    z = np.array([1.0, 0.8, 0.5, 1.0, -1.0])  # visible, hidden behind, on it, outside, behind cam
    colours = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 9, 9], [7, 7, 7]], np.uint8)
    out, painted = paint(image, depth, pixels, z, colours, radius=1)
    assert painted == 2
    assert tuple(out[5, 5]) == (255, 0, 0) and tuple(out[15, 20]) == (0, 0, 255)
    assert tuple(out[5, 20]) == (0, 0, 0)  # the hidden point left no colour
    assert tuple(out[12, 5]) == (0, 0, 0)
    assert (image == 0).all()  # the input is not drawn on


def testpick_steps_and_montage():
    assert pick_steps("start,middle,end", 101) == [0, 50, 100]
    assert pick_steps("3", 10) == [3]
    with pytest.raises(ValueError, match="outside"):
        pick_steps("12", 10)
    a, b = np.zeros((4, 5, 3), np.uint8), np.ones((4, 5, 3), np.uint8)
    m = montage([a, b])
    assert m.shape == (4, 18, 3) and (m[:, 5:13] == 255).all()


def test_library_command_is_parsed_and_checked():
    args = library_arguments("corn-drake objects --num-objects 80 --seed=3 --split unseen --out data/x")
    assert args == {"--num-objects": "80", "--seed": "3", "--split": "unseen", "--out": "data/x"}
    with pytest.raises(InputError, match="corn-drake objects"):
        library_arguments("python build.py --out x")
    with pytest.raises(InputError, match="no --out"):
        library_arguments("corn-drake objects --num-objects 8")
    # Read by `objects`' own parser: a switch is not taken for the next flag's value (a library
    # of one's own meshes kept at their size), and what `objects` refuses is refused here.
    mine = library_arguments("corn-drake objects --source meshes/ --keep-size --unit cm "
                             "--out data/mine")
    assert mine == {"--source": "meshes/", "--keep-size": True, "--unit": "cm",
                    "--out": "data/mine"}
    with pytest.raises(InputError, match="--library-command .*--unit"):
        library_arguments("corn-drake objects --unit inch --out x")


def test_a_card_quotes_only_its_own_runs_unseen_report(tmp_path):
    report = {"success_rate": 0.5, "episodes": [{}], "run": str(tmp_path / "run"),
              "split": "unseen", "policy": "corn", "overrides": []}
    runs = (str(tmp_path / "run"), str(tmp_path / "shipped"))
    _check_report(report, runs, "r.json")
    _check_report({**report, "run": str(tmp_path / "shipped")}, runs, "r.json")
    with pytest.raises(InputError, match="evaluated run"):
        _check_report({**report, "run": str(tmp_path / "other")}, runs, "r.json")
    with pytest.raises(InputError, match="split"):
        _check_report({**report, "split": "train"}, runs, "r.json")
    with pytest.raises(InputError, match="overrides"):
        _check_report({**report, "overrides": [{"key": "env.task.name"}]}, runs, "r.json")
    _check_report({**report, "checkpoint": "last.pt"}, runs, "r.json")
    with pytest.raises(InputError, match="kept checkpoint step_000051200.pt"):
        _check_report({**report, "checkpoint": "step_000051200.pt"}, runs, "r.json")
    with pytest.raises(InputError, match="success_rate"):
        _check_report({k: v for k, v in report.items() if k != "success_rate"}, runs, "r.json")


def test_a_card_quotes_only_a_report_of_the_weights_it_ships():
    """A report records the checkpoint file and env steps it measured; ship compares them with
    the weights it packs (issue 53: a report at 3,200 steps went out with 3,520-step weights)."""
    import io

    report = {"env_steps": 3200, "checkpoint": "last.pt"}
    check_measured_weights(report, "r.json", "runs/x", 3200, "last.pt")
    with pytest.raises(InputError) as refused:
        check_measured_weights(report, "r.json", "runs/x", 3520, "last.pt")
    message = str(refused.value)
    assert "\n" not in message and "r.json" in message and "runs/x" in message
    assert "3200" in message and "3520" in message
    # The run's last.pt was unusable and ship would pack prev.pt: not the file measured.
    with pytest.raises(InputError, match="prev.pt"):
        check_measured_weights(report, "r.json", "runs/x", 3200, "prev.pt")
    # A report from before `checkpoint` was recorded measured last.pt (all evaluate read then).
    check_measured_weights({"env_steps": 3200}, "r.json", "runs/x", 3200, "last.pt")
    # One from before env_steps was recorded cannot be checked: accepted, with a warning line.
    stream = io.StringIO()
    check_measured_weights({}, "old.json", "runs/x", 3520, "last.pt", stream=stream)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 1 and lines[0].startswith("warning: --report old.json records no env_steps")
