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
