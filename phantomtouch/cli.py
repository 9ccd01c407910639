"""The ``phantomtouch`` command line.

``phantomtouch serve``    the touch service: REST and WebSocket API on 127.0.0.1:8000
``phantomtouch osc``      the same with OSC input (VRChat contact receivers) on UDP 9001
``phantomtouch import``   a clip (.haptic, .ahap), .tact project or SDK2 deployment into the library
``phantomtouch render``   one pattern (JSON file, preset or .tact) to an 8-channel WAV
``phantomtouch presets``  list the named patterns
``phantomtouch stimuli``  render a whole stimulus set of the paper to a folder
``phantomtouch devices``  list the sound card outputs (``*``: enough outputs for the armband)
``phantomtouch bench accuracy``  phantom position and level error against CPU time
``phantomtouch calibrate``  measure each actuator, write a corrected device profile
``phantomtouch gateway``  a REST and WebSocket gateway of a fleet of armbands (NATS)
``phantomtouch bhaptics register``  make bHaptics' Windows libraries see the Player (per user)

Errors print one line: bad input (a field, its value and the allowed range; a wrong
argument) exits 2, a failure while running (a file, the sound card, a missing extra)
exits 1.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import soundfile
from pydantic import ValidationError
from tqdm import tqdm

from phantomtouch import __version__
from phantomtouch.commands.bhaptics import add_bhaptics_command, player_argv
from phantomtouch.commands.calibrate import add_calibrate_command
from phantomtouch.commands.device_arg import load_device
from phantomtouch.commands.import_file import add_import_command
from phantomtouch.commands.parser import OneLineParser, check_output_file, make_output_folder
from phantomtouch.commands.serve import EXIT_FAILURE, add_serve_commands
from phantomtouch.commands.tact import add_tact_render_arguments, is_tact, render_tact
from phantomtouch.errors import ParameterError, PhantomTouchError, install_hint
from phantomtouch.renderer import plan_at, preset, preset_names, render_plan_blocks
from phantomtouch.renderer.output import frames_at_ceiling
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import TouchPattern, describe_validation_error, limits

"""The command could not do its work (``serve``: the pattern library cannot be opened)."""
EXIT_USAGE = 2
_BLOCK_FRAMES = 1 << 15
_WAV_HEADER_BYTES = 4096
"""Room for a WAV file's header chunks, bytes (generous: libsndfile writes ~150)."""


def _load_pattern(path: str) -> TouchPattern:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ParameterError(f"cannot read pattern file {path!r}: {exc.strerror}") from exc
    try:
        return TouchPattern.model_validate_json(text)
    except ValidationError as exc:
        raise ParameterError(f"pattern file {path!r}: {describe_validation_error(exc)}") from exc


def write_wav(plan: Plan, out_path: str | Path, *, plot_path: str | Path | None = None) -> float:
    """Render a plan block by block into a float32 WAV, and optionally its plot.

    Returns the fraction of frames with a channel at the safety ceiling.
    """
    clipped = 0
    traces = None
    if plot_path is not None:
        from phantomtouch.plot import TraceEnvelope

        traces = TraceEnvelope(plan.frames, plan.channels)
    try:
        wav = soundfile.SoundFile(
            str(out_path),
            "w",
            samplerate=plan.sample_rate_hz,
            channels=plan.channels,
            subtype="FLOAT",
        )
    except soundfile.LibsndfileError as exc:
        raise PhantomTouchError(
            f"output={str(out_path)!r}: cannot open it for writing ({exc.error_string})"
        ) from exc
    with wav:
        for block in render_plan_blocks(plan, block_frames=_BLOCK_FRAMES):
            wav.write(block)
            clipped += frames_at_ceiling(block, plan.device.safety.ceiling)
            if traces is not None:
                traces.add(block)
    if traces is not None and plot_path is not None:
        from phantomtouch.plot import save_plot

        save_plot(plan, traces, plot_path)
    return clipped / plan.frames


def _check_plot_path(path: str) -> None:
    """Refuse a ``--plot`` file matplotlib cannot write, before anything is rendered."""
    try:
        from matplotlib.backend_bases import FigureCanvasBase
    except ImportError as exc:
        raise PhantomTouchError(
            f"--plot needs matplotlib, the plot extra: {install_hint('plot')}"
        ) from exc
    formats = FigureCanvasBase.get_supported_filetypes()
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in formats:
        raise ParameterError(
            f"--plot {path!r}: the file name must end in an image format "
            f"({', '.join('.' + f for f in sorted(formats))}), e.g. .png"
        )
    if not Path(path).parent.is_dir():
        raise ParameterError(f"--plot {path!r}: the folder {str(Path(path).parent)!r} is missing")


def _projection_note(plan: Plan) -> str | None:
    """A sentence on path points moved onto the layout, or None when there were none."""
    if plan.projected_points == 0:
        return None
    return (
        f"{plan.projected_points} path point(s) lay outside the actuator layout and were "
        f"projected onto it (up to {plan.max_projection_cm:.2f} cm); "
        '"outside": "error" refuses such a pattern instead'
    )


def _with_library_clip(pattern: TouchPattern, db: str | None) -> TouchPattern:
    """``pattern`` with its clip carrier's clip read from the library ``db`` (the service's
    default library without it), unless the carrier holds the clip itself."""
    from phantomtouch.schema import ClipCarrier

    carrier = pattern.carrier
    if not isinstance(carrier, ClipCarrier) or carrier.data is not None or carrier.clip is None:
        return pattern
    from phantomtouch.service.settings import default_db_path
    from phantomtouch.service.store import PatternStore

    path = Path(db) if db is not None else default_db_path()
    if not path.is_file():
        raise ParameterError(
            f"carrier.clip={carrier.clip!r}: no clip library at {str(path)!r}; name one with "
            "--db FILE, or give the clip itself in carrier.data (phantomtouch import -o)"
        )
    store = PatternStore.open(path)
    try:
        clip = store.get_clip(carrier.clip)
    finally:
        store.close()
    if clip is None:
        raise ParameterError(
            f"carrier.clip={carrier.clip!r} is not in the clip library {str(path)!r} "
            "(phantomtouch import adds one)"
        )
    return pattern.model_copy(update={"carrier": carrier.model_copy(update={"data": clip})})


def _cmd_render(args: argparse.Namespace) -> int:
    if is_tact(args.pattern):
        return render_tact(args)
    if (args.pattern is None) == (args.preset is None):
        raise ParameterError("give a PATTERN.json file or --preset NAME (one of them)")
    if args.plot is not None:
        _check_plot_path(args.plot)
    pattern = preset(args.preset) if args.preset else _load_pattern(args.pattern)
    pattern = _with_library_clip(pattern, args.db)
    plan = plan_at(pattern, load_device(args.device), sample_rate_hz=args.sample_rate)
    check_output_file(args.output, "--output")
    clipped_fraction = write_wav(plan, args.output, plot_path=args.plot)
    if args.json:
        summary = {**plan.summary(), "clipped_fraction": clipped_fraction}
        print(json.dumps({**summary, "output": str(args.output)}, indent=2))
    else:
        print(
            f"{args.output}: {plan.duration_s:.3f} s, {plan.frames} frames x {plan.channels} "
            f"channels at {plan.sample_rate_hz} Hz; path {plan.path_length_cm:.3f} cm at "
            f"{plan.speed_cm_s:.3f} cm/s"
        )
        if clipped_fraction > 0:
            print(
                f"{args.output}: {100 * clipped_fraction:.3g} % of the frames reach the safety "
                f"ceiling {plan.device.safety.ceiling:g} and are clipped: lower the level"
            )
    note = _projection_note(plan)
    if note is not None:
        print(f"phantomtouch: note: {note}", file=sys.stderr)
    return 0


def _cmd_presets(args: argparse.Namespace) -> int:
    names = [n for n in preset_names() if n.startswith(args.prefix or "")]
    if args.json:
        plans = {n: plan_at(preset(n)) for n in names}
        summaries = {
            n: {**p.summary(), "clipped_fraction": p.clipped_fraction} for n, p in plans.items()
        }
        print(json.dumps(summaries, indent=2))
    else:
        for name in names:
            plan = plan_at(preset(name))
            print(f"{name:32} {plan.duration_s:7.3f} s  {plan.speed_cm_s:6.2f} cm/s")
    return 0


def wav_bytes(plan: Plan) -> int:
    """Size of a plan's float32 WAV file, bytes (samples plus room for the header)."""
    return plan.frames * plan.channels * 4 + _WAV_HEADER_BYTES


def _cmd_stimuli(args: argparse.Namespace) -> int:
    from phantomtouch.manifest import row, write_manifest

    names = [n for n in preset_names() if n.startswith(f"{args.set}/")]
    device = load_device(args.device)
    plans = {name: plan_at(preset(name), device) for name in names}
    needed = sum(wav_bytes(plan) for plan in plans.values())
    out_dir = make_output_folder(args.output, "--output")
    free = shutil.disk_usage(out_dir).free
    if needed > free:
        raise ParameterError(
            f"--output {str(out_dir)!r}: {len(names)} stimuli need {needed / 1e6:.0f} MB, "
            f"only {free / 1e6:.0f} MB are free there"
        )
    print(
        f"phantomtouch: rendering {len(names)} stimuli, {needed / 1e6:.0f} MB of WAV files, "
        f"into {out_dir}",
        file=sys.stderr,
    )
    rows = []
    for name in tqdm(names, desc=f"{args.set} stimuli", unit="stimulus", file=sys.stderr):
        plan = plans[name]
        file_name = name.split("/", 1)[1] + ".wav"
        write_wav(plan, out_dir / file_name)
        rows.append(row(name, file_name, preset(name), plan))
    json_path, csv_path = write_manifest(rows, out_dir)
    print(f"{len(names)} stimuli in {out_dir}; factors in {json_path.name} and {csv_path.name}")
    return 0


def _cmd_devices(args: argparse.Namespace) -> int:
    from phantomtouch.output.devices import list_output_devices

    needed = load_device(args.device).channels
    devices = [
        {**d, "enough_outputs": d["max_output_channels"] >= needed} for d in list_output_devices()
    ]
    if args.json:
        print(json.dumps(devices, indent=2))
        return 0
    for d in devices:
        mark = "*" if d["enough_outputs"] else " "
        default = " (default)" if d["default"] else ""
        print(
            f"{mark} {d['index']:3d}  {d['name']}{default}: {d['max_output_channels']} outputs, "
            f"{d['default_samplerate']:g} Hz, {d['hostapi']}"
        )
    if not devices:
        print("no sound card outputs found")
    print(
        f"* = at least {needed} outputs; --output takes an index, a part of a name, or "
        "HOSTAPI:NAME (e.g. 'ASIO:Focusrite', 'WASAPI:Speakers', 'CoreAudio:Aggregate')"
    )
    return 0


def _cmd_bench_accuracy(args: argparse.Namespace) -> int:
    from phantomtouch.analysis.accuracy import default_settings, reference_strokes, run_accuracy
    from phantomtouch.analysis.accuracy_report import format_table, save_plot

    strokes = reference_strokes()
    unknown = sorted(set(args.stroke or ()) - set(strokes))
    if unknown:
        raise ParameterError(f"--stroke {unknown[0]!r} is not one of {sorted(strokes)}")
    if args.stroke:
        strokes = {name: strokes[name] for name in args.stroke}
    top = limits.MAX_GAIN_UPDATE_FRAMES
    if any(not 1 <= n <= top for n in args.frames):
        raise ParameterError(f"--frames {args.frames} must each be within [1, {top}]")
    settings = default_settings(args.frames)
    if args.plot:
        _check_plot_path(args.plot)  # before the run, not after it
    with tqdm(
        total=len(strokes) * (len(settings) + (0 if 1 in args.frames else 1)),
        desc="bench accuracy",
        unit="render",
        file=sys.stderr,
    ) as bar:
        report = run_accuracy(
            strokes,
            settings,
            device=load_device(args.device),
            repeats=args.repeats,
            progress=lambda label: (bar.set_postfix_str(label), bar.update(1)),
        )
    if args.plot:
        save_plot(report, args.plot)
    print(json.dumps(report.to_dict(), indent=2) if args.json else format_table(report))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = OneLineParser(  # its subcommands are OneLineParsers too
        prog="phantomtouch", description=__doc__.splitlines()[0].replace("``", "")
    )
    parser.add_argument("--version", action="version", version=f"phantomtouch {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    add_serve_commands(sub)
    add_import_command(sub)
    add_bhaptics_command(sub)
    add_calibrate_command(sub)

    render = sub.add_parser("render", help="render one pattern to an 8-channel WAV")
    render.add_argument("pattern", nargs="?", help="TouchPattern JSON file, or a .tact file")
    render.add_argument("--preset", help="a preset name (phantomtouch presets lists them)")
    render.add_argument("-o", "--output", required=True, help="output WAV file (float32)")
    render.add_argument("--plot", help="also write the Fig. 3 view to this PNG")
    render.add_argument("--json", action="store_true", help="print the plan as JSON")
    render.add_argument("--device", help="device profile (TOML or JSON); default: the paper's")
    render.add_argument("--sample-rate", type=int, help="sample rate in Hz (default: device's)")
    render.add_argument(
        "--db", help="clip library (SQLite) for a clip carrier named by clip (default: serve's)"
    )
    add_tact_render_arguments(render)
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

    devices = sub.add_parser("devices", help="list sound card outputs")
    devices.add_argument("--json", action="store_true", help="print the list as JSON")
    devices.add_argument("--device", help="device profile whose channels are needed")
    devices.set_defaults(func=_cmd_devices)

    bench = sub.add_parser("bench", help="measure accuracy or speed").add_subparsers(
        dest="bench", required=True
    )
    accuracy = bench.add_parser(
        "accuracy", help="phantom position and level error of gain update settings vs CPU time"
    )
    accuracy.add_argument("--json", action="store_true", help="print the full results as JSON")
    accuracy.add_argument("--plot", help="also write the work-precision plot to this PNG")
    accuracy.add_argument(
        "--frames",
        type=int,
        nargs="+",
        default=[1, 8, 32, 128, 512],
        help="frames between gain updates to compare, each ramped and held (default: %(default)s)",
    )
    accuracy.add_argument("--stroke", action="append", help="only this stroke (repeatable)")
    accuracy.add_argument("--repeats", type=int, default=5, help="timed renders per measurement")
    accuracy.add_argument("--device", help="device profile (TOML or JSON)")
    accuracy.set_defaults(func=_cmd_bench_accuracy)

    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status. Started as the bHaptics Player's
    program (``phantomtouch bhaptics register``), without arguments it serves as the
    Player (:func:`~phantomtouch.commands.bhaptics.player_argv`)."""
    if argv is None:
        argv = player_argv(sys.argv[0], sys.argv[1:])
    args = build_parser().parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        status = func(args)
        sys.stdout.flush()  # a closed pipe shows here, not at exit
        return status
    except BrokenPipeError:  # the reader has gone (`phantomtouch presets | head -1`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except ValidationError as exc:
        print(f"phantomtouch: invalid input: {describe_validation_error(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except ParameterError as exc:
        print(f"phantomtouch: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (PhantomTouchError, OSError) as exc:
        print(f"phantomtouch: {exc}", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
