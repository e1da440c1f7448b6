"""User-facing errors.

Every problem a user can cause (bad scene file, impossible setting, missing
file) raises :class:`StpmError` with one clear line naming the problem.  The
CLI prints that line to stderr and exits non-zero; the Blender add-on reports
it in the UI.  Anything else escaping is a bug in STPM.
"""
from __future__ import annotations


class StpmError(Exception):
    """A problem with the user's input, explained in one line."""


class SceneError(StpmError):
    """The scene (file or exported data) is malformed: names the first bad field."""


class SettingsError(StpmError):
    """A render setting is out of range or unknown."""


class RenderCancelled(StpmError):
    """The user (or Blender's ``test_break``) cancelled the render."""
