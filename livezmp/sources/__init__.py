"""Frame sources behind one interface.

:mod:`.interface` (the :class:`~.interface.Source` protocol and its records),
:mod:`.factory` (:func:`~.factory.open_source`: a source by path or URL), one module per
kind: :mod:`.file_replay`, :mod:`.udp` (with :mod:`.frame_format`), :mod:`.bvh_tcp`,
:mod:`.mcap_replay`; and :mod:`.body_spec` (what a source's body was built from).
"""
