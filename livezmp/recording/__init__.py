"""Session recording in MCAP: write while monitoring or running the loop, read back, recover after a crash.

One file holds everything a session saw, on JSON-schema'd JSON channels (so Foxglove
opens it and plots any field); the channels are listed in :mod:`.schemas`. The body the
session analysed is stored as attachments (``body/<file>``) plus the ``livezmp.body``
metadata record, and the monitor settings as ``livezmp.session``, so ``livezmp replay``
rebuilds the same body and re-runs the same analysis.

- :mod:`.schemas`: channels, their JSON schemas, and the messages made from results;
- :mod:`.foxglove`: beside them, the balance scene in Foxglove's own protobuf schemas
  (ZMP, CoM, CoP, support polygon, footprints), which Foxglove's 3D panel draws as it is;
- :mod:`.writer`: :class:`~.writer.Recorder` (crash-safe chunks) and
  :class:`~.writer.BackgroundWriter` (a real-time thread's queue, written in a thread of its own);
- :mod:`.reader`: :func:`~.reader.open_recording`, :func:`~.reader.iter_messages`;
- :mod:`.recover`: :func:`~.recover.recover`, every intact record of a killed session's file.
"""
