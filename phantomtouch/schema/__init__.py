"""The one contract: pydantic models for patterns, device profiles and messages."""

from phantomtouch.schema.clip import ClipCarrier, HapticClip
from phantomtouch.schema.device import Actuator, Calibration, DeviceProfile, SafetyLimits
from phantomtouch.schema.pattern import (
    AmplitudeModulation,
    ArcPath,
    Carrier,
    CombinedCarrier,
    Keyframe,
    KeyframePath,
    NoiseCarrier,
    PathSpec,
    PolylinePath,
    SineCarrier,
    SplinePath,
    TouchPattern,
)
from phantomtouch.schema.validation import describe_validation_error, error_items

__all__ = [
    "Actuator",
    "AmplitudeModulation",
    "ArcPath",
    "Calibration",
    "Carrier",
    "ClipCarrier",
    "CombinedCarrier",
    "DeviceProfile",
    "HapticClip",
    "Keyframe",
    "KeyframePath",
    "NoiseCarrier",
    "PathSpec",
    "PolylinePath",
    "SafetyLimits",
    "SineCarrier",
    "SplinePath",
    "TouchPattern",
    "describe_validation_error",
    "error_items",
]
