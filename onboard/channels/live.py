"""Foxglove live: the recording's channels published over the Foxglove WebSocket protocol
(foxglove-sdk's server), so an engineer opens Foxglove on a running sortie.

The channels are :data:`~.schemas.CHANNELS` with the recording's schemas, and the messages
are built by the recorder's builder (:class:`~.builder.ChannelBuilder` with a
:class:`FoxgloveSink` in place of a file): live and recorded channels are one definition.
Used by ``groundstation serve --foxglove`` and ``onboard run --foxglove``.
Message contents equal the file's (timestamps on the sortie's clock); log times are the wall
clock at publication, as Foxglove expects of a live source. Loopback by default.
"""

from __future__ import annotations

import foxglove

from .builder import ChannelBuilder
from .encode import encode
from .schemas import CHANNELS, schema_bytes

DEFAULT_PORT = 8765  # Foxglove's default for a WebSocket data source


class FoxgloveLive:
    """One Foxglove WebSocket server for the life of the process; each sortie publishes
    through :meth:`observer`. ``port`` 0 picks a free port (see :attr:`port`)."""

    def __init__(self, port: int = DEFAULT_PORT, host: str = "127.0.0.1") -> None:
        self._ctx = foxglove.Context()
        self.channels = []
        for topic, name in CHANNELS:
            schema = foxglove.Schema(name=name, encoding="jsonschema", data=schema_bytes(name))
            self.channels.append(
                foxglove.Channel(topic, schema=schema, message_encoding="json", context=self._ctx)
            )
        self.server = foxglove.start_server(
            name="peregrine", host=host, port=port, context=self._ctx
        )
        self.host = host
        self._index = {topic: i for i, (topic, _) in enumerate(CHANNELS)}

    @property
    def port(self) -> int:
        return self.server.port

    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def observer(self, **rates: int) -> ChannelBuilder:
        """A sortie observer publishing here (``rates``: the recorder's ``record_every``,
        ``annotate_every``, ``frame_every``; its defaults otherwise)."""
        return ChannelBuilder(sink=FoxgloveSink(self), **rates)

    def subscribed(self, topic: str) -> bool:
        """Whether any client subscribes to ``topic`` now."""
        return self.channels[self._index[topic]].has_sinks()

    def publish(self, ti: int, data: bytes) -> None:
        """One encoded message on channel ``ti`` (an index of CHANNELS)."""
        self.channels[ti].log(data)

    def stop(self) -> None:
        self.server.stop()


class FoxgloveSink:
    """The builder's sink interface (see :mod:`.builder`) over a :class:`FoxgloveLive`:
    messages are encoded here and published at once; metadata and attachments are files'
    only."""

    def __init__(self, live: FoxgloveLive) -> None:
        self.live = live
        self._static_subscribed = False

    def _static(self) -> bool:
        return self.live.subscribed("/camera/calibration") or self.live.subscribed("/gains")

    def joined(self) -> bool:
        """True once each time a client subscribes to the calibration or the gains after the
        sortie started (the builder then sends them again)."""
        now = self._static()
        joined, self._static_subscribed = now and not self._static_subscribed, now
        return joined

    def add(self, ti: int, ns: int, data: bytes) -> None:
        self.live.publish(ti, data)

    def add_many(self, ns: int, items) -> None:
        """Encoded only for a channel some client subscribes to."""
        channels = self.live.channels
        for ti, enc, payload in items:
            if channels[ti].has_sinks():
                self.live.publish(ti, encode(enc, payload))

    def metadata(self, name: str, data: dict[str, str]) -> None:
        pass

    def attachment(self, name: str, media_type: str, data: bytes) -> None:
        pass

    def started(self) -> None:
        self._static_subscribed = self._static()  # sent at the start to who is there

    def finish(self, outcome: dict[str, str]) -> None:
        pass

    def abandon(self) -> None:
        pass
