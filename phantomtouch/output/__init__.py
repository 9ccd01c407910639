"""Where the engine's samples go, below the engine: the sound card's output devices as
PortAudio lists them (:mod:`~phantomtouch.output.devices`), the sinks that need no
audio hardware (:mod:`~phantomtouch.output.sinks`: the ``Sink`` protocol, ``NullSink``,
``CaptureSink``) and the sound card's (:mod:`~phantomtouch.output.soundcard`:
``SoundDeviceSink``, ``SinkSpec``, ``open_default_sink``).

It imports only the base (the exception root and the schema), never the engine, which
plays into its sinks (docs/architecture.md). The package imports none of its modules, so
looking a device up loads neither numpy nor ``soundfile``.
"""
