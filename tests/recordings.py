"""Reading a Meshcat StaticHtml recording back: the commands it replays, and the attention
clouds (viz/attention_view.py) in it."""

import base64
import re

import msgpack  # installed with ray, a dependency of the project


def meshcat_messages(html: str) -> list[dict]:
    """The Meshcat commands a StaticHtml recording replays (msgpack, base64 in data URLs)."""
    return [msgpack.unpackb(base64.b64decode(blob), raw=False, strict_map_key=False)
            for blob in re.findall(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)", html)]


def attention_in_recording(html: str):
    """({step path: its set_object message}, {step path: [(frame, visible), ...]})."""
    objects, tracks = {}, {}
    for msg in meshcat_messages(html):
        if msg["type"] == "set_object" and msg["path"].startswith("/attention/"):
            objects[msg["path"]] = msg
        if msg["type"] == "set_animation":
            for anim in msg["animations"]:
                if anim["path"].startswith("/attention/"):
                    (track,) = anim["clip"]["tracks"]
                    assert (track["name"], track["type"]) == (".visible", "boolean")
                    tracks[anim["path"]] = [(k["time"], k["value"]) for k in track["keys"]]
    return objects, tracks


# --- the recording in a real browser (Debian's Chromium, headless; `make test` installs it) -----
# The flags a headless Chromium needs on a machine with no network and no GPU: no sandbox (the
# tests may run as root), software WebGL, and none of the background connections that a closed
# network refuses.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update",
                  "--disable-sync", "--window-size=800,600")
# Virtual time the page gets: Meshcat fetches each recorded command from a data URL, then the
# probe below reads the scene (virtual time runs as fast as the page allows).
PAGE_MS = 8000

# Appended to a copy of the recording: once the commands are in, it lists every drawable of the
# three.js scene Meshcat built (its path, kind, vertex count, whether it and its parents are
# visible) and what the renderer drew, into a <pre> that --dump-dom prints.
_PROBE = """
<script>
setTimeout(function () {
  const found = [];
  viewer.scene.traverse(function (o) {
    if (!(o.isMesh || o.isLine || o.isPoints)) return;
    const names = []; let n = o; let shown = true;
    while (n) { names.unshift(n.name); shown = shown && n.visible; n = n.parent; }
    const position = o.geometry && o.geometry.attributes && o.geometry.attributes.position;
    found.push({path: names.join('/'), kind: o.type, shown: shown,
                vertices: position ? position.count : 0});
  });
  viewer.render();
  const pre = document.createElement('pre');
  pre.id = 'corn-probe';
  pre.textContent = JSON.stringify({objects: found,
                                    drawn: viewer.renderer.info.render.triangles});
  document.body.appendChild(pre);
}, %d);
</script>
"""


def chromium() -> str | None:
    import shutil

    return shutil.which("chromium") or shutil.which("chromium-browser")


def _chromium(*args: str, profile) -> str:
    import subprocess

    out = subprocess.run([chromium(), *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                          f"--virtual-time-budget={PAGE_MS}", *args],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def scene_in_browser(recording, tmp_path) -> dict:
    """What Chromium's Meshcat built of `recording`: {"objects": [{path, kind, shown,
    vertices}], "drawn": triangles the last render drew}."""
    import json

    page = tmp_path / "probed.html"
    html = recording.read_text()
    page.write_text(html.replace("</body>", (_PROBE % (PAGE_MS // 2)) + "</body>"))
    dom = _chromium("--dump-dom", page.as_uri(), profile=tmp_path / "profile_dom")
    found = re.search(r'<pre id="corn-probe">(.*?)</pre>', dom, re.S)
    assert found, "the probe never ran: the page did not load its scene"
    return json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&")
                      .replace("&lt;", "<").replace("&gt;", ">"))


def screenshot_in_browser(recording, tmp_path):
    """The recording's first view as Chromium draws it: an (H, W, 3) uint8 array."""
    import numpy as np
    from PIL import Image

    png = tmp_path / "shot.png"
    _chromium(f"--screenshot={png}", recording.as_uri(), profile=tmp_path / "profile_shot")
    return np.asarray(Image.open(png).convert("RGB"))
