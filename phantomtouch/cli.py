"""The ``phantomtouch`` command line.

``phantomtouch serve``    the touch service: REST and WebSocket API on 127.0.0.1:8000
``phantomtouch render``   one pattern (JSON file or preset) to an 8-channel WAV (+ plot)
``phantomtouch presets``  list the named patterns
``phantomtouch stimuli``  render a whole stimulus set of the paper to a folder

Errors print one line naming the field, the value and the allowed range, and exit 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import soundfile
from pydantic import ValidationError
from tqdm import tqdm

from phantomtouch.errors import PhantomTouchError
from phantomtouch.renderer import plan_at, preset, preset_names, render_plan_blocks
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import DeviceProfile, TouchPattern, describe_validation_error

EXIT_USAGE = 2
_BLOCK_FRAMES = 1 << 15


def _load_device(path: str | None) -> DeviceProfile:
    return DeviceProfile.load(path) if path else DeviceProfile.default()


def _load_pattern(path: str) -> TouchPattern:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise PhantomTouchError(f"cannot read pattern file {path!r}: {exc.strerror}") from exc
    return TouchPattern.model_validate_json(text)


def write_wav(plan: Plan, out_path: str | Path, *, plot_path: str | Path | None = None) -> None:
    """Render a plan block by block into a float32 WAV, and optionally its plot."""
    traces = None
    if plot_path is not None:
        from phantomtouch.plot import TraceEnvelope

        traces = TraceEnvelope(plan.frames, plan.channels)
    with soundfile.SoundFile(
        str(out_path), "w", samplerate=plan.sample_rate_hz, channels=plan.channels, subtype="FLOAT"
    ) as wav:
        for block in render_plan_blocks(plan, block_frames=_BLOCK_FRAMES):
            wav.write(block)
            if traces is not None:
                traces.add(block)
    if traces is not None and plot_path is not None:
        from phantomtouch.plot import save_plot

        save_plot(plan, traces, plot_path)


def _cmd_render(args: argparse.Namespace) -> int:
    if (args.pattern is None) == (args.preset is None):
        raise PhantomTouchError("give a PATTERN.json file or --preset NAME (one of them)")
    pattern = preset(args.preset) if args.preset else _load_pattern(args.pattern)
    plan = plan_at(pattern, _load_device(args.device), sample_rate_hz=args.sample_rate)
    write_wav(plan, args.output, plot_path=args.plot)
    if args.json:
        print(json.dumps({**plan.summary(), "output": str(args.output)}, indent=2))
    else:
        print(
            f"{args.output}: {plan.duration_s:.3f} s, {plan.frames} frames x {plan.channels} "
            f"channels at {plan.sample_rate_hz} Hz; path {plan.path_length_cm:.3f} cm at "
            f"{plan.speed_cm_s:.3f} cm/s"
        )
    return 0


def _cmd_presets(args: argparse.Namespace) -> int:
    names = [n for n in preset_names() if n.startswith(args.prefix or "")]
    if args.json:
        print(json.dumps({n: plan_at(preset(n)).summary() for n in names}, indent=2))
    else:
        for name in names:
            plan = plan_at(preset(name))
            print(f"{name:32} {plan.duration_s:7.3f} s  {plan.speed_cm_s:6.2f} cm/s")
    return 0


def _cmd_stimuli(args: argparse.Namespace) -> int:
    names = [n for n in preset_names() if n.startswith(f"{args.set}/")]
    out_dir = Path(args.output)
    out_dir.mkdir(parents=True, exist_ok=True)
    device = _load_device(args.device)
    manifest = {}
    for name in tqdm(names, desc=f"{args.set} stimuli", unit="stimulus", file=sys.stderr):
        plan = plan_at(preset(name), device)
        file_name = name.split("/", 1)[1] + ".wav"
        write_wav(plan, out_dir / file_name)
        manifest[name] = {"file": file_name, **plan.summary()}
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=2), encoding="utf-8")
    print(f"{len(names)} stimuli in {out_dir}")
    return 0


def _cmd_serve(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from phantomtouch.server import Settings
    from phantomtouch.server.serve import serve

    options = {
        "host": args.host,
        "port": args.port,
        "device_profile": args.device,
        "output_device": args.output,
        "db_path": args.db,
        "token": args.token,
    }
    try:
        settings = Settings(**{k: v for k, v in options.items() if v is not None})
    except ValidationError as exc:
        raise PhantomTouchError(f"invalid settings: {describe_validation_error(exc)}") from exc
    print(f"phantomtouch serve: http://{settings.host}:{settings.port} (API docs at /docs)")
    serve(settings)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="phantomtouch", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    serve = sub.add_parser("serve", help="run the touch service (REST and WebSocket)")
    serve.add_argument("--host", help="address to bind (default 127.0.0.1; others need --token)")
    serve.add_argument("--port", type=int, help="TCP port (default 8000)")
    serve.add_argument("--device", help="device profile (TOML or JSON); default: the paper's")
    serve.add_argument(
        "--output", help="sound-card output name or index, or 'null' (default: first that fits)"
    )
    serve.add_argument("--db", help="pattern library, SQLite file")
    serve.add_argument("--token", help="bearer token every request must carry")
    serve.set_defaults(func=_cmd_serve)

    render = sub.add_parser("render", help="render one pattern to an 8-channel WAV")
    render.add_argument("pattern", nargs="?", help="TouchPattern JSON file")
    render.add_argument("--preset", help="a preset name (see `phantomtouch presets`)")
    render.add_argument("-o", "--output", required=True, help="output WAV file (float32)")
    render.add_argument("--plot", help="also write the Fig. 3 view to this PNG")
    render.add_argument("--json", action="store_true", help="print the plan as JSON")
    render.add_argument("--device", help="device profile (TOML or JSON); default: the paper's")
    render.add_argument("--sample-rate", type=int, help="sample rate in Hz (default: device's)")
    render.set_defaults(func=_cmd_render)

    presets = sub.add_parser("presets", help="list the preset patterns")
    presets.add_argument("prefix", nargs="?", help="only names starting with this, e.g. exp2/")
    presets.add_argument("--json", action="store_true", help="print each preset's plan as JSON")
    presets.set_defaults(func=_cmd_presets)

    stimuli = sub.add_parser("stimuli", help="render a stimulus set of the paper to a folder")
    stimuli.add_argument("set", choices=["exp1", "exp2", "vr"], help="which set")
    stimuli.add_argument("-o", "--output", required=True, help="output folder")
    stimuli.add_argument("--device", help="device profile (TOML or JSON)")
    stimuli.set_defaults(func=_cmd_stimuli)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return func(args)
    except ValidationError as exc:
        print(f"phantomtouch: invalid input: {describe_validation_error(exc)}", file=sys.stderr)
    except (PhantomTouchError, OSError) as exc:
        print(f"phantomtouch: {exc}", file=sys.stderr)
    return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
