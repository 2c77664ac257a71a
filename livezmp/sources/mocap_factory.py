"""``open_mocap_source(url)``: the live capture source a URL names.

- ``lsl://[NAME][?type=MoCap&source_id=ID&plates=NAME|none&up=z&timeout=5]`` (:mod:`.lsl`)
- ``qtm://HOST[:PORT][?version=1.25]`` (:mod:`.qtm`, port 22223 by default)
- ``natnet://HOST[:PORT][?data_port=1511&up=y&timeout=5]`` (:mod:`.natnet`, port 1510)
"""

from __future__ import annotations

from urllib.parse import urlsplit

from livezmp.errors import InputError
from livezmp.sources.mocap_frame import MocapSource
from livezmp.sources.url_query import query_params

MOCAP_SCHEMES = ("lsl", "qtm", "natnet")


def open_mocap_source(url: str) -> MocapSource:
    """Open the capture stream ``url`` names; InputError (one line) if it cannot."""
    u = urlsplit(url)
    if u.scheme == "lsl":
        from livezmp.sources.lsl import LslSource

        return LslSource(url)
    if u.scheme == "natnet":
        from livezmp.sources.natnet import NatNetSource

        return NatNetSource(url)
    if u.scheme == "qtm":
        from livezmp.sources.qtm import DEFAULT_PORT, QtmSource

        query = query_params(url, {"version"})
        try:
            port = u.port or DEFAULT_PORT
        except ValueError:
            raise InputError(f"{url}: bad port") from None
        if not u.hostname:
            raise InputError(f"{url}: need a host, e.g. qtm://127.0.0.1")
        return QtmSource(u.hostname, port, query.get("version", "1.25"))
    raise InputError(f"{url}: not a capture stream (lsl://, qtm://, natnet://)")
