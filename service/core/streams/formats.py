"""What a socket's frames are, decided once: `FrameFormat`, the one value a `Subscription` is
built from.

Why one value: whether frames are packed on the sim thread or rendered from snapshots, sent as
binary or text, carry entities or trajectory briefs, and which sockets may share one
serialisation (`key`) all follow from the same few choices of the socket's query. Deciding
them here, together, keeps the route, the hub and the frame thread from each deciding a part.
"""

from __future__ import annotations

from dataclasses import dataclass

# Packed frame formats (service.core.streams.frames.ENCODERS serialises each).
JSON, BINARY = "json", "binary"
JSON_ENTITIES, BINARY_ENTITIES = "json+entities", "binary+entities"
WITH_ENTITIES = (JSON_ENTITIES, BINARY_ENTITIES)  # the formats with each world's entities


@dataclass(frozen=True)
class FrameFormat:
    """One socket's kind of frame.

    kind: what is rendered ("single", "batch", "binary", "view:<focus>", "rosbridge <topic>")
    names: the joint names packed frames carry (packed formats only)
    entities: frames carry the worlds' entities (`entities=true`)
    binary: frames go out as binary WebSocket messages
    packed: the packed format (frames come from the sim thread), or None: rendered from
        snapshots on the event loop
    trajectories: packed JSON frames carry the worlds' trajectory briefs (the hub reads them
        from its briefs source on the sim thread, when it packs the frame)
    status_frames: the socket speaks armfleet's protocol: status frames (1001 at shutdown, ...)
    """

    kind: str
    names: tuple[str, ...] = ()
    entities: bool = False
    binary: bool = False
    packed: str | None = None
    trajectories: bool = False
    status_frames: bool = True

    @property
    def key(self) -> str:
        """Sockets whose frames have the same key (over the same worlds) share one serialisation."""
        return f"{self.kind}+entities" if self.entities else self.kind

    @classmethod
    def single(cls, entities: bool = False) -> FrameFormat:
        """One world's state frames, rendered from snapshots."""
        return cls("single", entities=entities)

    @classmethod
    def batch(cls, names: tuple[str, ...], entities: bool = False) -> FrameFormat:
        """Many worlds per JSON frame, packed on the sim thread, with trajectory briefs."""
        packed = JSON_ENTITIES if entities else JSON
        return cls("batch", names, entities, packed=packed, trajectories=True)

    @classmethod
    def batch_binary(cls, names: tuple[str, ...], entities: bool = False) -> FrameFormat:
        """Many worlds per binary frame (float32 rows), packed on the sim thread."""
        packed = BINARY_ENTITIES if entities else BINARY
        return cls("binary", names, entities, binary=True, packed=packed)

    @classmethod
    def view(cls, focus: int | None) -> FrameFormat:
        """The browser page's pose frames, rendered from snapshots, binary."""
        return cls(f"view:{focus}", binary=True)

    @classmethod
    def rosbridge(cls, topic: str) -> FrameFormat:
        """A rosbridge topic's messages: rendered, and no armfleet status frames."""
        return cls(f"rosbridge {topic}", status_frames=False)
