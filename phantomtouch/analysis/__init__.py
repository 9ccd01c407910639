"""Accuracy and numerics: a digital twin of the armband, a model of what is felt,
the accuracy study of the gain schedule, and the calibration of a real armband.

Pure numpy/scipy on top of :mod:`phantomtouch.renderer` and :mod:`phantomtouch.schema`.

- :mod:`~phantomtouch.analysis.twin`: each actuator as a second-order resonator
  (drive -> acceleration), discretised with the bilinear transform.
- :mod:`~phantomtouch.analysis.perception`: perceived phantom position (energy
  centroid) and level from the actuators' accelerations.
- :mod:`~phantomtouch.analysis.accuracy`: position, gain and level error of the gain
  update settings against their CPU cost (``phantomtouch bench accuracy``).
- :mod:`~phantomtouch.analysis.calibration`: measure each actuator, store its
  correction, verify the levels (``phantomtouch calibrate``), with the signal
  processing in :mod:`~phantomtouch.analysis.inverse_filter` (Welch H1, regularised
  minimum-phase inverse FIR) and the profile file writer in
  :mod:`~phantomtouch.analysis.profile_file`.
"""
