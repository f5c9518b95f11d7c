"""A sortie's channels, defined once for every place they go: the topics and their schemas
(:mod:`.schemas`, Foxglove's official ones in ``foxglove_jsonschema/``), the messages built
from :class:`~onboard.frames.Frame` s (:mod:`.builder`, :mod:`.encode`), and Foxglove live
(:mod:`.live`). The ground station's recorder writes them to MCAP files; ``onboard run
--foxglove`` and ``groundstation serve --foxglove`` publish them over Foxglove's WebSocket
protocol."""
