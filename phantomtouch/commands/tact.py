"""``phantomtouch render FILE.tact``: a bHaptics Designer project to an 8-channel WAV.

``phantomtouch render Stab_ArmL.tact -o stab.wav [--bhaptics-map arm.toml]
[--scale-intensity 0.5] [--scale-duration 2]`` reads the project
(:func:`~phantomtouch.clips.tact.load_tact`), turns it into voices as the bHaptics stand-in
does (:func:`~phantomtouch.clips.tact_score.score`, the arm map of docs/bhaptics.md) and
mixes them offline (:func:`~phantomtouch.renderer.score.render_timed`): the file holds the
samples the stand-in plays for the same key. A project with nothing for the arms the map
plays is refused in one line (exit 2).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import soundfile

from phantomtouch.commands.device_arg import load_device
from phantomtouch.errors import ParameterError, PhantomTouchError


def is_tact(path: str | None) -> bool:
    """The file is a ``.tact`` project (told by its suffix)."""
    return path is not None and Path(path).suffix.lower() == ".tact"


def add_tact_render_arguments(render: argparse.ArgumentParser) -> None:
    """The options ``phantomtouch render`` takes for a ``.tact`` file."""
    render.add_argument(
        "--bhaptics-map", help="arm map (TOML) for a .tact file; default: both arms, whole band"
    )
    render.add_argument(
        "--scale-intensity", type=float, default=1.0, help="a .tact file's intensity factor"
    )
    render.add_argument(
        "--scale-duration", type=float, default=1.0, help="a .tact file's time stretch factor"
    )


def render_tact(args: argparse.Namespace) -> int:
    """Render ``args.pattern`` (a ``.tact`` file) to ``args.output``; the exit status."""
    from phantomtouch.clips.tact import ARM_POSITIONS, load_tact
    from phantomtouch.clips.tact_map import ArmMap
    from phantomtouch.clips.tact_score import ScaleOption, score
    from phantomtouch.renderer.output import frames_at_ceiling
    from phantomtouch.renderer.score import render_timed

    if args.preset is not None or args.plot is not None:
        raise ParameterError("a .tact file renders alone: --preset and --plot do not apply")
    path = Path(args.pattern)
    project = load_tact(path)
    arm_map = ArmMap.load(args.bhaptics_map) if args.bhaptics_map else ArmMap()
    device = load_device(args.device)
    scale = ScaleOption(args.scale_intensity, args.scale_duration)
    played = score(project, arm_map, device, scale)
    if not played.voices:
        found = sorted(project.positions()) or ["none"]
        raise ParameterError(
            f"{path.name}: no arm content for this band: it plays on {', '.join(found)}; the "
            f"band plays {', '.join(a for a in ARM_POSITIONS if a in arm_map.arms)}"
        )
    samples = render_timed(
        played.voices, device, sample_rate_hz=args.sample_rate, duration_s=played.duration_s
    )
    rate = args.sample_rate or device.sample_rate_hz
    try:
        soundfile.write(str(args.output), samples, rate, subtype="FLOAT")
    except (soundfile.LibsndfileError, OSError) as exc:
        raise PhantomTouchError(f"output={str(args.output)!r}: cannot write it ({exc})") from exc
    summary = {
        "output": str(args.output),
        "duration_s": len(samples) / rate,
        "frames": len(samples),
        "channels": samples.shape[1],
        "voices": len(played.voices),
        "clipped_fraction": frames_at_ceiling(samples, device.safety.ceiling)
        / max(1, len(samples)),
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"{args.output}: {summary['duration_s']:.3f} s, {len(samples)} frames x "
            f"{samples.shape[1]} channels at {rate} Hz; {len(played.voices)} voices from "
            f"{path.name}"
        )
    return 0
