"""The live capture monitor: :mod:`.loop` (source → pipeline → sinks), :mod:`.alarms`,
:mod:`.dashboard` (web page and WebSocket feed, page in ``static/``), :mod:`.snapshot`
(what the page draws), :mod:`.tui` (terminal view)."""
