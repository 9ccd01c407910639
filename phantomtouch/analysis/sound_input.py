"""The sound-card side of a calibration: the measurement loop and the sensor's scale.

:func:`sounddevice_loop` plays a drive signal and records the accelerometer's input
(the ``audio`` extra); :func:`input_scale` turns the sensor's sensitivity and the input's
full scale (or a reference level) into m/s² per unit of input.
"""

from __future__ import annotations

import math

import numpy as np

from phantomtouch.analysis.calibration import PlayRecord
from phantomtouch.analysis.twin import amplitude_m_s2
from phantomtouch.errors import DeviceError, ParameterError, install_hint
from phantomtouch.output.devices import sounddevice_module


def input_scale(
    *,
    sensitivity_v_per_m_s2: float | None = None,
    input_full_scale_v: float | None = None,
    input_reference_level_db: float | None = None,
) -> float:
    """m/s² per unit of input from the sensor's sensitivity and the input's full scale
    (both given), or from the level of a full-scale sine at the input (dB re 1 µm/s²)."""
    if input_reference_level_db is not None:
        if sensitivity_v_per_m_s2 is not None or input_full_scale_v is not None:
            raise ParameterError(
                "give input_reference_level_db, or sensitivity_v_per_m_s2 with "
                "input_full_scale_v, not both"
            )
        return amplitude_m_s2(input_reference_level_db)
    if sensitivity_v_per_m_s2 is None or input_full_scale_v is None:
        raise ParameterError(
            "give sensitivity_v_per_m_s2 and input_full_scale_v, or input_reference_level_db"
        )
    for name, value in (
        ("sensitivity_v_per_m_s2", sensitivity_v_per_m_s2),
        ("input_full_scale_v", input_full_scale_v),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise ParameterError(f"{name}={value!r} must be finite and > 0")
    return input_full_scale_v / sensitivity_v_per_m_s2


def sounddevice_loop(
    *,
    sample_rate_hz: int,
    output_device: int | str | None,
    input_device: int | str | None,
    input_channel: int,
) -> PlayRecord:
    """A :data:`PlayRecord` through the sound card (needs the ``audio`` extra).

    Raises
    ------
    DeviceError
        sounddevice (or PortAudio) is missing, or the sound card refuses.
    """
    try:
        sd = sounddevice_module()  # PortAudio open, though a serve in this process closed it
    except DeviceError as exc:
        raise DeviceError(
            f"calibrate needs sounddevice and PortAudio, the audio extra: {install_hint('audio')} "
            f"({exc})"
        ) from exc
    if input_channel < 1:
        raise ParameterError(f"input_channel={input_channel!r} must be >= 1")

    def play_record(drive: np.ndarray) -> np.ndarray:
        try:
            recorded = sd.playrec(
                np.ascontiguousarray(drive, dtype=np.float32),
                samplerate=sample_rate_hz,
                input_mapping=[input_channel],
                device=(input_device, output_device),
                dtype="float32",
                blocking=True,
            )
        except (sd.PortAudioError, ValueError) as exc:
            raise DeviceError(f"sound card: {exc}") from exc
        return np.asarray(recorded[:, 0], dtype=np.float64)

    return play_record
