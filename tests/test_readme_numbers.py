"""The README and the results page quote their reports, and stay short and linked.

Every success figure in README.md's results table and in docs/results/README.md's task tables
must equal the `success_rate` of the report named in the same row (to the three decimals
quoted), every 95 % interval there must be the Wilson interval of that report's success count,
README.md stays under 1,500 words, and every relative link in the front pages resolves.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"
NUMBER = re.compile(r"\d+\.\d{3}")
INTERVAL = re.compile(r"(\d\.\d{3})-(\d\.\d{3})")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
# Pages whose relative links must resolve (the front page, the results pages, the new top-level
# documents and the logs that replaced the old results history).
LINKED_PAGES = ("README.md", "docs/results/README.md", "docs/results/primitive/README.md",
                "docs/guide.md", "CONTRIBUTING.md", "CHANGELOG.md", "experiments/LOG.md",
                "experiments/primitive_policy/LOG.md", "docs/results/demo/README.md")


def _tables(text: str) -> list[list[list[str]]]:
    """Markdown tables as lists of rows of cells (the header row first, the rule row dropped)."""
    tables, current = [], []
    for line in text.splitlines():
        if line.startswith("|"):
            cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
            if not all(set(cell) <= set("-: ") for cell in cells):
                current.append(cells)
        elif current:
            tables.append(current)
            current = []
    if current:
        tables.append(current)
    return tables


def _section(text: str, heading: str) -> str:
    start = text.index(heading)
    end = text.find("\n## ", start + len(heading))
    return text[start:end if end != -1 else len(text)]


def _report(path: Path) -> tuple[float, int]:
    """(success rate, episodes) of an evaluate report or a lookahead report."""
    report = json.loads(path.read_text())
    if "success_rate" not in report:  # a lookahead report: the lookahead's own figures
        report = report["lookahead"]
    episodes = report["episodes"]
    return report["success_rate"], episodes if isinstance(episodes, int) else len(episodes)


def _wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    p = successes / n
    denominator = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denominator
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


def _readme_results_rows() -> list[tuple[str, str]]:
    """(success cell, report link) of every row of README.md's results table."""
    section = _section((ROOT / "README.md").read_text(), "## Results")
    (table,) = [t for t in _tables(section) if "unseen success" in t[0]]
    header = table[0]
    success, report = header.index("unseen success"), header.index("report")
    return [(row[success], row[report]) for row in table[1:]]


def test_readme_is_under_1500_words():
    words = len((ROOT / "README.md").read_text().split())
    assert words < 1500, f"README.md has {words} words: move detail to docs/guide.md"


def test_readme_results_table_quotes_its_reports():
    rows = _readme_results_rows()
    assert len(rows) >= 3
    tasks = set()
    for success_cell, report_cell in rows:
        (target,) = LINK.findall(report_cell)
        path = ROOT / target
        rate, episodes = _report(path)
        (quoted,) = NUMBER.findall(success_cell)
        assert quoted == f"{rate:.3f}", f"README.md quotes {quoted} for {target}: it says {rate:.3f}"
        # The table's header promises the 200 fixed unseen episodes.
        assert episodes == 200, target
        tasks.add(json.loads(path.read_text())["task"])
    assert tasks == {"push", "push_turn", "full6d"}


def test_readme_results_table_quotes_the_at_rest_figure_of_the_same_policy():
    """Each row's at-rest cell: its linked report's success under the at-rest rule, the same
    policy and task as the row's report, 200 episodes; or 0.000 where the row's report has no
    success at all (nothing to hold still)."""
    section = _section((ROOT / "README.md").read_text(), "## Results")
    (table,) = [t for t in _tables(section) if "unseen success" in t[0]]
    header = table[0]
    at_rest, report = header.index("at rest"), header.index("report")
    for row in table[1:]:
        (quoted,) = NUMBER.findall(row[at_rest])
        (main_target,) = LINK.findall(row[report])
        main = json.loads((ROOT / main_target).read_text())
        links = LINK.findall(row[at_rest])
        if not links:
            assert quoted == "0.000" and main["success_rate"] == 0, row
            continue
        (target,) = links
        rested = json.loads((ROOT / target).read_text())
        assert quoted == f"{rested['success_rate']:.3f}", (target, quoted)
        assert len(rested["episodes"]) == 200 and rested["task"] == main["task"], target
        # The same policy: the same run, or the shipped folder whose card quotes the row's report.
        card = ROOT / rested["run"] / "card.json"
        shipped_from = json.loads(card.read_text()) if card.is_file() else {}
        assert rested["run"] == main["run"] or shipped_from.get("report") == main_target or \
            shipped_from.get("source_run") == main["run"], target
        changed = {o["key"]: o["new"] for o in rested.get("overrides", [])}
        assert changed.get("primitive.success_at_rest") is True, target
        assert rested["success_rate"] <= main["success_rate"] + 0.05, target


def _results_page_rows():
    """(row, [report paths], success cell, interval cell) of docs/results/README.md's task
    tables: the rows naming exactly the reports their figures come from (a brace pattern such
    as `seed{1..4}` names several and is left out)."""
    text = (RESULTS / "README.md").read_text()
    for table in _tables(text):
        header = table[0]
        if "success" not in header or "report" not in header:
            continue
        success, interval, report = (header.index("success"), header.index("95 % interval"),
                                     header.index("report"))
        for row in table[1:]:
            names = re.findall(r"`([^`]+\.json)`", row[report])
            if not names or any("{" in name for name in names):
                continue
            yield row, [RESULTS / name for name in names], row[success], row[interval]


def test_results_page_quotes_its_reports_with_wilson_intervals():
    checked = 0
    for row, paths, success_cell, interval_cell in _results_page_rows():
        quoted = NUMBER.findall(success_cell)
        assert len(quoted) == len(paths), row
        intervals = INTERVAL.findall(interval_cell)
        assert len(intervals) == len(paths), row
        for path, figure, (low, high) in zip(paths, quoted, intervals):
            rate, episodes = _report(path)
            assert figure == f"{rate:.3f}", f"{path.name}: quoted {figure}, report {rate:.3f}"
            wilson = _wilson(round(rate * episodes), episodes)
            assert (low, high) == (f"{wilson[0]:.3f}", f"{wilson[1]:.3f}"), (path.name, wilson)
            checked += 1
    assert checked >= 25


def _slug(heading: str) -> str:
    """GitHub's anchor for a markdown heading."""
    text = heading.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


@pytest.mark.parametrize("page", LINKED_PAGES)
def test_every_relative_link_resolves(page):
    source = ROOT / page
    text = source.read_text()
    # Links inside code blocks are code, not links.
    prose = "".join(text.split("```")[0::2])
    for target in LINK.findall(prose):
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        path_part, _, anchor = target.partition("#")
        resolved = (source.parent / path_part).resolve() if path_part else source
        assert resolved.exists(), f"{page}: link to {target} does not resolve"
        if anchor and resolved.suffix == ".md":
            headings = [line.lstrip("#") for line in resolved.read_text().splitlines()
                        if line.startswith("#")]
            assert anchor in {_slug(h) for h in headings}, f"{page}: no heading #{anchor} in {path_part}"


DEMO_LINE = re.compile(r"from \*\*(\d\.\d\d)\*\* untrained to \*\*(\d\.\d\d)\*\* after ([\d,]+) "
                       r"primitives")


@pytest.mark.parametrize("page", ["README.md", "docs/results/README.md"])
def test_the_demo_numbers_quote_its_summary(page):
    """What a page says `make demo` printed is its recorded summary (docs/results/demo/)."""
    summary = json.loads((RESULTS / "demo" / "demo_summary.json").read_text())
    quoted = DEMO_LINE.findall((ROOT / page).read_text())
    assert quoted, f"{page} quotes no demo result"
    for untrained, trained, primitives in quoted:
        assert float(untrained) == round(summary["success"]["untrained"], 2)
        assert float(trained) == round(summary["success"]["trained"], 2)
        assert int(primitives.replace(",", "")) == summary["train_primitives"]
