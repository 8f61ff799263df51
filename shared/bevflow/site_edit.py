"""Changing one camera's fields in a site file without disturbing the rest of it.

A site file is written by hand and annotated with comments; calibration must update K, D or the
pose of one camera and leave everything else as the technician wrote it. YAML is edited as text:
PyYAML's node tree gives the exact span of every key and value, and only the spans of the changed
values are rewritten (in flow style, ``{fx: 634.3, ...}``). Comments, blank lines, key order, the
other cameras and the rest of the file stay byte for byte. Comments *inside* a block value that is
replaced (say, between the lines of a ``pose:`` block) go with it.

Every edit is checked by loading the result: it must hold exactly the old data with the changes.
Where the text edit cannot guarantee that (anchors, unusual layouts), the whole file is written
again from the data and ``EditResult.comments_kept`` is False. JSON has no comments; a JSON site
is written again with the same key order.

>>> text = '''cameras:
...   - id: gate   # over the main door
...     image_size: [1280, 1280]
...     intrinsics: {fx: 400.0, fy: 400.0, cx: 640.0, cy: 640.0}
...     pose: {position: [0.0, 0.0, 3.3]}
... '''
>>> new = {"intrinsics": {"fx": 412.5, "fy": 411.0, "cx": 641.2, "cy": 638.9}}
>>> print(update_camera_text(text, "gate", new).text, end="")
cameras:
  - id: gate   # over the main door
    image_size: [1280, 1280]
    intrinsics: {fx: 412.5, fy: 411.0, cx: 641.2, cy: 638.9}
    pose: {position: [0.0, 0.0, 3.3]}
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import yaml

from bevflow.site import SiteError, parse_site

Changes = Mapping[str, Any]
"""Camera fields to set (any JSON-like value) or, with the value None, to remove."""


@dataclass(frozen=True)
class EditResult:
    text: str
    comments_kept: bool


def update_camera_file(path: str | Path, camera_id: str, changes: Changes, backup: bool = True) -> EditResult:
    """Apply ``changes`` to camera ``camera_id`` of the site file at ``path`` and save it (atomically;
    the previous version is kept as ``<name>.bak`` when ``backup``). The result must still be a
    valid site, or ``SiteError`` is raised and the file is left alone."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SiteError(f"{path}: cannot read the site file ({exc.strerror or exc})") from None
    fmt: Literal["yaml", "json"] = "json" if path.suffix.lower() == ".json" else "yaml"
    result = update_camera_text(text, camera_id, changes, fmt=fmt, source=str(path))
    try:
        if backup:
            path.with_name(path.name + ".bak").write_text(text, encoding="utf-8")
        _write_atomically(path, result.text)
    except OSError as exc:
        raise SiteError(f"{path}: cannot write the site file ({exc.strerror or exc})") from None
    return result


def update_camera_text(
    text: str, camera_id: str, changes: Changes, fmt: Literal["yaml", "json"] = "yaml", source: str = "<site>"
) -> EditResult:
    """The site text with ``changes`` applied to camera ``camera_id``; see the module notes."""
    parse_site(text, source=source, fmt=fmt)  # the file must be valid to begin with
    raw = json.loads(text) if fmt == "json" else yaml.safe_load(text)
    expected = _changed(raw, camera_id, changes, source)
    parse_site(json.dumps(expected), source=f"{source} (after the change)", fmt="json")
    if fmt == "json":
        return EditResult(json.dumps(expected, indent=2, ensure_ascii=False) + "\n", comments_kept=True)
    try:
        edited = _edit_yaml(text, camera_id, changes)
        if yaml.safe_load(edited) == expected:
            return EditResult(edited, comments_kept=True)
    except (_CannotEdit, yaml.YAMLError):
        pass
    return EditResult(yaml.safe_dump(expected, sort_keys=False, allow_unicode=True), comments_kept=False)


def _changed(raw: dict[str, Any], camera_id: str, changes: Changes, source: str) -> dict[str, Any]:
    cameras = [dict(c) for c in raw["cameras"]]
    for camera in cameras:
        if camera.get("id") == camera_id:
            for key, value in changes.items():
                if value is None:
                    camera.pop(key, None)
                else:
                    camera[key] = _plain(value)
            break
    else:
        known = ", ".join(str(c.get("id")) for c in cameras)
        raise SiteError(f"{source}: no camera {camera_id!r}; its cameras are {known}")
    return {**raw, "cameras": cameras}


def _plain(value: Any) -> Any:
    """Tuples and numpy scalars as the YAML loader gives them back (lists, floats)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item"):  # numpy scalar
        return value.item()
    return value


# --- YAML text edits ------------------------------------------------------------------------------
class _CannotEdit(Exception):
    """This layout is not edited in place; the caller writes the file again instead."""


def _edit_yaml(text: str, camera_id: str, changes: Changes) -> str:
    camera = _camera_node(yaml.compose(text), camera_id)
    if camera.flow_style:
        raise _CannotEdit("a camera written as one flow mapping")
    pairs = list(camera.value)
    present = {key.value: (key, value) for key, value in pairs}
    edits: list[tuple[int, int, str]] = []  # (start, end, replacement), applied back to front
    removed = [present[k] for k, v in changes.items() if v is None and k in present]
    added = [(k, v) for k, v in changes.items() if v is not None and k not in present]
    for key, value in changes.items():
        if value is not None and key in present:
            edits.append(_replace_value(text, *present[key], value))
    # A new key takes the place of a removed one (extrinsics for pose), else goes after the last.
    while added and removed:
        (name, value), (old_key, old_value) = added.pop(0), removed.pop(0)
        edits.append((old_key.start_mark.index, _node_end(old_value), f"{name}: {_flow(value)}"))
    for old_key, old_value in removed:
        edits.append(_remove_pair(text, old_key, old_value))
    if added:
        indent = " " * pairs[0][0].start_mark.column
        at = _line_end(text, _node_end(pairs[-1][1]))
        edits.append((at, at, "".join(f"\n{indent}{name}: {_flow(value)}" for name, value in added)))
    for start, end, replacement in sorted(edits, reverse=True):
        text = text[:start] + replacement + text[end:]
    return text


def _camera_node(root: yaml.Node | None, camera_id: str) -> yaml.MappingNode:
    if not isinstance(root, yaml.MappingNode):
        raise _CannotEdit("no top-level mapping")
    for key, value in root.value:
        if key.value == "cameras" and isinstance(value, yaml.SequenceNode):
            for item in value.value:
                if isinstance(item, yaml.MappingNode) and any(
                    k.value == "id" and isinstance(v, yaml.ScalarNode) and v.value == camera_id for k, v in item.value
                ):
                    return item
    raise _CannotEdit(f"camera {camera_id!r} not found as written")


def _replace_value(text: str, key: yaml.Node, value: yaml.Node, new: Any) -> tuple[int, int, str]:
    if _is_block(value):
        # A block value starts on the next line; the flow replacement goes right after the colon.
        colon = text.index(":", key.end_mark.index)
        return colon + 1, _node_end(value), " " + _flow(new)
    return value.start_mark.index, value.end_mark.index, _flow(new)


def _remove_pair(text: str, key: yaml.Node, value: yaml.Node) -> tuple[int, int, str]:
    start = text.rfind("\n", 0, key.start_mark.index) + 1
    if text[start : key.start_mark.index].strip():
        raise _CannotEdit("the key shares its line with something else (a list dash)")
    end = _line_end(text, _node_end(value))
    return start, min(end + 1, len(text)), ""


def _is_block(node: yaml.Node) -> bool:
    return isinstance(node, (yaml.MappingNode, yaml.SequenceNode)) and not node.flow_style


def _node_end(node: yaml.Node) -> int:
    """Where a node's own text ends. A block collection's end mark lies after the comments and
    blank lines that follow it, so its last child decides."""
    if _is_block(node):
        last = node.value[-1]
        return _node_end(last[1] if isinstance(last, tuple) else last)
    if isinstance(node, yaml.ScalarNode) and node.style in ("|", ">"):
        raise _CannotEdit("block scalars are not edited in place")
    return node.end_mark.index


def _line_end(text: str, index: int) -> int:
    end = text.find("\n", index)
    return len(text) if end < 0 else end


def _flow(value: Any) -> str:
    """``value`` as YAML flow text that loads back to the same data."""
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{_flow(str(k))}: {_flow(v)}" for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_flow(v) for v in value) + "]"
    if hasattr(value, "item"):
        value = value.item()
    if value is None or isinstance(value, bool):
        return {None: "null", True: "true", False: "false"}[value]
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return _yaml_float(value)
    text = str(value)
    plain = yaml.safe_dump(text, default_flow_style=True).removesuffix("\n...\n").strip()
    return plain if yaml.safe_load(plain) == text else json.dumps(text)


def _yaml_float(x: float) -> str:
    """Shortest round-tripping text that YAML 1.1 reads as a float: it needs a '.' in the mantissa
    (PyYAML reads '1e-05' as a string)."""
    if not math.isfinite(x):
        raise ValueError(f"a site file cannot hold {x}")
    text = repr(float(x))
    mantissa, _, exponent = text.partition("e")
    if "." not in mantissa:
        mantissa += ".0"
    return mantissa + (f"e{exponent}" if exponent else "")


def _write_atomically(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as out:
            out.write(text)
        if path.exists():
            os.chmod(tmp, path.stat().st_mode & 0o7777)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
