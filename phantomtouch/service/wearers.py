"""A wearer's profile at the output stage: folded into the device's calibration gains.

The output stage scales channel ``k`` by ``10 ** ((reference_level_db -
channel_level_db[k]) / 20)`` after the mix (:class:`~phantomtouch.renderer.OutputStage`),
and the engine's limiter and hard clip act on those calibrated samples. A wearer's offset
of ``d`` dB on channel ``k`` lowers ``channel_level_db[k]`` by ``d``: the channel's gain
becomes the calibration gain times ``10 ** (d / 20)``, and the limiter and the ceiling act
after it as they do on the calibration alone. The engine is opened with that fitted
device; nothing of the engine changes. Plans use the reference level only, so every plan,
voice and live contact is fitted alike.

One mix feeds the output stage, so one band of the profile applies to the whole service
(``Settings.wearer_band``, ``sine_100hz`` unless chosen).
"""

from __future__ import annotations

from pydantic import ValidationError

from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.schema import Calibration, DeviceProfile, describe_validation_error
from phantomtouch.schema.wearer import Band, WearerProfile, check_channels
from phantomtouch.service.settings import Settings
from phantomtouch.service.store import PatternStore


def fitted_device(device: DeviceProfile, profile: WearerProfile, band: Band) -> DeviceProfile:
    """``device`` with the offsets of ``band`` folded into its calibration levels.

    Raises
    ------
    ParameterError
        The profile names a channel the device does not have, or a fitted level falls
        outside the calibration's allowed levels.
    """
    check_channels(profile, device.channels)
    cal = device.calibration
    levels = cal.channel_level_db or (cal.reference_level_db,) * device.channels
    offsets = profile.channel_offsets_db(band, device.channels)
    fitted = tuple(level - offset for level, offset in zip(levels, offsets, strict=True))
    try:
        calibration = Calibration(
            reference_level_db=cal.reference_level_db,
            channel_level_db=fitted,
            fir_taps=cal.fir_taps,
        )
    except ValidationError as exc:
        raise ParameterError(
            f"wearer={band}: the fitted calibration is out of range "
            f"({describe_validation_error(exc)})"
        ) from exc
    return device.model_copy(update={"calibration": calibration})


def output_device(settings: Settings, store: PatternStore, device: DeviceProfile) -> DeviceProfile:
    """The device the engine plays through: ``device`` fitted to ``settings.wearer``.

    Raises
    ------
    DeviceError
        The named wearer is not in the library, or does not fit the device.
    """
    if settings.wearer is None:
        return device
    profile = store.get_wearer(settings.wearer)
    if profile is None:
        raise DeviceError(
            f"wearer={settings.wearer!r} is not in the library {str(store.path)!r}; "
            "store it first (PUT /wearers/{name}) or start without --wearer"
        )
    try:
        return fitted_device(device, profile, settings.wearer_band)
    except ParameterError as exc:
        raise DeviceError(f"wearer={settings.wearer!r} does not fit the device: {exc}") from exc
