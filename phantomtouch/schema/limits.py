"""Documented limits of every pattern and device parameter.

Each cap keeps one request bounded in time and memory; a value past a cap is refused
with a message that names the field, its value and the cap.
"""

from __future__ import annotations

MIN_SPEED_CM_S = 0.0
"""Exclusive lower bound of a stroke speed (a stroke must move)."""
MAX_SPEED_CM_S = 1000.0
"""Fastest stroke, cm/s (10 m/s, far above any hand stroke: 0.5-30 cm/s in the literature)."""
MAX_DURATION_S = 7200.0
"""Longest pattern, s (two hours). Rendering is block-wise, so memory does not grow with it."""
MAX_FADE_S = 60.0
"""Longest fade-in or fade-out, s."""
MAX_PATH_POINTS = 100_000
"""Most points in a polyline or spline path, and most keyframes."""
MAX_TIMELINE_POINTS = 1_000_000
"""Most vertices of a resolved path times its repeats kept in one plan."""
MAX_REPEAT = 1000
"""Most strokes in one pattern."""
MAX_COORD_CM = 1000.0
"""Largest absolute coordinate of a path point, cm."""
MAX_ACTUATORS = 64
"""Most actuators in one device profile."""
MAX_CHANNEL = 64
"""Highest sound-card output number (1-based)."""
MIN_SAMPLE_RATE_HZ = 8000
MAX_SAMPLE_RATE_HZ = 192_000
MIN_BLOCK_FRAMES = 16
MAX_BLOCK_FRAMES = 8192
MAX_GAIN_UPDATE_FRAMES = 4096
"""Longest interval between two gain updates, frames."""
MAX_GAIN_UPDATE_S = 0.02
"""Longest interval between two gain updates, s (4096 frames at 192 kHz is 21 ms)."""
MAX_FIR_TAPS = 4096
"""Most taps of one channel's calibration FIR filter."""
MIN_LEVEL_DB = 60.0
"""Lowest acceleration level, dB re 1 µm/s² (far below the vibrotactile threshold)."""
MAX_LEVEL_DB = 180.0
"""Highest acceleration level any profile may allow, dB re 1 µm/s²."""
MIN_CARRIER_HZ = 20.0
"""Lowest sine carrier frequency, Hz (a sine's and a combined carrier's ``freq_hz``). The
wide-band voice coils reproduce vibration from a few tens of Hz (the paper's carriers span
50-500 Hz, the calibration 40-500 Hz); far below, the coil only moves off centre and
back, slower than the skin feels as vibration (0.01 Hz sits near full scale for seconds).
The mixer's DC blocker (``renderer/dc_blocker.py``) catches what is left below it."""
MIN_NOISE_BAND_HZ = 1.0
"""Lowest band edge of a noise carrier, Hz (a band is at least ``MIN_NOISE_LOOP_BINS`` steps
wide, so its content never sits still)."""
MIN_NOISE_LOOP_BINS = 16
"""Fewest frequency steps of the noise loop a noise band must span (a step is
``sample_rate_hz / 2**20``: 0.046 Hz at 48 kHz, so bands of at least 0.73 Hz). A narrower
band would hold a few beating sines, not noise."""
MAX_SEED = 2**32 - 1
