"""Names and text that go into material files (docs/materials.md#native-materials-and-exports), one rule for every format.

- A material id is written as Mitsuba's ``<bsdf id>`` / ``<ref id>``, the glTF, Blender and
  MaterialX material name, and inside the XML comment that says how to use the file. The id a user
  gives (``--id``, ``bsdf_id=``) is checked (:func:`check_id`: refused with one line); an id made
  from a file or folder name is made safe (:func:`safe_id`).
- Text taken from data (a measurement's name, a model's citation) goes into an XML comment through
  :func:`xml_comment`: no character XML forbids, never ``--`` (XML 1.0 forbids it in a comment).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from .._files import plain_text
from ..errors import UsageError

#: letters, digits and '_', not starting with a digit: a Mitsuba id (which cannot hold '.'), a
#: MaterialX element name, and text that needs no escaping in XML
ID_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def check_id(bsdf_id) -> str:
    """``bsdf_id`` if it is a valid material id (``ID_PATTERN``), else one UsageError line."""
    if isinstance(bsdf_id, str) and ID_PATTERN.fullmatch(bsdf_id):
        return bsdf_id
    raise UsageError(f"material id (--id) {bsdf_id!r}: use letters, digits and '_', not starting with a digit "
                     "(Mitsuba ids cannot hold '.', and the id is written into XML)")


def safe_id(text) -> str:
    """A valid material id made from ``text`` (a file or folder name): every other character '_',
    ``m_`` before a leading digit, ``brdffit`` for nothing."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", str(text)) or "brdffit"
    return out if ID_PATTERN.fullmatch(out) else "m_" + out


def xml_comment(text: str) -> str:
    """``<!-- text -->`` for any ``text``: characters XML forbids replaced (``_files.plain_text``),
    runs of '-' shortened to one (a comment may not hold ``--`` nor end with ``-``)."""
    return "<!-- " + re.sub(r"-{2,}", "-", plain_text(text)) + " -->"


def default_id(path: str | os.PathLike) -> str:
    """The material id of an export to ``path`` when none is given: its file name made safe."""
    return safe_id(Path(path).stem)
