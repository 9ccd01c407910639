"""Pure numpy DSP: pattern + device -> samples. No threads, no I/O, no clocks."""

from phantomtouch.renderer.gains import apply_law, gains_at, gains_for_points
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.renderer.output import OutputStage
from phantomtouch.renderer.plan import Plan, plan
from phantomtouch.renderer.presets import preset, preset_names
from phantomtouch.renderer.render import plan_at, render, render_blocks, render_plan_blocks
from phantomtouch.renderer.voice import PatternRenderer

__all__ = [
    "Geometry",
    "OutputStage",
    "PatternRenderer",
    "Plan",
    "apply_law",
    "gains_at",
    "gains_for_points",
    "plan",
    "plan_at",
    "preset",
    "preset_names",
    "render",
    "render_blocks",
    "render_plan_blocks",
]
