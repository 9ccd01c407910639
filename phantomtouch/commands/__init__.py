"""The ``phantomtouch`` subcommands, one module each, with the parser and flags they share.

:mod:`phantomtouch.cli` builds the parser and dispatches to them: ``serve``/``osc``
(:mod:`.serve`), ``import`` (:mod:`.import_file`), ``calibrate`` (:mod:`.calibrate`),
``bhaptics`` (:mod:`.bhaptics`) and the ``.tact`` render (:mod:`.tact`); :mod:`.parser`
prints every error in one line, :mod:`.device_arg` reads ``--device``.
"""
