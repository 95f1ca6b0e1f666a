"""Statements in the docs that once contradicted the code stay corrected.

Each row names a claim the code disproves (the test that measures the fact is named beside it).
"""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

WRONG_CLAIMS = [
    # Actions have no latency (tests/test_timing.py measures it).
    ("README.md", "one physics step (12.5 ms) after it is latched"),
    ("docs/guide.md", "one physics step (12.5 ms) after it is latched"),
    # ~70 % of contact samples penetrate (tests/test_contact_data.py measures it).
    ("corn_drake/contact/generate.py", "roughly half penetrate"),
    # U(0.05, 0.10) m comes from the authors' code; the paper gives a 0.1-0.3 m scale.
    ("corn_drake/assets/processing/process.py", "the paper's object-radius range"),
]


@pytest.mark.parametrize("path, claim", WRONG_CLAIMS)
def test_corrected_claim_is_gone(path, claim):
    assert claim not in (ROOT / path).read_text()


def test_min_goal_distance_names_both_sources():
    # The paper says 0.1 m, the authors' code samples 0.055 m: where it is set says which we use.
    text = (ROOT / "corn_drake/config/task.py").read_text()
    block = text[text.index("class Full6dGoal"):text.index("min_goal_distance: float")]
    assert "0.1 m" in block and "0.055" in block


# The README's quickstart and the guide that holds the rest of the commands (issue 55 moved the
# pipeline, the weights' evaluation and the reference out of the README into docs/guide.md).
COMMAND_PAGES = ("README.md", "docs/guide.md", "CONTRIBUTING.md")


def _readme_commands():
    """Every `corn-drake ...` command line in the code blocks of COMMAND_PAGES (continuations
    joined), as (page, line)."""
    for page in COMMAND_PAGES:
        text = (ROOT / page).read_text()
        blocks = text.split("```")[1::2]
        for block in blocks:
            for line in block.replace("\\\n", " ").splitlines():
                line = line.strip().removeprefix(".venv/bin/")
                if line.startswith("corn-drake "):
                    yield page, line


def test_readme_commands_parse_with_the_current_flags():
    """A renamed flag (issue 36: demo --objects, bench sim --config/--envs) must not survive in
    the README: every command there parses."""
    import shlex

    from corn_drake.cli import build_parser

    commands = list(_readme_commands())
    assert len(commands) > 10
    assert any(page == "README.md" for page, _ in commands)  # the quickstart's own
    parser = build_parser()
    for page, line in commands:
        argv = shlex.split(line, comments=True)[1:]
        try:
            parser.parse_args(argv)
        except SystemExit:
            pytest.fail(f"{page}: `{line}` does not parse")


# A file path the package's comments cite as where to read more: `docs/....md`, `experiments/...`
# or a module (`corn_drake/...py`, or relative to the package: `rl/training/dagger.py`). Pages and
# modules move; a citation left behind sends the reader nowhere (config/retired.py once cited a
# log that had moved).
_UNITS = sorted(p.name for p in (ROOT / "corn_drake").iterdir()
                if p.is_dir() and not p.name.startswith("_"))
# A path after --report or --out is what a command writes, not a citation.
_CITED = (r"(?<![\w/.])(?<!--report )(?<!--out )((?:docs|experiments)/[\w./-]+\.(?:md|py|sh|jsonl|json)(?!\w)|corn_drake/[\w/]+\.py"
          r"|(?:" + "|".join(_UNITS) + r")/[\w/]+\.py)")


def cited_paths(text: str) -> list[str]:
    """The cited paths of `text`, each relative to the checkout."""
    import re

    found = [m.rstrip(".") for m in re.findall(_CITED, text)]
    return [m if m.split("/")[0] in ("docs", "experiments", "corn_drake") else f"corn_drake/{m}"
            for m in found]


def test_every_path_the_package_and_docs_cite_exists():
    missing = []
    texts = [*sorted((ROOT / "corn_drake").rglob("*.py")), *sorted((ROOT / "docs").rglob("*.md")),
             ROOT / "README.md"]
    for path in texts:
        for cited in cited_paths(path.read_text()):
            if not (ROOT / cited).exists():
                missing.append(f"{path.relative_to(ROOT)} cites {cited}")
    assert missing == []
    # Not vacuous: the scan finds each form of citation it is for.
    assert cited_paths("see docs/many_core.md, corn_drake/rl/training/dagger.py and "
                       "rl/ppo/agent.py; --report docs/x.json") == ["docs/many_core.md", "corn_drake/rl/training/dagger.py",
                                               "corn_drake/rl/ppo/agent.py"]
