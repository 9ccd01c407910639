"""``phantomtouch calibrate``: measure each actuator with an accelerometer and write a
corrected device profile (``docs/accuracy.md``, Calibration); ``--simulate`` calibrates the digital
twin instead of a sound card.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable

from phantomtouch.commands.device_arg import load_device


def add_calibrate_command(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``phantomtouch calibrate``."""
    calibrate = sub.add_parser(
        "calibrate", help="measure each actuator with an accelerometer, write a corrected profile"
    )
    calibrate.add_argument("-o", "--output", required=True, help="profile to write (.toml/.json)")
    calibrate.add_argument("--device", help="profile to start from (default: the paper's)")
    calibrate.add_argument("--channels", type=int, nargs="+", help="only these output channels")
    calibrate.add_argument("--output-device", help="sound-card output (index or name)")
    calibrate.add_argument("--input-device", help="sound-card input (index or name)")
    calibrate.add_argument(
        "--input-channel", type=int, default=1, help="input the accelerometer is on (1-based)"
    )
    calibrate.add_argument(
        "--sensitivity-v-per-m-s2", type=float, help="accelerometer sensitivity, V per m/s²"
    )
    calibrate.add_argument(
        "--input-full-scale-v", type=float, help="volts that read as digital full scale"
    )
    calibrate.add_argument(
        "--input-reference-db",
        type=float,
        help="instead of the two above: level, dB re 1 µm/s², of a full-scale sine at the input",
    )
    calibrate.add_argument("--excitation-s", type=float, default=8.0, help="noise per channel, s")
    calibrate.add_argument(
        "--drive-rms", type=float, default=0.1, help="RMS of the excitation (full scale = 1)"
    )
    calibrate.add_argument(
        "--taps",
        type=int,
        default=4096,
        help="FIR taps per channel (fewer: less exact below 60 Hz)",
    )
    calibrate.add_argument("--yes", action="store_true", help="do not wait for Enter per channel")
    calibrate.add_argument("--json", action="store_true", help="print the results as JSON")
    calibrate.add_argument(
        "--simulate",
        action="store_true",
        help="calibrate the digital twin (actuators with random resonances) instead of a card",
    )
    calibrate.add_argument("--seed", type=int, default=0, help="seed of --simulate")
    calibrate.set_defaults(func=_cmd_calibrate)


def _sound_device(name: str | None) -> int | str | None:
    return int(name) if name is not None and name.isdigit() else name


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from phantomtouch.analysis import calibration as cal
    from phantomtouch.analysis.sound_input import input_scale, sounddevice_loop

    device = load_device(args.device)
    settings = cal.CalibrationSettings(
        excitation_s=args.excitation_s, drive_rms=args.drive_rms, taps=args.taps
    )
    scale_given = args.input_reference_db is not None or args.sensitivity_v_per_m_s2 is not None
    play_record: cal.PlayRecord
    before: Callable[[int], None]
    if args.simulate:
        from phantomtouch.analysis.twin import simulated_loop

        reference = args.input_reference_db
        if not scale_given:
            reference = device.calibration.reference_level_db + 10.0
        scale = input_scale(
            sensitivity_v_per_m_s2=args.sensitivity_v_per_m_s2,
            input_full_scale_v=args.input_full_scale_v,
            input_reference_level_db=reference,
        )
        loop = simulated_loop(device, input_scale_m_s2=scale, seed=args.seed)
        play_record = loop
        total = len(args.channels or device.actuators)
        done = [0]

        def before(channel: int) -> None:
            # every channel is measured, then every channel is verified
            step = "measuring" if done[0] < total else "verifying"
            print(
                f"calibrate: {step} channel {channel} ({done[0] % total + 1} of {total})",
                file=sys.stderr,
            )
            done[0] += 1
            loop.place_sensor(channel)

    else:
        scale = input_scale(
            sensitivity_v_per_m_s2=args.sensitivity_v_per_m_s2,
            input_full_scale_v=args.input_full_scale_v,
            input_reference_level_db=args.input_reference_db,
        )
        play_record = sounddevice_loop(
            sample_rate_hz=device.sample_rate_hz,
            output_device=_sound_device(args.output_device),
            input_device=_sound_device(args.input_device),
            input_channel=args.input_channel,
        )

        def before(channel: int) -> None:
            if not args.yes:
                print(
                    f"Put the accelerometer on actuator {channel} and press Enter.",
                    file=sys.stderr,
                )
                sys.stdin.readline()

    result = cal.calibrate(
        device,
        play_record,
        input_scale_m_s2=scale,
        channels=args.channels,
        settings=settings,
        before_channel=before,
    )
    from phantomtouch.analysis.profile_file import write_profile

    write_profile(result.profile, args.output)
    if args.json:
        print(json.dumps({**result.to_dict(), "output": str(args.output)}, indent=2))
        return 0
    freqs = [f"{f:g} Hz" for f in cal.VERIFY_FREQS_HZ]
    print(
        f"{'ch':>2}  {'level dB':>8}  {'spread dB':>9}  {'coherence':>9}  {'FIR max dB':>10}  "
        f"{'max level dB':>12}  " + "  ".join(f"{f:>7}" for f in freqs) + "  band err"
    )
    checks = {c.channel: c for c in result.checks}
    for m in result.measurements:
        check = checks[m.channel]
        errors = "  ".join(f"{e:+7.2f}" for e in check.sine_errors_db.values())
        print(
            f"{m.channel:>2}  {m.level_db:8.2f}  {m.spread_db:9.2f}  {m.coherence_min:9.3f}  "
            f"{m.fir_max_gain_db:10.2f}  {m.max_level_db:12.1f}  {errors}  "
            f"{check.band_error_db:+8.2f}"
        )
    worst = max((c.worst_db for c in result.checks), default=0.0)
    print(
        f"level: full-scale sine at {settings.reference_hz:g} Hz, dB re 1 µm/s²; errors: "
        f"measured minus requested after calibration (worst {worst:.2f} dB)"
    )
    weakest = min(result.measurements, key=lambda m: m.max_level_db)
    if weakest.max_level_db < device.safety.max_level_db:
        print(
            f"note: channel {weakest.channel} reaches only {weakest.max_level_db:.1f} dB "
            f"somewhere in {cal.BAND_HZ[0]:g}-{cal.BAND_HZ[1]:g} Hz before its drive hits the "
            f"ceiling (max level column); safety.max_level_db is {device.safety.max_level_db:g}"
        )
    print(f"calibrated profile written to {args.output}")
    return 0
