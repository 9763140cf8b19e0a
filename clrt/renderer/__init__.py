"""Stages 4-6 of the pipeline: frames of a scene uploaded to one device.

``frame.py`` (the Renderer: upload once, render many frames), ``tiles.py``
(how a frame is cut into launches, the out-of-memory fallback, Ctrl-C),
and page-locked images from ``clrt/device/pinned.py`` (never reused while a caller holds them).
"""

from clrt.renderer.frame import Frame, Renderer, check_host_memory, render
from clrt.renderer.tiles import TileLimits

__all__ = ["Frame", "Renderer", "TileLimits", "check_host_memory", "render"]
