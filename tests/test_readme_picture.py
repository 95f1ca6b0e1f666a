"""The README's first picture shows what a success is (issue 64): a gallery episode that ended
with the object at rest on its goal, as that gallery's own gallery.json records it, not one that
tumbled through the goal and was counted at the instant it passed."""

from __future__ import annotations

import json
import re

from tests.paths import REPO_ROOT


def test_the_readmes_first_picture_is_a_success_ending_at_rest():
    readme = (REPO_ROOT / "README.md").read_text()
    first = re.search(r"!\[[^\]]*\]\((docs/gallery/[^)]+\.gif)\)", readme)
    assert first, "the README shows no gallery animation"
    gif = REPO_ROOT / first.group(1)
    assert gif.is_file() and gif.read_bytes()[:6] in (b"GIF87a", b"GIF89a")
    gallery = json.loads((gif.parent / "gallery.json").read_text())
    [entry] = [e for e in gallery["episodes"] if e.get("animation") == gif.name]
    assert entry["success"] and entry["ended_at_rest"] is True, entry
    # The command under the picture is the one that made it (its objects and settings).
    for change in gallery["overrides"]:
        assert f"--set {change['key']}={str(change['new']).lower()}" in " ".join(readme.split())
    assert entry["object"] in readme
